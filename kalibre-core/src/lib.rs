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
//! TODO(overview example): replaced when the calibrator lands.

#![warn(missing_docs)]

mod data;
mod error;
mod model;
mod param;
pub mod search;
mod surrogate;
mod validate;

pub use data::{Observations, OutputInfo, Snapshot};
pub use error::{Error, Result};
pub use model::{check_outputs, Model, ModelError, Outputs};
pub use param::{Param, ParamSpace, Scale};
pub use search::{Objective, Regularizer, SearchOutcome, Searcher, SurrogateObjective, TracePoint};
pub use surrogate::{FitSummary, Sample, Surrogate, TrainingSet};
pub use validate::{ErrorMetrics, ErrorStats, Validation, Validator};
