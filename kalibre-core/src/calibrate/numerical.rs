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

/// [`NumericalCheck::error`] of a variant not run because the wall budget had passed.
pub const SKIPPED_PAST_WALL: &str = "not run: the wall-time budget (max_wall_s) had passed";

impl NumericalCheck {
    /// One line for summaries: `grid 0.1 m: the sensors move 0.074 C`, or why it failed.
    pub fn describe(&self) -> String {
        match (&self.error, self.mean_abs_change) {
            (Some(e), _) if e == SKIPPED_PAST_WALL => format!("{}: {e}", self.variant),
            (Some(e), _) => format!("{}: failed ({e})", self.variant),
            (None, Some(m)) => format!("{}: the sensors move {m:.3} C", self.variant),
            (None, None) => format!("{}: nothing measured", self.variant),
        }
    }
}

/// Per measured row (the residuals' order), a variant's output minus the best run's.
pub(crate) fn output_change<S>(
    obs: &Observations<S>,
    variant_outputs: &[Vec<f64>],
    best_outputs: &[Vec<f64>],
) -> Vec<f64> {
    measured_rows(obs, variant_outputs)
        .zip(measured_rows(obs, best_outputs))
        .map(|((_, _, v), (_, _, b))| v - b)
        .collect()
}

/// What the variants gave at one point (unit box): the checks for the report and the
/// outputs (per snapshot) of each variant whose every run succeeded.
pub(crate) struct VariantRuns {
    pub unit: Vec<f64>,
    pub checks: Vec<NumericalCheck>,
    pub outputs: Vec<Vec<Vec<f64>>>,
}

/// What the uncertainty weighs with the model's numerics: the variants' outputs at the
/// best point, and each row's weight when the polish weighed the rows.
#[derive(Clone, Copy, Default)]
pub(crate) struct Numerics<'a> {
    pub variant_outputs: &'a [Vec<Vec<f64>>],
    pub weights: Option<&'a [f64]>,
}

/// Runs each variant once per snapshot at `params`: the checks for the report, and the
/// outputs (per snapshot) of each variant whose every run succeeded.
pub(crate) fn run_variants<M: Model>(
    variants: &[(String, Result<&M, String>)],
    obs: &Observations<M::Scenario>,
    scales: Option<&[Vec<f64>]>,
    best_outputs: &[Vec<f64>],
    params: &[f64],
    deadline: Option<std::time::Instant>,
) -> (Vec<NumericalCheck>, Vec<Vec<Vec<f64>>>) {
    let names: Vec<String> = obs.outputs().iter().map(|o| o.name.clone()).collect();
    let mut checks = Vec::new();
    let mut outputs = Vec::new();
    for (name, model) in variants {
        // A finer grid's runs are the costliest of the calibration: past the wall budget
        // they would overshoot it by more than any step it allows.
        if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
            checks.push(NumericalCheck {
                variant: name.clone(),
                mean_abs_change: None,
                error: Some(SKIPPED_PAST_WALL.into()),
            });
            continue;
        }
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
            .enumerate()
            .map(|(i, snap)| {
                model
                    .evaluate(&snap.scenario, params)
                    .and_then(|o| check_outputs(o, &names))
                    .map(|o| super::runner::scaled(o, scales.map(|sc| &sc[i][..])).values)
                    .map_err(|e| format!("{} `{}`: {e}", obs.noun(), snap.label))
            })
            .collect();
        match runs {
            Ok(v) => {
                let changes: Vec<f64> = output_change(obs, &v, best_outputs)
                    .iter()
                    .map(|c| c.abs())
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

/// Per measured row (the residuals' order), the largest change of any variant's output
/// from `best_outputs`; none without a variant that ran at every snapshot.
pub(crate) fn row_changes<S>(
    obs: &Observations<S>,
    best_outputs: &[Vec<f64>],
    variant_outputs: &[Vec<Vec<f64>>],
) -> Option<Vec<f64>> {
    let mut acc: Option<Vec<f64>> = None;
    for outputs in variant_outputs {
        let change: Vec<f64> = output_change(obs, outputs, best_outputs)
            .iter()
            .map(|c| c.abs())
            .collect();
        if change.iter().any(|c| !c.is_finite()) {
            continue;
        }
        match acc.as_mut() {
            None => acc = Some(change),
            Some(a) if a.len() == change.len() => {
                a.iter_mut().zip(&change).for_each(|(a, c)| *a = a.max(*c));
            }
            Some(_) => {}
        }
    }
    acc
}

/// Generalised least squares with the numerics as a per-row error: row `k` has variance
/// `s^2 + u_k^2` (`u_k` its numerical change), and `s^2` is the noise variance at which
/// the weighted squared residuals sum to their degrees of freedom, `m - dim` (a moment
/// estimate: the noise is what the numerics leave unexplained). Returns the relative
/// weights `s^2 / (s^2 + u_k^2)`, 1 for a row the numerics do not move.
pub(crate) fn row_weights(residuals: &[f64], changes: &[f64], dim: usize) -> Vec<f64> {
    let m = residuals.len();
    if m == 0 || changes.len() != m {
        return vec![1.0; m];
    }
    let mean_sq = residuals.iter().map(|r| r * r).sum::<f64>() / m as f64;
    if !(mean_sq > 0.0 && mean_sq.is_finite()) {
        return vec![1.0; m];
    }
    let dof = m.saturating_sub(dim).max(1) as f64;
    let floor = 1e-6 * mean_sq;
    let chi2 = |s2: f64| -> f64 {
        residuals
            .iter()
            .zip(changes)
            .map(|(r, u)| r * r / (s2 + u * u).max(floor))
            .sum()
    };
    // chi2 falls as s^2 grows; at `mean_sq * m / dof` it is at most `dof`.
    let (mut lo, mut hi) = (0.0, mean_sq * m as f64 / dof);
    if chi2(lo) <= dof {
        hi = lo;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if chi2(mid) > dof {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let s2 = hi.max(floor);
    changes.iter().map(|u| s2 / (s2 + u * u)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_the_numerics_do_not_move_weigh_one_and_the_noise_is_recovered() {
        // 100 rows of +-1 noise; the last 10 also carry a numerical error of 3 that their
        // changes report.
        let mut r: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let mut u = vec![0.0; 100];
        for k in 90..100 {
            r[k] += 3.0;
            u[k] = 3.0;
        }
        let w = row_weights(&r, &u, 0);
        assert!(w[..90].iter().all(|&w| w == 1.0));
        // s^2 near 1 (the noise): the moved rows weigh about 1 / (1 + 9).
        for &wk in &w[90..] {
            assert!(wk > 0.07 && wk < 0.14, "weight {wk}");
        }
        // Without numerical changes every row weighs 1.
        assert!(row_weights(&r, &[0.0; 100], 3).iter().all(|&w| w == 1.0));
    }

    #[test]
    fn residuals_the_numerics_fully_explain_leave_only_the_unmoved_rows() {
        let r = [0.5, -0.5, 2.0, -2.0];
        let w = row_weights(&r, &[0.0, 0.0, 100.0, 100.0], 2);
        assert!(w[0] == 1.0 && w[1] == 1.0);
        assert!(w[2] < 1e-3 && w[3] < 1e-3, "{w:?}");
    }
}
