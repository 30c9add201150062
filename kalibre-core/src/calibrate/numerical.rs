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

use crate::{Model, Observations};

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

/// Runs each variant once per snapshot at `params`: the checks for the report, and the
/// outputs (per snapshot) of each variant whose every run succeeded.
pub(crate) fn run_variants<M: Model>(
    variants: &[(String, Result<&M, String>)],
    obs: &Observations<M::Scenario>,
    best_outputs: &[Vec<f64>],
    params: &[f64],
) -> (Vec<NumericalCheck>, Vec<Vec<Vec<f64>>>) {
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
                    .map_err(|e| format!("snapshot `{}`: {e}", snap.label))
                    .and_then(|o| {
                        if o.values.len() == obs.outputs().len()
                            && o.values.iter().all(|v| v.is_finite())
                        {
                            Ok(o.values)
                        } else {
                            Err(format!(
                                "snapshot `{}`: {} outputs, not all finite, where {} were expected",
                                snap.label,
                                o.values.len(),
                                obs.outputs().len()
                            ))
                        }
                    })
            })
            .collect();
        match runs {
            Ok(v) => {
                let (mut sum, mut n) = (0.0, 0usize);
                for ((snap, var), base) in obs.snapshots().iter().zip(&v).zip(best_outputs) {
                    for ((m, a), b) in snap.measured.iter().zip(var).zip(base) {
                        if m.is_some() {
                            sum += (a - b).abs();
                            n += 1;
                        }
                    }
                }
                checks.push(NumericalCheck {
                    variant: name.clone(),
                    mean_abs_change: (n > 0).then(|| sum / n as f64),
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
