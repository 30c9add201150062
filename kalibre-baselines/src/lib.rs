//! # kalibre-baselines
//!
//! The comparators of the Kalibre paper's Table 4, each usable through kalibre's traits:
//!
//! - [`OnePlusOneEs`]: the paper's "heuristic", a (1+1) evolution strategy with the 1/5
//!   success rule that runs the model every iteration (an argmin solver; [`run_es`]
//!   drives it on a [`kalibre_core::Model`]);
//! - [`Mlp`]: the "vanilla" fully connected neural surrogate, a
//!   [`kalibre_core::Surrogate`] that runs in the same four-step [`kalibre_core::Calibrator`]
//!   loop as the thermal graph;
//! - [`ManualHeuristic`]: the domain expert's procedure: where the model reads hotter than
//!   a sensor, raise the air flow of the servers near it, and vice versa.
//!
//! The model-in-the-loop baselines return a [`BaselineReport`] with a history of
//! (model runs, MAE) per iteration; the MLP returns the core's
//! [`kalibre_core::Report`] like any calibration. On halls of thousands of servers give
//! the MLP [`InputLevel::Rack`] inputs (power and mean alpha per rack): on `hall-a`
//! (2,240 servers) one fit of 192 samples took 1.2 s with rack inputs (340) and 12 s
//! with server inputs (4,500), release build.
//!
//! # Example
//!
//! ```no_run
//! use kalibre_baselines::{run_es, OnePlusOneEs};
//! use kalibre_dc::{hall::Hall, sim::SimConfig, snapshots, HallModel};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = std::path::Path::new("data/openfoam/of-dev-clean");
//! let hall = Hall::load(&dir.join("hall.json"))?;
//! let snaps = snapshots::load_snapshots(&hall, &dir.join("snapshots.csv"))?;
//! let obs = snapshots::to_observations(&hall, &snaps)?;
//! let model = HallModel::new(&hall, SimConfig::default())?;
//! let es = OnePlusOneEs::default().with_seed(1).with_max_iterations(50);
//! let report = run_es(&model, &obs, model.layout().space(), &es, None)?;
//! assert!(report.best_mae_c <= report.initial_mae_c);
//!
//! // The vanilla MLP in the four-step loop, where the thermal graph would be.
//! use kalibre_baselines::{Mlp, MlpSettings};
//! use kalibre_core::Calibrator;
//! let mlp = Mlp::new(&hall, model.layout().clone(), MlpSettings::default())?;
//! let space = model.layout().space().clone();
//! let calibrated = Calibrator::new(&model, mlp, &obs, &space)
//!     .with_seed(1)
//!     .with_max_iterations(10)
//!     .run()?;
//! assert!(calibrated.best.mae_c.is_finite());
//! # Ok(())
//! # }
//! ```

#![warn(missing_docs)]

mod error;
mod es;
mod manual;
mod mlp;
mod runner;

pub use error::{Error, Result};
pub use es::{reflect_unit, run_es, EsSolver, OnePlusOneEs};
pub use manual::{ManualHeuristic, ManualSettings, Neighbourhood};
pub use mlp::{
    flatten, loss_and_gradients, Activation, Dense, Gradients, InputLevel, Mlp, MlpSettings,
    Network, Tape,
};
pub use runner::{BaselineReport, HistoryPoint, ModelMae, PointResult};
