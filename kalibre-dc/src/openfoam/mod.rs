//! OpenFOAM as the hall's model: [`OpenFoamModel`] builds a case from `hall.json` once
//! (blockMesh on the grid, racks and CRACs cut out with `topoSet` + `subsetMesh`, one
//! intake and one exhaust patch per server, tiles, bypass openings and returns made by
//! `createPatch`), and per run writes only `0.orig/include/params` and runs
//! `buoyantBoussinesqSimpleFoam` (k-epsilon, Boussinesq buoyancy) serially or with
//! `mpirun -np N` after `decomposePar`. [`OpenFoamEffectSolver`] lets a diagnosis solve
//! its candidate effects with OpenFOAM too.
//!
//! Outputs are the window means of the probes at the sensors; their window standard
//! deviations are the run's spread. A run fails (a [`kalibre_core::ModelError`], journaled,
//! the loop goes on) on a non-zero exit, a signal, a timeout (the process group is
//! killed), a floating-point exception, a log without `End`, missing probes or an energy
//! balance off by more than the tolerance. The layout of the case and each setting are
//! documented in `docs/models.md`.

mod case;
mod dicts;
mod geometry;
mod model;
mod params;
mod results;
mod servers;
mod settings;
mod solver;
mod step;

use thiserror::Error;

pub use case::{remove_interrupted_runs, CaseDir, MeshSummary};
pub use geometry::{
    CaseExtras, CaseGeometry, CellRange, FacePatch, GapPatches, PanelPlane, RackGap, ServerPatches,
};
pub use model::{
    OpenFoamModel, RunTimings, KILLED_ATTEMPTS_KEY, SERVER_INTAKE_KEY, SUPPORTED_EFFECTS,
};
pub use params::{RunInputs, M3_S_PER_CFM};
pub use results::{log_verdict, probe_window, ProbeWindow};
pub use servers::server_air_from_intakes;
pub use settings::{panel_loss_coefficient, OpenFoamSettings, PANEL_DISCHARGE_COEFFICIENT};
pub use solver::OpenFoamEffectSolver;

/// Errors of building an OpenFOAM case (a run's failure is a
/// [`kalibre_core::ModelError`] instead).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum OpenFoamError {
    /// The hall uses something the adapter cannot represent.
    #[error("not supported by the OpenFOAM adapter: {0}")]
    Unsupported(String),
    /// The hall's geometry does not fit the grid.
    #[error("hall.json: {field}: {message}")]
    Geometry {
        /// The field or item concerned.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A setting is out of range.
    #[error("OpenFOAM setting `{name}`: {reason}")]
    Setting {
        /// The setting.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// An OpenFOAM program is missing.
    #[error(
        "OpenFOAM program `{0}` not found in PATH (install OpenFOAM, e.g. `apt-get install openfoam`)"
    )]
    NotInstalled(String),
    /// Meshing failed.
    #[error("meshing step `{step}` failed: {reason}{}", log_tail.as_deref().map(|t| format!("\n{t}")).unwrap_or_default())]
    Meshing {
        /// The OpenFOAM program.
        step: String,
        /// What went wrong.
        reason: String,
        /// The end of its log.
        log_tail: Option<String>,
    },
    /// A file could not be written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: String,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The hall or its effects are invalid.
    #[error(transparent)]
    Hall(#[from] crate::Error),
}

impl OpenFoamError {
    /// The error with the hall file's real path in place of `hall.json`: a geometry the
    /// grid cannot hold becomes an [`crate::Error::Format`] naming `file` and the field,
    /// and the hall's own errors name it as [`crate::Error::in_hall_file`] does.
    pub fn in_hall_file(self, file: &str) -> Self {
        match self {
            OpenFoamError::Geometry { field, message } => {
                OpenFoamError::Hall(crate::Error::format(file, field, message))
            }
            OpenFoamError::Hall(e) => OpenFoamError::Hall(e.in_hall_file(file)),
            e => e,
        }
    }

    pub(crate) fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        OpenFoamError::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }
}

impl From<OpenFoamError> for crate::Error {
    fn from(e: OpenFoamError) -> Self {
        match e {
            OpenFoamError::Hall(e) => e,
            e => crate::Error::Mismatch(e.to_string()),
        }
    }
}
