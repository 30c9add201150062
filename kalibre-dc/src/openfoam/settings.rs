//! Settings of the OpenFOAM adapter.

use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;

use super::OpenFoamError;

/// How the OpenFOAM case is built and run.
///
/// | Name | Default | Meaning |
/// |---|---|---|
/// | `grid_m` | 0.2 | blockMesh cell size (m); every box edge of the hall must lie on it |
/// | `iterations` | 1000 | SIMPLE iterations per run |
/// | `average_from` | 0.5 | probes are averaged over iterations in (`average_from` x `iterations`, `iterations`] |
/// | `probe_every` | 5 | probe sampling interval (iterations) |
/// | `np` | 1 | processes: 1 runs serially, more runs `decomposePar` then `mpirun -np N` |
/// | `timeout` | 600 s | wall-clock limit per attempt at a run (all its steps), after which the process group is killed |
/// | `killed_retries` | 1 | times a solve killed from outside (SIGKILL or SIGTERM not sent by kalibre: the out-of-memory killer, an administrator) is solved again, in a fresh directory; a timeout, a divergence or a crash is not |
/// | `energy_tolerance` | 0.05 | largest accepted relative error of the energy balance |
/// | `project_dir` | `/usr/share/openfoam` | `WM_PROJECT_DIR` given to every OpenFOAM program |
/// | `cache_root` | `openfoam-cases` | meshed cases (one per hall and grid) and run directories |
/// | `keep_runs` | false | keep each run's directory after a successful run (failed ones are kept) |
/// | `containment_leak_fraction` | 0.02 | open fraction of closed containment panels and doors, the built-in simulator's default: a panel drops the pressure of a sharp-edged orifice of that open area ([`panel_loss_coefficient`]) |
///
/// Physical constants follow the development datasets: rho 1.2 kg/m3, cp 1005 J/(kg K),
/// beta 3.3e-3 1/K, TRef 25 C, nu 1.5e-5 m2/s. Returns take no inflow (25 C closes the
/// temperature boundary where the flow would turn inward).
#[derive(Debug, Clone, Serialize)]
pub struct OpenFoamSettings {
    /// Cell size (m).
    pub grid_m: f64,
    /// SIMPLE iterations.
    pub iterations: u32,
    /// Start of the averaging window as a fraction of the iterations.
    pub average_from: f64,
    /// Probe sampling interval (iterations).
    pub probe_every: u32,
    /// Processes (1 = serial).
    pub np: u32,
    /// Air density (kg/m3).
    pub rho_kg_m3: f64,
    /// Air heat capacity (J/(kg K)).
    pub cp_j_kgk: f64,
    /// Thermal expansion coefficient (1/K).
    pub beta_1_k: f64,
    /// Boussinesq reference temperature (C).
    pub t_ref_c: f64,
    /// Kinematic viscosity (m2/s).
    pub nu_m2_s: f64,
    /// Temperature a return's face takes where the flow turns inward (C). Returns let
    /// no air in (their velocity is held at zero there), so this only closes the
    /// temperature boundary of such faces.
    pub return_backflow_c: f64,
    /// Wall-clock limit per run.
    #[serde(skip)]
    pub timeout: Duration,
    /// Times a solve killed from outside is solved again (not in the fingerprint: it
    /// changes no result).
    #[serde(skip)]
    pub killed_retries: u32,
    /// Largest accepted relative energy balance error.
    #[serde(skip)]
    pub energy_tolerance: f64,
    /// `WM_PROJECT_DIR`.
    #[serde(skip)]
    pub project_dir: PathBuf,
    /// Where meshed cases and run directories go.
    #[serde(skip)]
    pub cache_root: PathBuf,
    /// Keep successful run directories.
    #[serde(skip)]
    pub keep_runs: bool,
    /// Open fraction of closed containment panels (in the fingerprint only for halls with
    /// containment, so other halls' fingerprints do not change).
    #[serde(skip)]
    pub containment_leak_fraction: f64,
}

/// Discharge coefficient of a sharp-edged orifice (see [`panel_loss_coefficient`]).
pub const PANEL_DISCHARGE_COEFFICIENT: f64 = 0.61;

/// The loss coefficient `K` of a panel of open fraction `f` in `(0, 1]`: air crossing it
/// at face velocity `u` drops the kinematic pressure by `0.5 K u^2`, with
/// `K = ((1 - f) / (0.61 f))^2`: a sharp-edged orifice's jet loss, none when fully open.
///
/// ```
/// use kalibre_dc::openfoam::panel_loss_coefficient;
/// assert_eq!(panel_loss_coefficient(1.0), 0.0);
/// // The default 2 % leak: about 6,450 dynamic heads.
/// assert!((panel_loss_coefficient(0.02) - 6452.0).abs() < 1.0);
/// ```
pub fn panel_loss_coefficient(open_fraction: f64) -> f64 {
    ((1.0 - open_fraction) / (PANEL_DISCHARGE_COEFFICIENT * open_fraction)).powi(2)
}

impl Default for OpenFoamSettings {
    fn default() -> Self {
        OpenFoamSettings {
            grid_m: 0.2,
            iterations: 1000,
            average_from: 0.5,
            probe_every: 5,
            np: 1,
            rho_kg_m3: 1.2,
            cp_j_kgk: 1005.0,
            beta_1_k: 3.3e-3,
            t_ref_c: 25.0,
            nu_m2_s: 1.5e-5,
            return_backflow_c: 25.0,
            timeout: Duration::from_secs(600),
            killed_retries: 1,
            energy_tolerance: 0.05,
            project_dir: PathBuf::from("/usr/share/openfoam"),
            cache_root: PathBuf::from("openfoam-cases"),
            keep_runs: false,
            containment_leak_fraction: 0.02,
        }
    }
}

fn bad(name: &str, reason: impl Into<String>) -> OpenFoamError {
    OpenFoamError::Setting {
        name: name.into(),
        reason: reason.into(),
    }
}

impl OpenFoamSettings {
    /// Sets the cell size (m).
    pub fn with_grid_m(mut self, h: f64) -> Self {
        self.grid_m = h;
        self
    }

    /// Sets the SIMPLE iterations.
    pub fn with_iterations(mut self, k: u32) -> Self {
        self.iterations = k;
        self
    }

    /// Sets the processes (1 = serial).
    pub fn with_np(mut self, np: u32) -> Self {
        self.np = np;
        self
    }

    /// Sets how many times a solve killed from outside is solved again (0: never).
    pub fn with_killed_retries(mut self, retries: u32) -> Self {
        self.killed_retries = retries;
        self
    }

    /// Sets the wall-clock limit per run.
    pub fn with_timeout(mut self, t: Duration) -> Self {
        self.timeout = t;
        self
    }

    /// Sets the energy balance tolerance (relative).
    pub fn with_energy_tolerance(mut self, tol: f64) -> Self {
        self.energy_tolerance = tol;
        self
    }

    /// Sets where meshed cases and runs go.
    pub fn with_cache_root(mut self, root: impl Into<PathBuf>) -> Self {
        self.cache_root = root.into();
        self
    }

    /// Sets `WM_PROJECT_DIR`.
    pub fn with_project_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.project_dir = dir.into();
        self
    }

    /// Keeps successful run directories.
    pub fn with_keep_runs(mut self, keep: bool) -> Self {
        self.keep_runs = keep;
        self
    }

    /// Sets the open fraction of containment panels.
    pub fn with_containment_leak_fraction(mut self, fraction: f64) -> Self {
        self.containment_leak_fraction = fraction;
        self
    }

    /// Checks every value.
    pub fn check(self) -> Result<Self, OpenFoamError> {
        if !(self.grid_m.is_finite() && self.grid_m > 0.0) {
            return Err(bad(
                "grid_m",
                format!("{} is not a positive size", self.grid_m),
            ));
        }
        if self.iterations < 10 {
            return Err(bad("iterations", "at least 10 SIMPLE iterations"));
        }
        if self.probe_every == 0 || self.probe_every > self.iterations {
            return Err(bad("probe_every", "between 1 and the iterations"));
        }
        if !(0.0..1.0).contains(&self.average_from) {
            return Err(bad("average_from", "a fraction in [0, 1)"));
        }
        let window = (self.iterations as f64 * (1.0 - self.average_from)) as u32;
        if window < self.probe_every {
            return Err(bad(
                "average_from",
                "the averaging window holds no probe sample",
            ));
        }
        if self.np == 0 || self.np > 1024 {
            return Err(bad("np", format!("{} is not a process count", self.np)));
        }
        for (name, v) in [
            ("rho_kg_m3", self.rho_kg_m3),
            ("cp_j_kgk", self.cp_j_kgk),
            ("beta_1_k", self.beta_1_k),
            ("nu_m2_s", self.nu_m2_s),
            ("energy_tolerance", self.energy_tolerance),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, format!("{v} is not positive")));
            }
        }
        let f = self.containment_leak_fraction;
        if !(f.is_finite() && f > 0.0 && f <= 1.0) {
            return Err(bad(
                "containment_leak_fraction",
                format!("{f} is not an open fraction in (0, 1] (a sealed panel leaves unbalanced flows no steady state)"),
            ));
        }
        if self.timeout.is_zero() {
            return Err(bad("timeout", "must be positive"));
        }
        Ok(self)
    }
}
