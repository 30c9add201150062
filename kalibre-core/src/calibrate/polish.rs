//! The optional last stage of the loop: Levenberg-Marquardt on the model itself.
//!
//! The surrogate finds the basin; near the optimum its own error (a fraction of a degree
//! on a hall) is as large as the differences it must resolve, so the loop stalls above
//! what the model can reach. When model runs are cheap enough, a few Gauss-Newton steps
//! with finite-difference Jacobians of the model close that gap. Each step costs
//! `dim + 1` runs per snapshot after an accepted move (the Jacobian), one per snapshot
//! after a rejected one (the Jacobian is kept, the damping raised). Every run goes through
//! the same runner as the loop's: journaled, replayed on resume, failures recorded.
//!
//! A Jacobian's runs take an iteration number of their own, and the step after it the
//! next; each step has a history record, and the Jacobian's iteration one too when one of
//! its runs became the best point, so that the report's best iteration always has one
//! (but 0, the initial design, which is recorded under `initial`).

use std::time::Instant;

use super::report::{Errors, IterationRecord, NamedValues, SnapshotErrors, Timings};
use super::robust::{residuals, RobustFit};
use super::runner::{RunResult, Runner};
use super::slopes::ModelJacobian;
use super::state::{PointEval, State};
use super::{Settings, StopReason};
use crate::diagnose::linalg::lstsq;
use crate::{Model, Observations, ParamSpace, Result, Validator};

/// Finite-difference step in the unit box.
const FD_STEP: f64 = 0.01;
/// Initial Marquardt damping (relative to each column's squared norm).
const LAMBDA_START: f64 = 0.01;
/// A step shorter than this (max norm, unit box) ends the polish: nothing left to gain.
const MIN_STEP: f64 = 1e-6;

/// What each polish step adds to its [`IterationRecord`] beyond the run's errors.
pub(crate) struct StepInfo {
    pub fit_mse: f64,
    pub training_samples: usize,
    pub search_loss: f64,
    pub search_data_mse: f64,
    pub search_evaluations: usize,
    pub perturbed: bool,
    pub wall_s: Timings,
}

/// The history record of one evaluated point (loop iteration or polish step).
pub(crate) fn record(
    iteration: usize,
    state: &State,
    eval: &PointEval,
    n_snap: usize,
    names: &[String],
    params: &[f64],
    info: StepInfo,
) -> IterationRecord {
    let v = eval.validation.as_ref();
    IterationRecord {
        iteration,
        model_runs: state.counts.total,
        mae_c: v.map(|v| v.overall.mae),
        rmse_c: v.map(|v| v.overall.rmse),
        max_abs_c: v.map(|v| v.overall.max_abs),
        score: eval.score,
        best_mae_c: state.best.as_ref().map(|b| b.validation.overall.mae),
        per_snapshot: v.map_or_else(Vec::new, |v| {
            v.per_snapshot
                .iter()
                .map(|(l, e)| SnapshotErrors {
                    snapshot: l.clone(),
                    mae_c: e.mae,
                    rmse_c: e.rmse,
                    max_abs_c: e.max_abs,
                })
                .collect()
        }),
        per_group: v.map_or_else(Default::default, |v| {
            v.per_group
                .iter()
                .map(|(g, e)| (g.clone(), Errors::from(*e)))
                .collect()
        }),
        fit_mse: info.fit_mse,
        training_samples: info.training_samples,
        search_loss: info.search_loss,
        search_data_mse: info.search_data_mse,
        search_evaluations: info.search_evaluations,
        failed_runs: n_snap - eval.ok_runs,
        perturbed: info.perturbed,
        params: NamedValues::new(names, params),
        wall_s: info.wall_s,
    }
}

/// The model linearised at a point: its finite-difference Jacobian and the residuals
/// there.
struct Linearisation {
    jacobian: ModelJacobian,
    residuals: Vec<f64>,
    /// With numerical weighting: each row's weight, fitted to these residuals.
    row_weights: Option<Vec<f64>>,
}

/// The score the weighted polish accepts steps by: the validator's MAE with each row
/// weighed.
fn weighted_mae(residuals: &[f64], weights: &[f64]) -> f64 {
    let total: f64 = weights.iter().sum();
    residuals
        .iter()
        .zip(weights)
        .map(|(r, w)| w * r.abs())
        .sum::<f64>()
        / total.max(f64::MIN_POSITIVE)
}

/// What the polish did: its history records, the model's last finite-difference
/// Jacobian, and the budget that cut its steps short (none when it ran its steps or
/// stopped on its own).
pub(crate) struct PolishOutcome {
    pub records: Vec<IterationRecord>,
    pub jacobian: Option<ModelJacobian>,
    pub cut: Option<StopReason>,
}

/// The polish stage's context: what it runs and scores with.
pub(crate) struct Polish<'p, 'r, M: Model, V> {
    pub runner: &'p Runner<'r, M>,
    pub validator: &'p V,
    pub observations: &'p Observations<M::Scenario>,
    pub space: &'p ParamSpace,
    pub settings: &'p Settings,
    pub names: &'p [String],
    pub t_start: Instant,
    /// With numerical weighting: per measured row, the largest change over the model's
    /// numerical variants at the loop's best point.
    pub numerical_changes: Option<&'p [f64]>,
}

impl<M: Model, V: Validator> Polish<'_, '_, M, V> {
    /// The budget (runs or wall time) that leaves no room for `runs` more model runs.
    fn budget_spent(&self, state: &State, runs: usize) -> Option<StopReason> {
        let st = self.settings;
        if st
            .max_model_runs
            .is_some_and(|b| state.counts.total + runs > b)
        {
            Some(StopReason::ModelRunBudget)
        } else if st
            .max_wall_s
            .is_some_and(|w| self.t_start.elapsed().as_secs_f64() >= w)
        {
            Some(StopReason::WallClockBudget)
        } else {
            None
        }
    }

    /// Runs up to `settings.polish_iterations` damped Gauss-Newton steps from the best
    /// point, numbering them after `last_iteration`; returns their history records, the
    /// model's last finite-difference Jacobian (the uncertainty's slopes) and the budget
    /// that cut the steps short, if one did.
    pub(crate) fn run(
        &self,
        state: &mut State,
        last_iteration: usize,
        mut emit: impl FnMut(&IterationRecord),
    ) -> Result<PolishOutcome> {
        let (obs, space) = (self.observations, self.space);
        let n_snap = obs.snapshots().len();
        let dim = space.dim();
        let mut records = Vec::new();
        let mut lambda = LAMBDA_START;
        let mut jac: Option<Linearisation> = None;
        let mut iteration = last_iteration;
        let mut cut = None;
        // With numerical weighting the polish minimises the weighted misfit, which the
        // lowest plain MAE need not: the best point is the weighted optimum, and only an
        // accepted step moves it.
        state.best_held = self.numerical_changes.is_some();
        for _ in 0..self.settings.polish_iterations {
            let Some(best) = state.best.as_ref() else {
                break;
            };
            let mut t_iter = Instant::now();
            let mut model_s = 0.0;
            let stale = jac.as_ref().is_none_or(|l| l.jacobian.unit != best.unit);
            if stale {
                if let Some(spent) = self.budget_spent(state, (dim + 1) * n_snap) {
                    cut = Some(spent);
                    break;
                }
                let (u0, y0) = (best.unit.clone(), best.outputs.clone());
                let r0 = residuals(obs, &y0);
                let row_weights = self
                    .numerical_changes
                    .map(|u| super::numerical::row_weights(&r0, u, dim));
                let mut steps = Vec::with_capacity(dim);
                let mut points = Vec::with_capacity(dim);
                for i in 0..dim {
                    let mut u = u0.clone();
                    u[i] = if u[i] + FD_STEP <= 1.0 {
                        u[i] + FD_STEP
                    } else {
                        u[i] - FD_STEP
                    };
                    steps.push(u[i] - u0[i]);
                    points.push(u);
                }
                let phys: Vec<Vec<f64>> = points
                    .iter()
                    .map(|u| space.from_unit(u))
                    .collect::<Result<_>>()?;
                iteration += 1;
                let t = Instant::now();
                let results = self.runner.run(iteration, &phys)?;
                model_s += t.elapsed().as_secs_f64();
                let mut cols = Vec::with_capacity(dim);
                let mut complete = true;
                let all_ran = |res: &[RunResult]| -> Option<Vec<Vec<f64>>> {
                    res.iter()
                        .map(|r| r.result.as_ref().ok().map(|o| o.values.clone()))
                        .collect()
                };
                let column = |out: &[Vec<f64>], step: f64| -> Vec<f64> {
                    (residuals(obs, out).iter().zip(&r0))
                        .map(|(r, r0)| (r0 - r) / step)
                        .collect()
                };
                let mut failed = Vec::new();
                for (i, res) in results.into_iter().enumerate() {
                    cols.push(match all_ran(&res) {
                        Some(out) => column(&out, steps[i]),
                        None => {
                            failed.push(i);
                            vec![0.0; r0.len()]
                        }
                    });
                    state.absorb(self.validator, obs, iteration, &points[i], &phys[i], res)?;
                }
                // A difference that failed (the model cannot run just beyond the best
                // point: a diverging solver at the box's edge, say) is taken on the other
                // side, so that the polish does not stall there for want of that slope.
                let other_side: Vec<(usize, Vec<f64>)> = failed
                    .iter()
                    .filter_map(|&i| {
                        let mut u = u0.clone();
                        u[i] = u0[i] - steps[i];
                        (0.0..=1.0).contains(&u[i]).then_some((i, u))
                    })
                    .collect();
                // Only with room left for the step as well: a slope without a step to take
                // would only end the polish.
                if !other_side.is_empty()
                    && self
                        .budget_spent(state, (other_side.len() + 1) * n_snap)
                        .is_none()
                {
                    let phys: Vec<Vec<f64>> = (other_side.iter())
                        .map(|(_, u)| space.from_unit(u))
                        .collect::<Result<_>>()?;
                    let t = Instant::now();
                    let results = self.runner.run(iteration, &phys)?;
                    model_s += t.elapsed().as_secs_f64();
                    for (((i, u), p), res) in other_side.iter().zip(&phys).zip(results) {
                        if let Some(out) = all_ran(&res) {
                            cols[*i] = column(&out, -steps[*i]);
                            failed.retain(|f| f != i);
                        }
                        state.absorb(self.validator, obs, iteration, u, p, res)?;
                    }
                }
                // The report names the best point by its iteration, and every number it
                // names has a record: a difference that is now the best gets this
                // iteration's (the step's record, next, is another point's).
                let probe_best = (state.best.as_ref())
                    .filter(|b| b.iteration == iteration)
                    .map(|b| (b.params.clone(), b.eval(n_snap)));
                if let Some((params, eval)) = probe_best {
                    let rec = record(
                        iteration,
                        state,
                        &eval,
                        n_snap,
                        self.names,
                        &params,
                        StepInfo {
                            fit_mse: f64::NAN,
                            training_samples: 0,
                            search_loss: f64::NAN,
                            search_data_mse: f64::NAN,
                            search_evaluations: 0,
                            perturbed: false,
                            wall_s: Timings {
                                fit_s: 0.0,
                                search_s: 0.0,
                                model_s,
                                total_s: t_iter.elapsed().as_secs_f64(),
                            },
                        },
                    );
                    emit(&rec);
                    records.push(rec);
                    // The step's record counts its own time, not the differences' again.
                    (t_iter, model_s) = (Instant::now(), 0.0);
                }
                // A difference failed on both sides leaves its parameter where it is (a
                // zero column).
                if !failed.is_empty() {
                    complete = false;
                }
                jac = Some(Linearisation {
                    jacobian: ModelJacobian {
                        unit: u0,
                        columns: cols,
                        complete,
                    },
                    residuals: r0,
                    row_weights,
                });
            }
            let Some(Linearisation {
                jacobian:
                    ModelJacobian {
                        unit: u0,
                        columns: cols,
                        ..
                    },
                residuals: r0,
                row_weights,
            }) = jac.as_ref()
            else {
                break;
            };
            if let Some(spent) = self.budget_spent(state, n_snap) {
                cut = Some(spent);
                break;
            }
            let t = Instant::now();
            // Under a Student-t, IRLS: the step weighs each row by its residual's weight
            // at the linearisation point.
            let robust = self
                .settings
                .robust_nu
                .and_then(|nu| RobustFit::new(nu, r0));
            // Each row's weight: the t's IRLS weight and the numerics' weight.
            let row_w: Option<Vec<f64>> = match (&robust, row_weights) {
                (None, None) => None,
                (r, n) => Some(
                    (0..r0.len())
                        .map(|k| {
                            r.as_ref().map_or(1.0, |f| f.weight(r0[k]))
                                * n.as_ref().map_or(1.0, |n| n[k])
                        })
                        .collect(),
                ),
            };
            let step = match &row_w {
                None => self.damped_step(u0, r0, cols, lambda),
                Some(w) => {
                    let sw: Vec<f64> = w.iter().map(|w| w.sqrt()).collect();
                    let weigh =
                        |v: &[f64]| -> Vec<f64> { v.iter().zip(&sw).map(|(a, w)| a * w).collect() };
                    let cols_w: Vec<Vec<f64>> = cols.iter().map(|c| weigh(c)).collect();
                    self.damped_step(u0, &weigh(r0), &cols_w, lambda)
                }
            };
            let search_s = t.elapsed().as_secs_f64();
            if step.iter().map(|d| d.abs()).fold(0.0, f64::max) < MIN_STEP {
                break;
            }
            let unit: Vec<f64> = u0
                .iter()
                .zip(&step)
                .map(|(u, d)| (u + d).clamp(0.0, 1.0))
                .collect();
            let params = space.from_unit(&unit)?;
            let before = state.best.as_ref().map(|b| b.rank);
            iteration += 1;
            let t = Instant::now();
            let results = self
                .runner
                .run(iteration, std::slice::from_ref(&params))?
                .pop()
                .unwrap_or_default();
            model_s += t.elapsed().as_secs_f64();
            let eval = state.absorb(self.validator, obs, iteration, &unit, &params, results)?;
            let improved = match row_weights {
                Some(w) => {
                    // Judged as every best point is (docs/formats.md): the misfit, here
                    // weighted, plus the prior when it judges too.
                    let here = weighted_mae(r0, w) + state.prior_cost(&space.from_unit(u0)?);
                    let prior = state.prior_cost(&params);
                    // `absorb` keeps a point's outputs only when every snapshot ran.
                    let better = state
                        .ok_runs
                        .last()
                        .filter(|_| eval.validation.is_some())
                        .map(|(_, o)| o.clone())
                        .filter(|o| weighted_mae(&residuals(obs, o), w) + prior < here);
                    let improved = better.is_some();
                    if let Some(outputs) = better {
                        state.promote(self.validator, obs, iteration, &unit, &params, outputs)?;
                    }
                    improved
                }
                None => {
                    state.best.as_ref().map(|b| b.rank) < before
                        || before.is_none() && state.best.is_some()
                }
            };
            lambda = if improved {
                (lambda / 3.0).max(1e-6)
            } else {
                lambda * 4.0
            };
            // The linearised loss: what the step promised, per measured output.
            let predicted = {
                let mut r = r0.clone();
                for (c, d) in cols.iter().zip(&step) {
                    r.iter_mut().zip(c).for_each(|(ri, ci)| *ri -= ci * d);
                }
                let w = |k: usize| row_weights.as_ref().map_or(1.0, |w| w[k]);
                r.iter()
                    .enumerate()
                    .map(|(k, v)| w(k) * robust.as_ref().map_or(v * v, |f| f.loss(*v)))
                    .sum::<f64>()
                    / (0..r.len()).map(w).sum::<f64>().max(f64::MIN_POSITIVE)
            };
            let rec = record(
                iteration,
                state,
                &eval,
                n_snap,
                self.names,
                &params,
                StepInfo {
                    fit_mse: f64::NAN,
                    training_samples: 0,
                    search_loss: predicted,
                    search_data_mse: predicted,
                    search_evaluations: if stale { dim } else { 0 },
                    perturbed: false,
                    wall_s: Timings {
                        fit_s: 0.0,
                        search_s,
                        model_s,
                        total_s: t_iter.elapsed().as_secs_f64(),
                    },
                },
            );
            emit(&rec);
            records.push(rec);
        }
        state.best_held = false;
        Ok(PolishOutcome {
            records,
            jacobian: jac.map(|l| l.jacobian),
            cut,
        })
    }

    /// The Levenberg-Marquardt step in the unit box: `min |r0 - J d|^2 + lambda sum_j
    /// |J_j|^2 d_j^2`, with parameters the step would push out of the box held at the
    /// bound and the rest solved again.
    fn damped_step(&self, u0: &[f64], r0: &[f64], cols: &[Vec<f64>], lambda: f64) -> Vec<f64> {
        let dim = cols.len();
        let mut free = vec![true; dim];
        let mut step = vec![0.0; dim];
        for _ in 0..dim.max(1) {
            let active: Vec<usize> = (0..dim).filter(|&j| free[j]).collect();
            let a: Vec<&[f64]> = active.iter().map(|&j| cols[j].as_slice()).collect();
            let ridge: Vec<f64> = active
                .iter()
                .map(|&j| lambda * cols[j].iter().map(|v| v * v).sum::<f64>())
                .collect();
            let x = lstsq(&a, r0, &ridge).x;
            step = vec![0.0; dim];
            let mut clipped = false;
            for (k, &j) in active.iter().enumerate() {
                step[j] = x[k];
                let u = u0[j] + x[k];
                if (u < 0.0 && u0[j] <= 0.0) || (u > 1.0 && u0[j] >= 1.0) {
                    free[j] = false;
                    clipped = true;
                }
            }
            if !clipped {
                break;
            }
        }
        step.iter()
            .zip(&free)
            .map(|(d, f)| if *f { *d } else { 0.0 })
            .collect()
    }
}
