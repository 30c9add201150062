//! Refitting the leading hypotheses with the model itself (secant steps).
//!
//! The ranking linearises each candidate at the calibrated parameters with the effect
//! absent. A large effect breaks that: a calibration without it has moved the alphas to
//! absorb part of it, and at those alphas a small step of the effect changes little (the
//! 15 % cable cutout of `docs/diagnosis.md`), or its footprint grows faster than
//! linearly. So the leading hypotheses are run at their fitted point (the current
//! parameters moved by their joint change, the effect at its fitted value), and each one's
//! Jacobian column is replaced by the secant that makes the linear model exact there:
//!
//! `h = (y(p, q) - y(p0, 0) - J (p - p0)) / q`
//!
//! Ranked again with those columns, each refit hypothesis is scored at a point the model
//! has actually run, against the same no-effect refit as before. A few such steps are a
//! secant (quasi-Newton) iteration on the effect's size; each costs one solve per snapshot
//! and hypothesis. A hypothesis none of whose runs reads better than the calibrated model
//! is refuted ([`Hypothesis::refuted`]): listed, never significant.

use ndarray::Array2;
use rayon::prelude::*;
use serde::Serialize;

use kalibre_core::diagnose::{diagnose, Diagnosis, Hypothesis, Residuals};
use kalibre_core::{Observations, ParamSpace};

use super::{absent, effect_list, effect_step_size, HallDiagnosisSettings};
use crate::effects::Effect;
use crate::snapshots::OperatingState;
use crate::{ParamLayout, Result};

/// One model run of a refit: the point and what the model read there.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RefitStep {
    /// The effect's value the model ran at.
    pub effect_value: f64,
    /// Mean absolute residual of the model there, over the measured values (C).
    pub model_mae_c: f64,
    /// Whether it read better than every earlier point (the calibrated one included), so
    /// that the hypothesis's column is now the secant through it.
    pub accepted: bool,
}

/// The secant refit of one hypothesis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Refit {
    /// Hypothesis name.
    pub name: String,
    /// The model runs, in order (one solve per snapshot each).
    pub steps: Vec<RefitStep>,
    /// Why it stopped before its last iteration, if it did (a failed run, a fitted value
    /// out of range, no step improving on the best point).
    pub stopped: Option<String>,
}

/// A refit stops when its step towards the ranking's fit has been halved this far without
/// reading better than its best point: the linearisation there points nowhere useful.
const MIN_SHARE: f64 = 0.2;

/// The hall, the calibrated point and its linearisation: what a refit runs and updates.
pub(super) struct Linearisation<'a> {
    pub layout: &'a ParamLayout,
    pub space: &'a ParamSpace,
    pub effects: &'a [Box<dyn Effect>],
    pub params: &'a [f64],
    pub obs: &'a Observations<OperatingState>,
    pub states: &'a [&'a OperatingState],
    /// Outputs of the calibrated point, per snapshot.
    pub base: &'a [Vec<f64>],
    /// Jacobian of the calibrated parameters, per snapshot (`outputs x params`).
    pub jac: &'a [Array2<f64>],
    pub residuals: &'a Residuals,
}

/// A hypothesis as the ranking sees it, with the candidate effect behind it.
pub(super) struct Candidate<'a> {
    pub effect: &'a dyn Effect,
    pub hypothesis: Hypothesis,
}

/// Refits the `settings.refit_top` leading one-parameter hypotheses of `diagnosis` (in its
/// order, fitted within their range and not inert) for up to `settings.refit_iterations`
/// secant steps each, and ranks all hypotheses again. Returns the new ranking and what
/// each refit ran.
pub(super) fn refit_leading(
    lin: &Linearisation<'_>,
    candidates: &mut [Candidate<'_>],
    mut diagnosis: Diagnosis,
    settings: &HallDiagnosisSettings,
    solver: &dyn super::EffectSolver,
) -> Result<(Diagnosis, Vec<Refit>)> {
    let index_of = |name: &str| candidates.iter().position(|c| c.hypothesis.name == name);
    let picked: Vec<usize> = diagnosis
        .hypotheses
        .iter()
        .filter(|h| h.in_range && !h.inert)
        .filter_map(|h| index_of(&h.name))
        .filter(|&c| candidates[c].effect.parameters().len() == 1)
        .take(settings.refit_top)
        .collect();
    let mut refits: Vec<Refit> = picked
        .iter()
        .map(|&c| Refit {
            name: candidates[c].hypothesis.name.clone(),
            steps: Vec::new(),
            stopped: None,
        })
        .collect();
    let names = lin.space.names();
    // Per refit: the best point run so far (parameters, effect value, model MAE; at first
    // the calibrated point, effect absent) and the share of the way to the ranking's fit
    // the next run goes (halved after a run that reads worse than the best).
    let mut best: Vec<(Vec<f64>, f64, f64)> = picked
        .iter()
        .map(|&c| {
            let q0 = absent(&candidates[c].effect.parameters()[0]);
            (lin.params.to_vec(), q0, diagnosis.mae)
        })
        .collect();
    let mut share = vec![1.0_f64; picked.len()];
    for _ in 0..settings.refit_iterations {
        // Each live refit's point: from its best point towards the ranking's joint fit
        // (the current parameters' change, within their bounds, and the effect's value),
        // the effect at least half the ranking's step from absent (below that a run says
        // nothing the linearisation did not).
        let mut points: Vec<(usize, Vec<f64>, f64)> = Vec::new();
        for (k, &c) in picked.iter().enumerate() {
            if refits[k].stopped.is_some() {
                continue;
            }
            if share[k] < MIN_SHARE {
                refits[k].stopped = Some("no step read better than the best point".into());
                continue;
            }
            let name = &candidates[c].hypothesis.name;
            let Some(h) = diagnosis.hypotheses.iter().find(|h| &h.name == name) else {
                continue;
            };
            let param = &candidates[c].effect.parameters()[0];
            let dq = h.fitted.values().first().copied().unwrap_or(0.0);
            if !h.in_range {
                refits[k].stopped = Some(format!("fitted value {dq:.4} out of its range"));
                continue;
            }
            let (from_p, from_q, _) = &best[k];
            let t = share[k];
            let min_dq = 0.5 * effect_step_size(settings, param);
            let q_fit = absent(param) + dq;
            // The effect at least `min_dq` from absent, on the fit's side of it (an
            // offset may be fitted below its absence, a leak only above).
            let side = if dq < 0.0 { -1.0 } else { 1.0 };
            let towards = from_q + t * (q_fit - from_q);
            let q = if side * (towards - absent(param)) < min_dq {
                absent(param) + side * min_dq
            } else {
                towards
            }
            .clamp(param.lower, param.upper);
            let p: Vec<f64> = lin
                .params
                .iter()
                .zip(from_p)
                .zip(lin.space.params())
                .zip(&names)
                .map(|(((x0, from), bound), n)| {
                    let fit = x0 + h.current_change.get(n).unwrap_or(0.0);
                    (from + t * (fit - from)).clamp(bound.lower, bound.upper)
                })
                .collect();
            points.push((k, p, q));
        }
        if points.is_empty() {
            break;
        }
        let jobs: Vec<(usize, usize)> = (0..points.len())
            .flat_map(|i| (0..lin.states.len()).map(move |s| (i, s)))
            .collect();
        let outputs: Vec<Result<Vec<f64>>> = jobs
            .par_iter()
            .map(|&(i, s)| {
                let (k, p, q) = &points[i];
                let vals: Vec<Vec<f64>> = (0..lin.effects.len())
                    .map(|e| lin.layout.effect_values(p, e).to_vec())
                    .collect();
                let mut list = effect_list(lin.effects, &vals);
                let qv = [*q];
                list.push((candidates[picked[*k]].effect, &qv));
                solver.solve(lin.states[s], &lin.layout.alpha_per_server(p), &list)
            })
            .collect();
        let mut outputs = outputs.into_iter();
        for (k, p, q) in points {
            let runs: Vec<Result<Vec<f64>>> = outputs.by_ref().take(lin.states.len()).collect();
            let runs: Vec<Vec<f64>> = match runs.into_iter().collect::<Result<_>>() {
                Ok(r) => r,
                Err(e) => {
                    refits[k].stopped = Some(format!("a run failed: {e}"));
                    continue;
                }
            };
            let at_point = Residuals::from_observations(lin.obs, &runs, lin.jac, names.clone())?;
            let r = at_point.residuals();
            let mae = r.iter().map(|x| x.abs()).sum::<f64>() / r.len() as f64;
            let accepted = mae < best[k].2;
            refits[k].steps.push(RefitStep {
                effect_value: q,
                model_mae_c: mae,
                accepted,
            });
            if !accepted {
                share[k] *= 0.5;
                continue;
            }
            let c = picked[k];
            let param = &candidates[c].effect.parameters()[0];
            let dq = q - absent(param);
            let dp: Vec<f64> = p.iter().zip(lin.params).map(|(a, b)| a - b).collect();
            let blocks: Vec<Array2<f64>> = runs
                .iter()
                .enumerate()
                .map(|(s, y)| {
                    let lin_part = lin.jac[s].dot(&ndarray::ArrayView1::from(&dp));
                    Array2::from_shape_fn((y.len(), 1), |(o, _)| {
                        (y[o] - lin.base[s][o] - lin_part[o]) / dq
                    })
                })
                .collect();
            let old = &candidates[c].hypothesis;
            candidates[c].hypothesis =
                Hypothesis::from_snapshots(old.name.clone(), old.params.clone(), lin.obs, &blocks)?;
            best[k] = (p, q, mae);
            share[k] = 1.0;
        }
        // A hypothesis every one of whose runs, towards its fit, read worse than the
        // calibrated model is refuted by the model itself: its linearisation promised an
        // improvement the model does not give.
        for (k, &c) in picked.iter().enumerate() {
            let steps = &refits[k].steps;
            candidates[c].hypothesis.refuted =
                !steps.is_empty() && steps.iter().all(|s| !s.accepted);
        }
        let hypotheses: Vec<Hypothesis> = candidates.iter().map(|c| c.hypothesis.clone()).collect();
        diagnosis = diagnose(lin.residuals, &hypotheses, &settings.diagnose)?;
    }
    Ok((diagnosis, refits))
}
