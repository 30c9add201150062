//! Refitting the leading candidate effects with the model itself (secant steps).
//!
//! [`linearise`](super::linearise) measures each candidate's footprint by one step from
//! its absent value. A large or curved effect breaks that: the fitted size is the step's
//! slope carried far beyond the step, and the model reads otherwise there. So each of the
//! leading hypotheses is run at its fitted point (the calibrated parameters moved by
//! their joint change, the effect at its fitted value), and its columns are updated so
//! that the linear model is exact there: Broyden's rank-one update, in units of each
//! parameter's range, which for a one-parameter effect is the secant through that run,
//!
//! `H' = H + (r(p, q) - r0 - J dp - H dq) dq^T / |dq|^2`.
//!
//! Ranked again with those columns, each refit hypothesis is scored at a point the model
//! has run; its best run ([`Refit::best`]) is the value to take, since the ranking's fit
//! from those columns may lie beyond it. The first run goes where the ranking fitted the
//! candidate; each later one from the best point so far by the ranking's own fit on local
//! slopes that every run updates (the same rank-one update, from the best point), half as
//! far after a run that reads worse or fails. A hypothesis none of whose runs reads better
//! than the baseline is refuted ([`Hypothesis::refuted`]). Each run costs one model run
//! per snapshot, through the journal.

use ndarray::{Array1, Array2};
use serde::Serialize;

use super::{
    diagnose, Calibrated, CandidateEffect, DiagnoseSettings, Diagnosis, Hypothesis,
    HypothesisParam, HypothesisResult, LineariseSettings, Residuals,
};
use crate::calibrate::NamedValues;
use crate::{Error, Model, Result};

/// How many leading hypotheses [`refit_leading`] refits, and how far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefitSettings {
    /// Hypotheses refit: the first ones in the diagnosis's order that are fitted within
    /// their range, move the outputs (not inert) and are not refuted.
    pub top: usize,
    /// Runs of each (one model run per snapshot each).
    pub iterations: usize,
    /// The linearisation's step of a candidate, as a share of its range
    /// ([`LineariseSettings::effect_step`]): a run nearer absent than half of it says
    /// nothing the linearisation did not, so a refit runs at least that far out.
    pub effect_step: f64,
}

impl Default for RefitSettings {
    /// The leading hypothesis, 4 runs, the linearisation's default step.
    fn default() -> Self {
        RefitSettings {
            top: 1,
            iterations: 4,
            effect_step: LineariseSettings::default().effect_step,
        }
    }
}

/// One point a refit ran.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RefitStep {
    /// The candidate's parameters there, as the model takes them.
    pub values: NamedValues,
    /// Every parameter there (the calibrated ones moved with the candidate's).
    pub params: NamedValues,
    /// The model's mean absolute residual there (as [`Diagnosis::mae`]); `None` when a
    /// run failed.
    pub mae: Option<f64>,
    /// Why a run there failed: the next run goes half as far.
    pub failed: Option<String>,
    /// It read better than every earlier point and the baseline, so the hypothesis's
    /// columns are now the secant through it.
    pub accepted: bool,
    /// Calibrated parameters the step would have moved beyond their bounds, held there
    /// for the run: the run is not where the fit pointed, and a worse reading may be the
    /// box's.
    pub clamped: Vec<String>,
}

/// The secant refit of one hypothesis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Refit {
    /// The hypothesis (the candidate effect's name).
    pub name: String,
    /// Its runs, in order.
    pub steps: Vec<RefitStep>,
    /// Why it stopped before its last run, if it did.
    pub stopped: Option<String>,
}

impl Refit {
    /// Its best accepted run, if any: the point the model has run where it reads best,
    /// below the baseline (the ranking's fit, from columns exact there, may lie beyond).
    pub fn best(&self) -> Option<&RefitStep> {
        (self.steps.iter().filter(|s| s.accepted)).min_by(|a, b| {
            let mae = |s: &RefitStep| s.mae.unwrap_or(f64::INFINITY);
            mae(a).total_cmp(&mae(b))
        })
    }
}

/// What [`refit_leading`] made.
#[derive(Debug, Clone)]
pub struct Refitted {
    /// The ranking with the refit columns.
    pub diagnosis: Diagnosis,
    /// The hypotheses it ranks: the refit ones with their secant columns and verdicts.
    pub hypotheses: Vec<Hypothesis>,
    /// What each refit ran.
    pub refits: Vec<Refit>,
    /// Model runs made (not in the journal before).
    pub runs: usize,
    /// Runs read from the journal.
    pub cached: usize,
}

/// A refit stops when its step towards the fit has been halved this far without reading
/// better than its best point: the linearisation there points nowhere useful.
const MIN_SHARE: f64 = 0.2;

/// Refits the `refit.top` leading hypotheses of `hypotheses` (ranked on `residuals`, the
/// linearisation at `at`'s calibrated parameters; one per candidate of `candidates`, by
/// name) with up to `refit.iterations` model runs each, and ranks them again.
/// `baseline_mae` is what a run must read below to be accepted: the calibrated point's
/// MAE, or the calibrated parameters' own refit run by the model
/// ([`Calibrated::run_refit_alone`]) when that reads lower.
pub fn refit_leading<M: Model>(
    at: &Calibrated<'_, M>,
    residuals: &Residuals,
    candidates: &[CandidateEffect],
    mut hypotheses: Vec<Hypothesis>,
    baseline_mae: f64,
    settings: &DiagnoseSettings,
    refit: &RefitSettings,
) -> Result<Refitted> {
    if !(refit.effect_step > 0.0 && refit.effect_step <= 0.5) {
        return Err(Error::InvalidSetting {
            name: "effect_step".into(),
            reason: format!("{} is not in (0, 0.5]", refit.effect_step),
        });
    }
    let names = at.space.names();
    // The residuals' parameters in the space, for the calibrated parameters' change.
    let res_index: Vec<usize> = (residuals.params().iter())
        .map(|n| {
            names.iter().position(|m| m == n).ok_or_else(|| {
                Error::Mismatch(format!(
                    "the linearisation's parameter `{n}` is not in the space"
                ))
            })
        })
        .collect::<Result<_>>()?;
    let mut diagnosis = diagnose(residuals, &hypotheses, settings)?;
    let picked: Vec<(usize, &CandidateEffect)> = (diagnosis.hypotheses.iter())
        .filter(|h| h.in_range && !h.inert)
        .filter_map(|h| {
            let i = hypotheses.iter().position(|x| x.name == h.name)?;
            let c = candidates.iter().find(|c| c.name == h.name)?;
            (!hypotheses[i].refuted && c.params.len() == hypotheses[i].params.len())
                .then_some((i, c))
        })
        .take(refit.top)
        .collect();
    let mut refits: Vec<Refit> = (picked.iter())
        .map(|(_, c)| Refit {
            name: c.name.clone(),
            steps: Vec::new(),
            stopped: None,
        })
        .collect();
    let n_cal = res_index.len();
    // Each parameter's scale in the rank-one updates: how far one unit of its unit box
    // moves it at the calibrated point, as the linearisation steps it (its range on a
    // linear scale; 1 where it has none, as a fixed parameter, which never moves).
    let width = |lower: f64, upper: f64| if upper > lower { upper - lower } else { 1.0 };
    let cal_width: Vec<f64> = (res_index.iter())
        .map(|&j| {
            let p = &at.space.params()[j];
            let u = p.to_unit(at.params[j]);
            let (lo, hi) = ((u - 0.01).max(0.0), (u + 0.01).min(1.0));
            let w = (p.from_unit(hi) - p.from_unit(lo)) / (hi - lo);
            if w.is_finite() && w > 0.0 {
                w
            } else {
                1.0
            }
        })
        .collect();
    let q_widths: Vec<Vec<f64>> = (picked.iter())
        .map(|(_, c)| c.params.iter().map(|p| width(p.lower, p.upper)).collect())
        .collect();
    let r0 = Array1::from(residuals.residuals().to_vec());
    let mut state: Vec<State> = (picked.iter())
        .map(|&(i, c)| State::new(at.params, c, &r0, residuals, &hypotheses[i], baseline_mae))
        .collect();
    let base_columns: Vec<Array2<f64>> = (picked.iter())
        .map(|&(i, _)| hypotheses[i].jacobian.clone())
        .collect();
    // The local fits weigh the outputs as the ranking does, at its noise.
    let local_settings = settings.clone().with_noise_sigma(diagnosis.noise_sigma);
    let (mut runs, mut cached) = (0, 0);
    for _ in 0..refit.iterations {
        let mut points: Vec<Planned> = Vec::new();
        for (k, (_, c)) in picked.iter().enumerate() {
            if refits[k].stopped.is_some() {
                continue;
            }
            if state[k].share < MIN_SHARE {
                refits[k].stopped = Some("no run read better than its best point".into());
                continue;
            }
            if (diagnosis.hypotheses.iter()).any(|h| h.name == c.name && !h.in_range) {
                refits[k].stopped = Some("fitted outside its range".into());
                continue;
            }
            // The first run goes where the ranking fitted it (where `run_fitted` runs);
            // later ones by the local fit.
            let first = (diagnosis.hypotheses.iter())
                .find(|h| h.name == c.name)
                .filter(|_| refits[k].steps.is_empty());
            let step = match first {
                Some(h) => step_of(h, residuals, c),
                None => match state[k].local_fit(residuals, c, n_cal, &local_settings) {
                    Ok(step) => step,
                    Err(e) => {
                        refits[k].stopped = Some(format!("no local fit: {e}"));
                        continue;
                    }
                },
            };
            let t = state[k].share;
            let mut point = state[k].point.clone();
            let mut clamped = Vec::new();
            for (col, &j) in res_index.iter().enumerate() {
                let p = &at.space.params()[j];
                let wanted = point[j] + t * step[col];
                point[j] = wanted.clamp(p.lower, p.upper);
                if (wanted - point[j]).abs() > 1e-9 * width(p.lower, p.upper) {
                    clamped.push(p.name.clone());
                }
            }
            let mut values: Vec<f64> = (state[k].values.iter())
                .zip(&step[n_cal..])
                .map(|(v, dq)| v + t * dq)
                .collect();
            // How far from absent, in the linearisation's steps.
            let reach_of = |values: &[f64]| {
                (c.params.iter().zip(values))
                    .map(|(p, v)| (v - p.absent).abs() / p.step(refit.effect_step).abs())
                    .fold(0.0, f64::max)
            };
            // At least half the linearisation's step from absent, on the fit's side.
            let reach = reach_of(&values);
            if reach == 0.0 {
                refits[k].stopped = Some("fitted at its absent value".into());
                continue;
            }
            for (p, v) in c.params.iter().zip(values.iter_mut()) {
                if reach < 0.5 {
                    *v = p.absent + (*v - p.absent) * 0.5 / reach;
                }
                *v = v.clamp(p.lower, p.upper);
                point[p.index] = *v;
            }
            // Clamped back towards absent (the fit points out of the range through it), a
            // run would try the calibrated parameters alone, not the effect.
            if reach_of(&values) < 0.5 - 1e-9 {
                refits[k].stopped = Some("its fit points back to absent, or beyond".into());
                continue;
            }
            points.push(Planned {
                k,
                point,
                values,
                clamped,
            });
        }
        if points.is_empty() {
            break;
        }
        let ran = at.run(&points.iter().map(|p| p.point.clone()).collect::<Vec<_>>())?;
        for (planned, run) in points.into_iter().zip(ran) {
            let Planned {
                k,
                point,
                values,
                clamped,
            } = planned;
            runs += run.runs;
            cached += run.cached;
            let (i, c) = picked[k];
            let value_names: Vec<String> = c.params.iter().map(|p| p.name.clone()).collect();
            let mut step = RefitStep {
                values: NamedValues::new(&value_names, &values),
                params: NamedValues::new(&names, &point),
                mae: None,
                failed: None,
                accepted: false,
                clamped,
            };
            let (mae, r1) = match run.residuals {
                Ok(r) => (super::mean_abs(&r), Array1::from(r)),
                Err(why) => {
                    // Too far for the model: half as far next time.
                    step.failed = Some(why);
                    refits[k].steps.push(step);
                    state[k].share *= 0.5;
                    continue;
                }
            };
            let accepted = mae < state[k].mae;
            step.mae = Some(mae);
            step.accepted = accepted;
            refits[k].steps.push(step);
            // Every run teaches the local slopes, from the best point to it.
            let q_width = &q_widths[k];
            let widths: Vec<f64> = cal_width.iter().chain(q_width).copied().collect();
            let dx: Vec<f64> = (res_index.iter().map(|&j| point[j] - state[k].point[j]))
                .chain(values.iter().zip(&state[k].values).map(|(v, b)| v - b))
                .collect();
            let dr = &r1 - &state[k].residuals;
            rank_one_update(&mut state[k].local, &dr, &dx, &widths);
            if !accepted {
                state[k].share *= 0.5;
                continue;
            }
            // The ranking's columns: the linearisation's, made exact at this run (from the
            // calibrated point, the effect absent).
            let dp: Array1<f64> = res_index.iter().map(|&j| point[j] - at.params[j]).collect();
            let dq: Vec<f64> = (c.params.iter().zip(&values))
                .map(|(p, v)| v - p.absent)
                .collect();
            let mut h = base_columns[k].clone();
            let dr_base = &r1 - &r0 - residuals.jacobian().dot(&dp);
            rank_one_update(&mut h, &dr_base, &dq, q_width);
            hypotheses[i].jacobian = h;
            let s = &mut state[k];
            (s.point, s.values, s.residuals, s.mae, s.share) = (point, values, r1, mae, 1.0);
        }
        // A hypothesis every one of whose runs read worse than the baseline is refuted by
        // the model itself: its linearisation promised what the model does not give. One
        // whose runs all failed is not: the model said nothing of it.
        for (k, (i, _)) in picked.iter().enumerate() {
            let steps = &refits[k].steps;
            hypotheses[*i].refuted =
                steps.iter().any(|s| s.mae.is_some()) && steps.iter().all(|s| !s.accepted);
        }
        diagnosis = diagnose(residuals, &hypotheses, settings)?;
    }
    Ok(Refitted {
        diagnosis,
        hypotheses,
        refits,
        runs,
        cached,
    })
}

/// A run one refit plans this round.
struct Planned {
    /// The refit's index.
    k: usize,
    /// Every parameter there.
    point: Vec<f64>,
    /// The candidate's parameters there.
    values: Vec<f64>,
    /// Calibrated parameters held at a bound for it.
    clamped: Vec<String>,
}

/// A refit's best point so far and its local linear model.
struct State {
    /// Every parameter there.
    point: Vec<f64>,
    /// The candidate's parameters there.
    values: Vec<f64>,
    /// The residuals there.
    residuals: Array1<f64>,
    /// The model's MAE there (at first the baseline, which a run must read below).
    mae: f64,
    /// Rows x (calibrated parameters, then the candidate's): the slopes there, from the
    /// linearisation, updated by every run.
    local: Array2<f64>,
    /// Share of the local fit's step the next run takes (halved after a worse run).
    share: f64,
}

impl State {
    /// At the calibrated point, the effect absent.
    fn new(
        params: &[f64],
        c: &CandidateEffect,
        r0: &Array1<f64>,
        residuals: &Residuals,
        h: &Hypothesis,
        baseline_mae: f64,
    ) -> Self {
        let local = ndarray::concatenate(
            ndarray::Axis(1),
            &[residuals.jacobian().view(), h.jacobian.view()],
        )
        .expect("the hypothesis's rows are the residuals'");
        State {
            point: params.to_vec(),
            values: c.params.iter().map(|p| p.absent).collect(),
            residuals: r0.clone(),
            mae: baseline_mae,
            local,
            share: 1.0,
        }
    }

    /// The step the ranking's own fit (its likelihood, at its noise; a prior, if any,
    /// about the current value) takes from here with the local slopes: the calibrated
    /// parameters' change, then the candidate's.
    fn local_fit(
        &self,
        residuals: &Residuals,
        c: &CandidateEffect,
        n_cal: usize,
        settings: &DiagnoseSettings,
    ) -> Result<Vec<f64>> {
        let mut here = Residuals::new(
            residuals.rows().to_vec(),
            self.residuals.to_vec(),
            self.local.slice(ndarray::s![.., ..n_cal]).to_owned(),
            residuals.params().to_vec(),
        )?;
        if let Some(u) = residuals.uncertainty() {
            here = here.with_uncertainty(u.to_vec())?;
        }
        if let Some(u) = residuals.model_form() {
            here = here.with_model_form(u.to_vec())?;
        }
        let params = (c.params.iter().zip(&self.values))
            .map(|(p, v)| HypothesisParam::bounded(p.name.clone(), p.lower - v, p.upper - v))
            .collect();
        let columns = self.local.slice(ndarray::s![.., n_cal..]).to_owned();
        let d = diagnose(
            &here,
            &[Hypothesis::new(&c.name, params, columns)],
            settings,
        )?;
        Ok(step_of(&d.hypotheses[0], residuals, c))
    }
}

/// A fit's step: the calibrated parameters' change (in `residuals`' order), then the
/// candidate's.
fn step_of(h: &HypothesisResult, residuals: &Residuals, c: &CandidateEffect) -> Vec<f64> {
    (residuals.params().iter())
        .map(|n| h.current_change.get(n).unwrap_or(0.0))
        .chain(
            c.params
                .iter()
                .map(|p| h.fitted.get(&p.name).unwrap_or(0.0)),
        )
        .collect()
}

/// Broyden's rank-one update of `jacobian` (rows x `dx.len()`) so that it maps `dx` to
/// `dr`, the least change in units of each column's `width`.
fn rank_one_update(jacobian: &mut Array2<f64>, dr: &Array1<f64>, dx: &[f64], width: &[f64]) {
    let z: Vec<f64> = dx.iter().zip(width).map(|(d, w)| d / w).collect();
    let zz: f64 = z.iter().map(|v| v * v).sum();
    if zz == 0.0 {
        return;
    }
    let predicted = jacobian.dot(&Array1::from(dx.to_vec()));
    for row in 0..jacobian.nrows() {
        let u = dr[row] - predicted[row];
        for (col, (zj, w)) in z.iter().zip(width).enumerate() {
            jacobian[[row, col]] += u * zj / (w * zz);
        }
    }
}
