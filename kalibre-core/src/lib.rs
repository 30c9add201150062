//! # kalibre-core
//!
//! The generic four-step calibration loop of kalibre, independent of any domain.
//!
//! 1. **fit** a cheap [`Surrogate`] on every model run so far;
//! 2. **search** the parameters on the surrogate against the measurements ([`Searcher`]);
//! 3. **run** the expensive [`Model`] there (runs are journaled in a [`RunStore`]);
//! 4. **validate** the model's outputs against the measurements ([`Validator`]).
//!
//! The [`Calibrator`] drives the loop from an initial design, keeps the best parameters,
//! and stops on an iteration, error, model-run or wall-clock budget.
//!
//! Every model run is journaled in a [`RunStore`] (`runs.jsonl`) as it finishes, so a
//! restarted calibration replays what it already ran and ends bit-identical to an
//! uninterrupted one. Progress goes to [`Observe`]rs; the result is a serialisable
//! [`Report`] (`report.json`). The journal is in memory unless one is given:
//! `.with_store(RunStore::open("runs.jsonl", model.fingerprint())?)`.
//!
//! [`Settings::default`] is the paper's plain loop; with a model and surrogate of your
//! own, start from [`Settings::recommended`] (the surrogate corrected to the model's runs,
//! a trust region, a polish on the model's own slopes), as `kalibre calibrate` does:
//! `.with_settings(Settings::recommended())` before the other `with_*` calls.
//!
//! # Example
//!
//! Calibrate a sensor model with a thermal resistance-like parameter `k` and an offset,
//! using a surrogate of the same physical form with a learned gain per output:
//!
//! ```
//! use kalibre_core::{
//!     Calibrator, FitSummary, Model, ModelError, Observations, OutputInfo, Outputs,
//!     ParamSpace, Scale, Snapshot, Surrogate, TrainingSet,
//! };
//!
//! /// The expensive model: two sensors warmed by a load (the scenario, in W).
//! struct Rise;
//! impl Model for Rise {
//!     type Scenario = f64;
//!     fn fingerprint(&self) -> String {
//!         "rise-v1".into()
//!     }
//!     fn evaluate(&self, load_w: &f64, p: &[f64]) -> Result<Outputs, ModelError> {
//!         let rise = load_w / p[0];
//!         Ok(vec![20.0 + rise, 20.0 + 0.5 * rise + p[1]].into())
//!     }
//! }
//!
//! /// The surrogate: `20 + gain_j * load / k (+ offset)`, gains fitted by least squares.
//! #[derive(Default)]
//! struct Form {
//!     gain: [f64; 2],
//! }
//! impl Surrogate for Form {
//!     type Scenario = f64;
//!     fn fit(&mut self, data: TrainingSet<'_, f64>, _seed: u64) -> kalibre_core::Result<FitSummary> {
//!         for j in 0..2 {
//!             let (mut xx, mut xy) = (0.0, 0.0);
//!             for s in data.samples {
//!                 let x = data.scenarios[s.snapshot] / s.params[0];
//!                 let y = s.outputs[j] - 20.0 - if j == 1 { s.params[1] } else { 0.0 };
//!                 xx += x * x;
//!                 xy += x * y;
//!             }
//!             self.gain[j] = xy / xx;
//!         }
//!         Ok(FitSummary::default())
//!     }
//!     fn predict(&self, load_w: &f64, p: &[f64]) -> Vec<f64> {
//!         let x = load_w / p[0];
//!         vec![20.0 + self.gain[0] * x, 20.0 + self.gain[1] * x + p[1]]
//!     }
//!     fn vjp(&self, load_w: &f64, p: &[f64], g: &[f64]) -> Vec<f64> {
//!         let dx_dk = -load_w / (p[0] * p[0]);
//!         vec![(g[0] * self.gain[0] + g[1] * self.gain[1]) * dx_dk, g[1]]
//!     }
//! }
//!
//! # fn main() -> kalibre_core::Result<()> {
//! let space = ParamSpace::new()
//!     .with("k", 1.0, 10.0, 2.0, Scale::Log)?
//!     .with("offset_c", 0.0, 5.0, 1.0, Scale::Linear)?;
//! let outputs = ["inlet", "outlet"]
//!     .map(|n| OutputInfo { name: n.into(), group: "all".into() })
//!     .to_vec();
//! // Measured with k = 4 and an offset of 1.5.
//! let snapshot = |label: &str, load_w: f64| Snapshot {
//!     label: label.into(),
//!     scenario: load_w,
//!     measured: vec![Some(20.0 + load_w / 4.0), Some(20.0 + load_w / 8.0 + 1.5)],
//! };
//! let obs = Observations::new(outputs, vec![snapshot("low", 10.0), snapshot("high", 30.0)])?;
//!
//! let report = Calibrator::new(&Rise, Form::default(), &obs, &space)
//!     .with_seed(1)
//!     .with_max_iterations(10)
//!     .with_target_score(1e-3)
//!     .run()?;
//! assert!((report.best.params.get("k").unwrap() - 4.0).abs() < 0.02);
//! assert!((report.best.params.get("offset_c").unwrap() - 1.5).abs() < 0.01);
//! assert!(report.best.mae_c < 1e-3 && report.initial.mae_c.unwrap() > 1.0);
//! # Ok(())
//! # }
//! ```

#![warn(missing_docs)]

pub mod calibrate;
mod data;
pub mod diagnose;
mod error;
pub mod external;
mod fsio;
pub mod gp;
mod linalg;
mod model;
mod number;
pub mod observe;
mod param;
pub mod search;
mod store;
mod surrogate;
mod validate;

pub use calibrate::{Calibrator, Report, Settings, StopReason};

pub use data::{Observations, OutputInfo, Snapshot};
pub use error::{Error, Result};
pub use fsio::write_atomic;
pub use gp::GaussianProcess;
pub use model::{check_outputs, scenario_digest, Model, ModelError, Outputs};
pub use number::{
    number, some_names, unprintable_name, within_magnitude, MAX_MAGNITUDE, MAX_NAME_CHARS,
};
pub use observe::{Event, Observe};
pub use param::{Param, ParamSpace, Scale};
pub use search::{
    Adam, DifferentialEvolution, Hybrid, Objective, Regularizer, SearchOutcome, Searcher,
    SurrogateObjective, TracePoint,
};
pub use store::{BadLine, LoadReport, RunRecord, RunStatus, RunStore};
pub use surrogate::{FitSummary, Sample, Surrogate, TrainingSet};
pub use validate::{check_prediction_shape, ErrorMetrics, ErrorStats, Validation, Validator};
