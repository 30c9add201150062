//! The OpenFOAM options shared by `kalibre calibrate` and `kalibre diagnose`.

use std::path::Path;
use std::time::Duration;

use clap::Args;
use kalibre_dc::openfoam::{OpenFoamError, OpenFoamSettings};

use super::{CliError, CliResult};

/// OpenFOAM options (with `--model openfoam`).
#[derive(Debug, Clone, Args)]
pub struct OpenFoamArgs {
    /// OpenFOAM: processes per solve; 1 runs serially, more runs decomposePar then
    /// `mpirun -np N` (then run fewer solves at once so they do not compete for cores:
    /// `calibrate --parallel-runs 1`, `diagnose --threads 1`).
    #[arg(long)]
    pub np: Option<u32>,
    /// OpenFOAM: SIMPLE iterations per solve; sensors are averaged over the second half.
    #[arg(long = "of-iterations")]
    pub of_iterations: Option<u32>,
    /// OpenFOAM: wall-clock limit per solve (s); a solve past it is killed with its whole
    /// process group and recorded as failed (a diagnosis leaves that candidate out).
    #[arg(long = "of-timeout-s")]
    pub of_timeout_s: Option<f64>,
}

impl OpenFoamArgs {
    /// The first OpenFOAM option given, refused when the model is not OpenFOAM.
    pub fn refuse_unless(&self, openfoam: bool) -> CliResult {
        let given = [
            ("--np", self.np.is_some()),
            ("--of-iterations", self.of_iterations.is_some()),
            ("--of-timeout-s", self.of_timeout_s.is_some()),
        ];
        match given.iter().find(|(_, g)| *g) {
            Some((flag, _)) if !openfoam => Err(CliError::Input(format!(
                "{flag} is an OpenFOAM option: add --model openfoam"
            ))),
            _ => Ok(()),
        }
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
