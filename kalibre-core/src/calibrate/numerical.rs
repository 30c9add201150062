//! The model's numerical uncertainty: how far the calibrated parameters would move if
//! only the model's numerics changed (a finer grid, tighter tolerances).
//!
//! A discretised model errs by its grid at every sensor, in every snapshot, the same way;
//! the parameters absorb that error like any other model error, and no number of
//! measurements averages it away. So, as in verification and validation practice (ASME
//! V&V 20: the numerical uncertainty beside the input and data ones), each numerical
//! variant of the model runs once per snapshot at the best parameters; the change of its
//! outputs, pushed through the same linearisation as the spreads
//! ([`super::uncertainty`]), is the shift of each parameter that the numerics alone
//! cause. Which variant is nearer the truth is not known, so the largest shift over the
//! variants counts, combined in quadrature with the data's spread when a parameter is
//! called identified.

use serde::{Deserialize, Serialize};

use super::robust::measured_rows;
use crate::{check_outputs, Model, Observations};

/// What one numerical variant of the model gave at the best parameters (`report.json`,
/// `numerical_checks`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NumericalCheck {
    /// The variant, e.g. `grid 0.1 m`.
    pub variant: String,
    /// Mean absolute change of the measured outputs from the best run's (outputs' units);
    /// none when a run failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_abs_change: Option<f64>,
    /// Why the variant gave nothing, when a run failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl NumericalCheck {
    /// One line for summaries: `grid 0.1 m: the sensors move 0.074 C`, or why it failed.
    pub fn describe(&self) -> String {
        match (&self.error, self.mean_abs_change) {
            (Some(e), _) => format!("{}: failed ({e})", self.variant),
            (None, Some(m)) => format!("{}: the sensors move {m:.3} C", self.variant),
            (None, None) => format!("{}: nothing measured", self.variant),
        }
    }
}

/// Runs each variant once per snapshot at `params`: the checks for the report, and the
/// outputs (per snapshot) of each variant whose every run succeeded.
pub(crate) fn run_variants<M: Model>(
    variants: &[(String, Result<&M, String>)],
    obs: &Observations<M::Scenario>,
    best_outputs: &[Vec<f64>],
    params: &[f64],
) -> (Vec<NumericalCheck>, Vec<Vec<Vec<f64>>>) {
    let names: Vec<String> = obs.outputs().iter().map(|o| o.name.clone()).collect();
    let mut checks = Vec::new();
    let mut outputs = Vec::new();
    for (name, model) in variants {
        let model = match model {
            Ok(m) => m,
            Err(reason) => {
                checks.push(NumericalCheck {
                    variant: name.clone(),
                    mean_abs_change: None,
                    error: Some(format!("not set up: {reason}")),
                });
                continue;
            }
        };
        // One snapshot at a time: a finer grid's solve is the memory's largest user.
        let runs: Result<Vec<Vec<f64>>, String> = obs
            .snapshots()
            .iter()
            .map(|snap| {
                model
                    .evaluate(&snap.scenario, params)
                    .and_then(|o| check_outputs(o, &names))
                    .map(|o| o.values)
                    .map_err(|e| format!("snapshot `{}`: {e}", snap.label))
            })
            .collect();
        match runs {
            Ok(v) => {
                let changes: Vec<f64> = measured_rows(obs, &v)
                    .zip(measured_rows(obs, best_outputs))
                    .map(|((_, _, a), (_, _, b))| (a - b).abs())
                    .collect();
                checks.push(NumericalCheck {
                    variant: name.clone(),
                    mean_abs_change: (!changes.is_empty())
                        .then(|| changes.iter().sum::<f64>() / changes.len() as f64),
                    error: None,
                });
                outputs.push(v);
            }
            Err(e) => checks.push(NumericalCheck {
                variant: name.clone(),
                mean_abs_change: None,
                error: Some(e),
            }),
        }
    }
    (checks, outputs)
}
