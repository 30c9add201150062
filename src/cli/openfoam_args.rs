//! The OpenFOAM options shared by `kalibre calibrate` and `kalibre diagnose`.

use std::path::Path;
use std::time::Duration;

use clap::Args;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{OpenFoamError, OpenFoamSettings};
use kalibre_dc::snapshots::number;

use super::{CliError, CliResult};

/// OpenFOAM's memory per cell for a steady incompressible solve, as its users' rule of
/// thumb has it (about 1 GB per million cells).
const BYTES_PER_CELL: f64 = 1e3;

/// The most `--of-killed-retries` allowed.
const MAX_KILLED_RETRIES: u32 = 5;

/// Above this many cells a warning says what each solve will cost.
const LARGE_MESH_CELLS: f64 = 1e6;

/// OpenFOAM options (with `--model openfoam`).
#[derive(Debug, Clone, Args)]
pub struct OpenFoamArgs {
    /// OpenFOAM: processes per solve; 1 runs serially, more runs decomposePar then
    /// `mpirun -np N` (then run fewer solves at once so they do not compete for cores:
    /// `calibrate --parallel-runs 1`, `diagnose --threads 1`). Default 1 (`diagnose` and
    /// `simulate --params`: the calibration's).
    #[arg(long)]
    pub np: Option<u32>,
    /// OpenFOAM: SIMPLE iterations per solve; sensors are averaged over the second half.
    /// Default 1000, at least 10 (`diagnose` and `simulate --params`: the calibration's).
    #[arg(long = "of-iterations")]
    pub of_iterations: Option<u32>,
    /// OpenFOAM: wall-clock limit per solve (s); a solve past it is killed with its whole
    /// process group and recorded as failed (a diagnosis leaves that candidate out).
    /// Default 600.
    #[arg(long = "of-timeout-s")]
    pub of_timeout_s: Option<f64>,
    /// OpenFOAM: times a solve killed from outside kalibre (SIGKILL or SIGTERM it did not
    /// send: the out-of-memory killer, an administrator) is solved again at once, in a
    /// fresh directory; 0 records it as failed. Default 1.
    #[arg(long = "of-killed-retries")]
    pub of_killed_retries: Option<u32>,
}

impl OpenFoamArgs {
    /// The first OpenFOAM option given, refused when the model is not OpenFOAM.
    pub fn refuse_unless(&self, openfoam: bool) -> CliResult {
        self.refuse_unless_because(openfoam, "add --model openfoam")
    }

    /// [`Self::refuse_unless`], saying `why` of each flag given (for a model of your own,
    /// which OpenFOAM does not solve, "add --model openfoam" would mislead).
    pub fn refuse_unless_because(&self, openfoam: bool, why: &str) -> CliResult {
        let given = [
            ("--np", self.np.is_some()),
            ("--of-iterations", self.of_iterations.is_some()),
            ("--of-timeout-s", self.of_timeout_s.is_some()),
            ("--of-killed-retries", self.of_killed_retries.is_some()),
        ];
        if openfoam {
            return Ok(());
        }
        super::simulate::refuse_given(&given, |flag| {
            format!("{flag} is an OpenFOAM option: {why}")
        })
    }

    /// The adapter's settings; meshed cases and runs go in `root`.
    pub fn settings(&self, root: &Path, grid_m: Option<f64>) -> CliResult<OpenFoamSettings> {
        let mut s = OpenFoamSettings::default().with_cache_root(root);
        if let Some(h) = grid_m {
            s = s.with_grid_m(h);
        }
        if let Some(np) = self.np {
            s = s.with_np(np);
        }
        if let Some(k) = self.of_iterations {
            s = s.with_iterations(k);
        }
        if let Some(t) = self.of_timeout_s {
            if !(t.is_finite() && t > 0.0 && t < 1e9) {
                return Err(CliError::Input(format!(
                    "--of-timeout-s: {t} is not a positive number of seconds"
                )));
            }
            s = s.with_timeout(Duration::from_secs_f64(t));
        }
        if let Some(n) = self.of_killed_retries {
            if n > MAX_KILLED_RETRIES {
                return Err(CliError::Input(format!(
                    "--of-killed-retries: {n} is more than {MAX_KILLED_RETRIES}: a solve killed \
                     that often is being killed for a reason (memory?), not by chance"
                )));
            }
            s = s.with_killed_retries(n);
        }
        s.check().map_err(|e| {
            CliError::Input(match e {
                OpenFoamError::Setting { name, reason } => {
                    let flag = match name.as_str() {
                        "np" => "--np",
                        "iterations" => "--of-iterations",
                        "grid_m" => "--grid-m",
                        "timeout" => "--of-timeout-s",
                        other => other,
                    };
                    format!("{flag}: {reason}")
                }
                e => e.to_string(),
            })
        })
    }
}

/// A case-building error: meshing and I/O failures are run errors, the rest bad input.
pub fn of_err(e: OpenFoamError) -> CliError {
    match e {
        OpenFoamError::Meshing { .. } | OpenFoamError::Io { .. } => CliError::Run(e.to_string()),
        e => CliError::Input(e.to_string()),
    }
}

/// Refuses an OpenFOAM mesh that could not fit in this machine's memory (about 1 GB per
/// million cells), before `blockMesh` starts on it, and warns of one above a million
/// cells. `grid_given`: `--grid-m` was given (else the room's size is what to check).
pub fn check_mesh(hall: &Hall, hall_path: &Path, grid_m: f64, grid_given: bool) -> CliResult {
    let cells: f64 = hall
        .room
        .size_m
        .iter()
        .map(|l| (l / grid_m).ceil().max(1.0))
        .product();
    let need_gb = cells * BYTES_PER_CELL / 1e9;
    let cause = || {
        if grid_given {
            format!("--grid-m {}", number(grid_m))
        } else {
            let [x, y, z] = hall.room.size_m.map(number);
            format!(
                "{}: /room/size_m: a room of {x} x {y} x {z} m at cells of {} m",
                hall_path.display(),
                number(grid_m)
            )
        }
    };
    if let Some(have_gb) = memory_gb().filter(|have| need_gb > *have) {
        return Err(CliError::Input(format!(
            "{}: the OpenFOAM mesh would have {cells:.2e} cells, needing about {need_gb:.0} GB \
             (about 1 GB per million cells) where this machine has {have_gb:.0} GB: use \
             coarser cells{}",
            cause(),
            if grid_given {
                ""
            } else {
                " (--grid-m), or check that the lengths are in metres"
            }
        )));
    }
    if cells > LARGE_MESH_CELLS {
        // Measured here: a 31,080-cell hall solves 1000 iterations in 20-50 s on one core,
        // and the time grows at least in proportion to the cells.
        let minutes = cells / 31_080.0 * 35.0 / 60.0;
        eprintln!(
            "kalibre: warning: {}: the OpenFOAM mesh will have {cells:.2e} cells: about \
             {need_gb:.1} GB per solve, and at least {minutes:.0} min per solve of 1000 \
             iterations on one core (31,080 cells take 20-50 s)",
            cause()
        );
    }
    Ok(())
}

/// This machine's memory (GB), from `/proc/meminfo`; `None` where it cannot be read.
fn memory_gb() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0 / 1e9)
}
