//! The calibration report (`report.json`, formats.md section 3) and its parts.
//!
//! Key names follow the contract (`mae_c`, `residuals[].sensor`, ...) whatever the domain:
//! `_c` and `sensor` are the data hall's (degrees C, a temperature sensor), kept because
//! other tools read these files. An error (`mae_c`, `rmse_c`, `max_abs_c`) is in the
//! outputs' own units, or in scale units when the observations have scales
//! ([`crate::Observations::with_scales`]); a residual row's `measured_c` and
//! `predicted_c` are always in the outputs' own units.

use std::collections::BTreeMap;
use std::fmt;

use serde::de::{MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::Settings;
use crate::{ErrorStats, LoadReport};

/// Schema tag of [`Report`].
pub const REPORT_SCHEMA: &str = "kalibre.report/1";

/// Parameter values by name, kept in parameter order; a JSON object.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NamedValues(pub Vec<(String, f64)>);

impl NamedValues {
    /// Pairs names with values.
    pub fn new(names: &[String], values: &[f64]) -> Self {
        NamedValues(names.iter().cloned().zip(values.iter().copied()).collect())
    }

    /// Whether it holds no value.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The value of a name.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }

    /// The values in order.
    pub fn values(&self) -> Vec<f64> {
        self.0.iter().map(|(_, v)| *v).collect()
    }
}

impl Serialize for NamedValues {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for NamedValues {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = NamedValues;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object of parameter values by name")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<NamedValues, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, f64>()? {
                    if out.iter().any(|(n, _): &(String, f64)| *n == k) {
                        return Err(serde::de::Error::custom(format!(
                            "duplicate parameter `{k}`"
                        )));
                    }
                    out.push((k, v));
                }
                Ok(NamedValues(out))
            }
        }
        deserializer.deserialize_map(V)
    }
}

/// MAE, RMSE and max absolute error of a set of values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Errors {
    /// Mean absolute error, in the outputs' own units (C for a data hall), or in scale
    /// units with [`crate::Observations::with_scales`] (as every error of the report).
    pub mae_c: f64,
    /// Root-mean-square error.
    pub rmse_c: f64,
    /// Largest absolute error.
    pub max_abs_c: f64,
    /// Values compared.
    pub count: usize,
}

impl From<ErrorStats> for Errors {
    fn from(s: ErrorStats) -> Self {
        Errors {
            mae_c: s.mae,
            rmse_c: s.rmse,
            max_abs_c: s.max_abs,
            count: s.count,
        }
    }
}

/// Errors of one snapshot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SnapshotErrors {
    /// Snapshot label.
    pub snapshot: String,
    /// Mean absolute error, in the outputs' own units (C for a data hall), or in scale
    /// units with [`crate::Observations::with_scales`].
    pub mae_c: f64,
    /// Root-mean-square error.
    pub rmse_c: f64,
    /// Largest absolute error.
    pub max_abs_c: f64,
}

/// Wall times of one iteration, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Timings {
    /// Step 1: surrogate fit.
    pub fit_s: f64,
    /// Step 2: search.
    pub search_s: f64,
    /// Step 3: model runs (wall time of the parallel batch).
    pub model_s: f64,
    /// The whole iteration.
    pub total_s: f64,
}

/// One evaluated point of the history: a four-step iteration's, or a polish step's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IterationRecord {
    /// 1-based iteration (polish steps number on past the loop's).
    pub iteration: usize,
    /// Every model run so far, initial design and journal replays included.
    pub model_runs: usize,
    /// Overall MAE of the model at this iteration's parameters (`None`: a run failed),
    /// in the outputs' own units (C for a data hall), or in scale units with
    /// [`crate::Observations::with_scales`].
    pub mae_c: Option<f64>,
    /// Overall RMSE.
    pub rmse_c: Option<f64>,
    /// Overall max absolute error.
    pub max_abs_c: Option<f64>,
    /// The validator's score (lower is better).
    pub score: Option<f64>,
    /// Best overall MAE so far.
    pub best_mae_c: Option<f64>,
    /// Per snapshot, in snapshot order (empty when a run failed).
    pub per_snapshot: Vec<SnapshotErrors>,
    /// Per output group (e.g. aisle).
    pub per_group: BTreeMap<String, Errors>,
    /// Surrogate training MSE after step 1.
    #[serde(deserialize_with = "crate::number::null_as_nan")]
    pub fit_mse: f64,
    /// Training samples of step 1 (augmented copies included).
    pub training_samples: usize,
    /// Search loss at the proposal (step 2).
    #[serde(deserialize_with = "crate::number::null_as_nan")]
    pub search_loss: f64,
    /// The data term of the search loss (surrogate MSE against the measurements) at the
    /// proposal; `search_loss` minus this is the weighted regulariser.
    #[serde(deserialize_with = "crate::number::null_as_nan")]
    pub search_data_mse: f64,
    /// Objective evaluations of the search.
    pub search_evaluations: usize,
    /// Runs of this iteration that failed.
    pub failed_runs: usize,
    /// True when the proposal was moved off an earlier failed point.
    pub perturbed: bool,
    /// The parameters run, by name.
    pub params: NamedValues,
    /// Wall times.
    pub wall_s: Timings,
}

/// The best parameters found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Best {
    /// Iteration that found them: 0 for the initial design, otherwise the `iteration`
    /// of the [`Report::history`] record of this very point (its parameters and
    /// errors). A polish step's finite-difference runs number their own iteration,
    /// which has a record only when one of them is the best point.
    pub iteration: usize,
    /// Overall MAE, in the outputs' own units (C for a data hall), or in scale units
    /// with [`crate::Observations::with_scales`].
    pub mae_c: f64,
    /// Overall RMSE.
    pub rmse_c: f64,
    /// Overall max absolute error.
    pub max_abs_c: f64,
    /// The validator's score.
    pub score: f64,
    /// Parameters by name.
    pub params: NamedValues,
    /// When the prior judges the best run too ([`super::Settings::prior_in_best`]): the
    /// weighted regulariser at these parameters, in the score's units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<f64>,
    /// A run with a lower score that the prior ruled out: its iteration, score and prior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub passed_over: Option<PassedOver>,
}

/// A run with a lower score than the best one, passed over for the prior's cost there.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PassedOver {
    /// Iteration that ran it (0: the initial design).
    pub iteration: usize,
    /// Its score (default: overall MAE).
    pub score: f64,
    /// The weighted regulariser at its parameters.
    pub prior: f64,
}

/// The model at the initial parameter values, and the initial design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Initial {
    /// Overall MAE at the initial values (`None`: a run failed), in the outputs' own
    /// units (C for a data hall), or in scale units with
    /// [`crate::Observations::with_scales`].
    pub mae_c: Option<f64>,
    /// Overall RMSE.
    pub rmse_c: Option<f64>,
    /// Overall max absolute error.
    pub max_abs_c: Option<f64>,
    /// Initial parameters by name.
    pub params: NamedValues,
    /// Distinct points of the initial design (lower, upper, midpoint, initial values).
    pub design_points: usize,
    /// Model runs of the design (points times snapshots).
    pub design_runs: usize,
    /// Design runs that failed.
    pub failed_runs: usize,
    /// Wall time of the design's runs, seconds.
    pub wall_s: f64,
}

/// A measured value against the best model's prediction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Residual {
    /// Snapshot label.
    pub snapshot: String,
    /// Output (sensor) name.
    pub sensor: String,
    /// Measured value, in the output's own units (C for a data hall), scales or not.
    pub measured_c: f64,
    /// Predicted by the best model, in the output's own units.
    pub predicted_c: f64,
    /// With numerical weighting: the weight the polish gave this reading, `s^2 / (s^2 +
    /// u^2)` (`u` how far the model's numerical variants move it); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight: Option<f64>,
}

/// The best run's residual rows: every measured output of every snapshot, with its
/// numerical weight when the polish weighed them (`weights` in the same row order).
/// `outputs` are as the loop saw them; with scales ([`crate::Observations::with_scales`])
/// the rows are still the measured and predicted values, in the outputs' units.
pub(crate) fn residual_rows<S>(
    obs: &crate::Observations<S>,
    outputs: &[Vec<f64>],
    weights: Option<&[f64]>,
) -> Vec<Residual> {
    let mut weights = weights.into_iter().flatten().copied();
    let mut rows = Vec::new();
    for (s, (snap, pred)) in obs.snapshots().iter().zip(outputs).enumerate() {
        let scale = |k: usize| obs.scales().map_or(1.0, |sc| sc[s][k]);
        for (k, ((info, m), p)) in obs
            .outputs()
            .iter()
            .zip(&snap.measured)
            .zip(pred)
            .enumerate()
        {
            let p = &(p * scale(k));
            if let Some(m) = m {
                rows.push(Residual {
                    snapshot: snap.label.clone(),
                    sensor: info.name.clone(),
                    measured_c: *m,
                    predicted_c: *p,
                    weight: weights.next(),
                });
            }
        }
    }
    rows
}

/// Why the loop stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// `max_iterations` reached.
    MaxIterations,
    /// The best score reached `target_score`.
    TargetError,
    /// Another iteration would exceed `max_model_runs`.
    ModelRunBudget,
    /// `max_wall_s` passed.
    WallClockBudget,
    /// The search proposed a point already run.
    Converged,
}

/// In words, for summaries: `iteration budget used`, `converged (...)`.
impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            StopReason::MaxIterations => "iteration budget used",
            StopReason::TargetError => "target error reached",
            StopReason::ModelRunBudget => "model-run budget reached",
            StopReason::WallClockBudget => "wall-time budget passed",
            StopReason::Converged => "converged (the search proposed a point already run)",
        })
    }
}

/// How many model runs were computed, replayed from the journal, and failed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunCounts {
    /// Every run (new plus cached).
    pub total: usize,
    /// Runs computed by the model in this session.
    pub new: usize,
    /// Runs read back from the run store instead of run: an earlier calibration's
    /// journaled runs, and points this calibration asked for again (a fixed parameter,
    /// a repeated proposal), which the store already holds even when it is in memory.
    pub cached: usize,
    /// Runs that failed (new or cached).
    pub failed: usize,
}

/// The result of a calibration; `report.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Report {
    /// Always [`REPORT_SCHEMA`].
    pub schema: String,
    /// Calibration seed.
    pub seed: u64,
    /// Settings the loop ran with.
    pub settings: Settings,
    /// The best parameters.
    pub best: Best,
    /// How well the measurements determine each parameter at the best run (linearised;
    /// empty when not estimated: more than [`super::UNCERTAINTY_MAX_PARAMS`] parameters, or
    /// no fit ran). Missing in older reports: empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub uncertainty: Vec<super::ParamUncertainty>,
    /// Which slopes `uncertainty` was computed with (the model's own where its runs
    /// measure them, else the surrogate's). Missing in older reports and without an
    /// uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty_slopes: Option<super::UncertaintySlopes>,
    /// Intra-class correlation of the best run's residuals grouped by output over the
    /// snapshots: near 0 when they are noise, near 1 when each output's residual repeats
    /// in every snapshot (a model error the parameters cannot absorb; above
    /// [`super::REPEATED_RESIDUAL_ICC`] reports warn that the values may be biased beyond
    /// their spreads). Missing with one snapshot and in older reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_icc: Option<f64>,
    /// What each numerical variant of the model changed at the best run
    /// (`Calibrator::with_numerical_variant`); empty without variants and in older
    /// reports.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub numerical_checks: Vec<super::NumericalCheck>,
    /// The model at the initial values.
    pub initial: Initial,
    /// One record per four-step iteration, then one per polish step (its Levenberg-
    /// Marquardt point) and one per polish iteration of finite differences whose run
    /// became the best point ([`Best::iteration`]); numbers increase, with gaps where a
    /// Jacobian's runs have no record.
    pub history: Vec<IterationRecord>,
    /// Residuals of the best model, per snapshot and measured output.
    pub residuals: Vec<Residual>,
    /// Why the loop stopped.
    pub stop_reason: StopReason,
    /// Run counts.
    pub runs: RunCounts,
    /// What loading the journal found (`None` without a journal file).
    pub journal: Option<LoadReport>,
    /// The journal's runs this calibration did not reach (a budget smaller than the one
    /// that wrote them), and the best point among them; missing when it reached all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unreached: Option<super::UnreachedRuns>,
    /// Wall time of the whole calibration, seconds.
    pub wall_s: f64,
    /// How the calibrated model was set up, as its domain describes it (e.g. the CLI's
    /// `{ "kind": "builtin", "grid_m": 0.2, "alpha": "per_type" }`), so that a later
    /// command can run the same model. The loop itself leaves it empty. Missing in
    /// older reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<serde_json::Value>,
}

impl Report {
    /// Where the best point was found, in words: `iteration 9`, `the polish, after the
    /// loop's 10 iterations` (polish records fit no surrogate, so they have no training
    /// samples; their numbers count on past the loop's), or `the initial design`.
    pub fn best_found_in(&self) -> String {
        let loop_iterations = self
            .history
            .iter()
            .filter(|h| h.training_samples > 0)
            .count();
        let last_loop_iteration = (self.history.iter())
            .filter(|h| h.training_samples > 0)
            .map(|h| h.iteration)
            .max()
            .unwrap_or(0);
        let s = if loop_iterations == 1 { "" } else { "s" };
        let polish = format!("the polish, after the loop's {loop_iterations} iteration{s}");
        match self
            .history
            .iter()
            .find(|h| h.iteration == self.best.iteration)
        {
            Some(h) if h.training_samples == 0 => polish,
            None if self.best.iteration == 0 => "the initial design".to_string(),
            // A finite-difference probe the polish ran between its records (a report
            // written before such a best point had a record of its own).
            None if self.best.iteration > last_loop_iteration => polish,
            _ => format!("iteration {}", self.best.iteration),
        }
    }

    /// What the residual's repetition over the snapshots (`residual_icc`, when above
    /// [`super::REPEATED_RESIDUAL_ICC`]) says, in words, for the summary and
    /// `report.html`: a model error the parameters cannot absorb, or a fit not finished.
    pub fn repeated_residual_note(&self) -> Option<String> {
        let icc = self
            .residual_icc
            .filter(|r| *r > super::REPEATED_RESIDUAL_ICC)?;
        let share = format!(
            "{:.0}% of the residual repeats at the same sensors in every snapshot",
            100.0 * icc
        );
        // A fit stopped short of the data's optimum repeats too (its parameters are off
        // the same way in every snapshot): a per-server alpha or a few iterations.
        Some(format!(
            "{share}: the model misses something the parameters cannot absorb, or the fit \
             has not finished, and the values may be off by more than their spreads (kalibre \
             diagnose looks for what is missing; when it finds nothing, more iterations or \
             the polish may be what is)"
        ))
    }
}
