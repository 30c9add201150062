//! The cheap surrogate trained on model runs (step 1 of the loop).

use serde::{Deserialize, Serialize};

use crate::Result;

/// One training sample: the outputs of a model run (or an augmented copy of one).
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Index of the snapshot (scenario) in [`TrainingSet::scenarios`].
    pub snapshot: usize,
    /// Physical parameter values.
    pub params: Vec<f64>,
    /// Model outputs.
    pub outputs: Vec<f64>,
    /// Relative weight of the sample in the fit (1 is an ordinary sample; the calibrator
    /// lowers the weight of runs far from the measurements when `Settings::focus` is set).
    pub weight: f64,
}

/// Everything a surrogate is fitted on: the scenarios and the samples that refer to them.
#[derive(Debug, Clone, Copy)]
pub struct TrainingSet<'a, S> {
    /// Scenarios by snapshot index.
    pub scenarios: &'a [S],
    /// Samples; `sample.snapshot` indexes `scenarios`.
    pub samples: &'a [Sample],
}

/// What a fit reports.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FitSummary {
    /// Mean squared error on the training samples after fitting.
    pub train_mse: f64,
    /// Epochs (or iterations) run.
    pub epochs: usize,
    /// The deadline ([`Surrogate::fit_until`]) ended training early: the surrogate holds
    /// the best weights found by then, and `epochs` counts the epochs that ran.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub timed_out: bool,
}

/// A cheap, differentiable stand-in for the model.
///
/// `predict` and `vjp` take physical parameter values. `vjp` is the vector-Jacobian
/// product: for a cotangent `g` over outputs it returns `d(sum_k g_k * out_k) / d params`,
/// which is what gradient searchers need.
pub trait Surrogate {
    /// The scenario type, shared with the [`crate::Model`].
    type Scenario;

    /// Trains on all samples. Deterministic for a given `seed`.
    fn fit(&mut self, data: TrainingSet<'_, Self::Scenario>, seed: u64) -> Result<FitSummary>;

    /// [`Self::fit`] that stops training at `deadline` (checked once per epoch) with the
    /// best weights so far and [`FitSummary::timed_out`] set; a wall-clock budget
    /// (`Settings::max_wall_s`) reaches inside the fit this way. Without a deadline it
    /// is `fit`, bit for bit. The default ignores the deadline: a surrogate whose
    /// training can run long should override it.
    fn fit_until(
        &mut self,
        data: TrainingSet<'_, Self::Scenario>,
        seed: u64,
        deadline: Option<std::time::Instant>,
    ) -> Result<FitSummary> {
        let _ = deadline;
        self.fit(data, seed)
    }

    /// Predicted outputs at a scenario and physical parameters, one per output. The loop
    /// checks this, finite, after each fit at the search's start (an error otherwise).
    fn predict(&self, scenario: &Self::Scenario, params: &[f64]) -> Vec<f64>;

    /// The vector-Jacobian product at a scenario and physical parameters: for a cotangent
    /// `g` (one value per output) the gradient `d(sum_k g_k * out_k) / d params`, one value
    /// per parameter (0 for a parameter the surrogate does not read; checked as
    /// [`Self::predict`] is).
    fn vjp(&self, scenario: &Self::Scenario, params: &[f64], cotangent: &[f64]) -> Vec<f64>;
}
