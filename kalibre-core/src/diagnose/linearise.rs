//! A diagnosis's inputs from the model itself: its residuals at the calibrated
//! parameters, their Jacobian by finite differences, and one [`Hypothesis`] per
//! [`CandidateEffect`], every run through the journal (a run already there is read, never
//! repeated; a new one is kept).

use ndarray::Array2;

use super::input::stack_blocks;
use super::runs::{all_ran, scaled_residuals, RunInputs, Tally};
use super::{measured_rows, CandidateEffect, Hypothesis, HypothesisParam, Residuals};
use crate::{Error, Model, Observations, ParamSpace, Result, RunStore};

/// Finite-difference steps of [`linearise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineariseSettings {
    /// Step of a calibrated parameter, in the unit box: forward, or backward at the upper
    /// bound, and the other way if a run there fails.
    pub unit_step: f64,
    /// Step of a candidate's parameter from its absent value, as a share of its range:
    /// a secant over a typical size of the effect, not a tangent at nothing.
    pub effect_step: f64,
}

impl Default for LineariseSettings {
    /// 0.01 of the unit box and 0.05 of a candidate's range: the hall diagnosis's steps.
    fn default() -> Self {
        LineariseSettings {
            unit_step: 0.01,
            effect_step: 0.05,
        }
    }
}

/// What [`linearise`] made.
#[derive(Debug, Clone)]
pub struct Linearised {
    /// Residuals at the calibrated parameters with their Jacobian (in the observations'
    /// scale units when they have scales); the candidates' parameters are not among its
    /// parameters.
    pub residuals: Residuals,
    /// One hypothesis per candidate whose runs succeeded.
    pub hypotheses: Vec<Hypothesis>,
    /// Candidates not tried, each with why (a run of its step failed).
    pub not_tried: Vec<(String, String)>,
    /// The model's outputs at the parameters, per snapshot, in the outputs' own units: to
    /// compare with what the calibration recorded there (a scenario edited since runs
    /// anew, and answers otherwise).
    pub predicted: Vec<Vec<f64>>,
    /// Model runs made (not in the journal before).
    pub runs: usize,
    /// Runs read from the journal.
    pub cached: usize,
}

/// Linearises `model` at `params` (a point of `space`, each candidate's parameters at
/// their absent values) for every snapshot of `obs`: one run there, one per calibrated
/// parameter that is not fixed, one per candidate parameter. Runs go through `store`.
///
/// A failed run at `params` is an error: there is nothing to diagnose. A calibrated
/// parameter whose step fails is tried on the other side before it is an error. A
/// candidate whose step fails is left out, in [`Linearised::not_tried`].
///
/// ```
/// use kalibre_core::diagnose::{diagnose, linearise, CandidateEffect, CandidateParam, DiagnoseSettings, LineariseSettings};
/// use kalibre_core::{Model, ModelError, Observations, OutputInfo, Outputs, Param, ParamSpace, RunStore, Scale, Snapshot};
///
/// // A line a x seen at x = 1..3 by two sensors, one at x and one at x + 3; the data
/// // also curve (leak 0.3 of x^2), which the calibration held at 0.
/// struct Line;
/// impl Model for Line {
///     type Scenario = f64;
///     fn fingerprint(&self) -> String { "line".into() }
///     fn evaluate(&self, x: &f64, p: &[f64]) -> Result<Outputs, ModelError> {
///         let y = |x: f64| p[0] * x + p[1] * x * x;
///         Ok(Outputs::from(vec![y(*x), y(x + 3.0)]))
///     }
/// }
/// # fn main() -> kalibre_core::Result<()> {
/// let truth = |x: f64| 2.0 * x + 0.3 * x * x;
/// let snaps = (1..=3).map(|i| {
///     let x = i as f64;
///     Snapshot { label: format!("x{i}"), scenario: x, measured: vec![Some(truth(x)), Some(truth(x + 3.0))] }
/// }).collect();
/// let sensor = |name: &str| OutputInfo { name: name.into(), group: String::new() };
/// let obs = Observations::new(vec![sensor("near"), sensor("far")], snaps)?;
/// let mut space = ParamSpace::new();
/// space.push(Param::new("a", 0.0, 10.0, 1.0, Scale::Linear)?)?;
/// space.push(Param::new("leak", 0.0, 0.0, 0.0, Scale::Linear)?)?;
/// let leak = CandidateEffect {
///     name: "leak".into(),
///     params: vec![CandidateParam { name: "leak".into(), index: 1, absent: 0.0, lower: 0.0, upper: 1.0 }],
/// };
/// // Near the best straight line through the data.
/// let store = RunStore::in_memory("line");
/// let lin = linearise(&Line, &obs, &space, &[3.5, 0.0], &[leak], &store, &LineariseSettings::default())?;
/// assert_eq!(lin.runs, 3 * 3); // the point, a step of `a`, a step of the leak; 3 snapshots
/// let d = diagnose(&lin.residuals, &lin.hypotheses, &DiagnoseSettings::new().with_noise_sigma(0.01))?;
/// assert!(d.hypotheses[0].significant, "{:?}", d.hypotheses[0]);
/// assert!((d.hypotheses[0].fitted.get("leak").unwrap() - 0.3).abs() < 1e-6);
/// # Ok(())
/// # }
/// ```
pub fn linearise<M: Model>(
    model: &M,
    obs: &Observations<M::Scenario>,
    space: &ParamSpace,
    params: &[f64],
    candidates: &[CandidateEffect],
    store: &RunStore,
    settings: &LineariseSettings,
) -> Result<Linearised> {
    check(space, params, candidates, settings)?;
    let inputs = RunInputs::new(model, obs, space);
    let runner = inputs.runner(model, obs, store);
    let names = &inputs.names;
    let is_candidate = |i: usize| {
        candidates
            .iter()
            .any(|c| c.params.iter().any(|p| p.index == i))
    };
    let moved = |i: usize, to: f64| {
        let mut p = params.to_vec();
        p[i] = to;
        p
    };
    // Calibrated parameters, forward in the unit box (backward at the upper bound);
    // fixed ones have no step and a zero column.
    let calibrated: Vec<usize> = (0..space.dim()).filter(|&i| !is_candidate(i)).collect();
    // Parameter `i`'s unit coordinate one step forward or back from the calibrated value.
    let unit_after = |i: usize, forward: bool| {
        let u = space.params()[i].to_unit(params[i]);
        if forward {
            u + settings.unit_step
        } else {
            u - settings.unit_step
        }
    };
    let unit_step_to =
        |i: usize, forward: bool| space.params()[i].from_unit(unit_after(i, forward));
    let forward_first = |i: usize| unit_after(i, true) <= 1.0;
    let movable: Vec<usize> = (calibrated.iter().copied())
        .filter(|&i| !space.params()[i].is_fixed())
        .collect();
    let candidate_params: Vec<(usize, usize, f64)> = (candidates.iter().enumerate())
        .flat_map(|(c, e)| {
            e.params
                .iter()
                .map(move |p| (c, p.index, p.absent + p.step(settings.effect_step)))
        })
        .collect();

    let mut points = vec![params.to_vec()];
    points.extend(
        movable
            .iter()
            .map(|&i| moved(i, unit_step_to(i, forward_first(i)))),
    );
    points.extend(candidate_params.iter().map(|&(_, i, v)| moved(i, v)));
    let results = runner.run(0, &points)?;
    let mut tally = Tally::default();
    tally.count(&results);
    let base = all_ran(&results[0]).map_err(|(s, why)| {
        Error::Mismatch(format!(
            "the model failed at the calibrated parameters (`{}`): {why}; there is nothing \
             to diagnose until it runs there",
            obs.snapshots()[s].label
        ))
    })?;

    // Columns of the calibrated parameters: (snapshot blocks) outputs x parameters.
    let n_out = inputs.output_names.len();
    let n_snap = obs.snapshots().len();
    let mut blocks = vec![Array2::<f64>::zeros((n_out, calibrated.len())); n_snap];
    for (k, &i) in movable.iter().enumerate() {
        let col = calibrated.iter().position(|&j| j == i).expect("calibrated");
        let mut point = &points[1 + k];
        let mut ran = all_ran(&results[1 + k]);
        let retried;
        if let Err((s, why)) = &ran {
            // The other side, if the box has room for a step there.
            if !(0.0..=1.0).contains(&unit_after(i, !forward_first(i))) {
                return Err(Error::Mismatch(format!(
                    "the model failed a step of `{}` from its calibrated value (`{}`): {why}; \
                     and the other side is beyond its bounds, so its slope there cannot be \
                     measured",
                    names[i],
                    obs.snapshots()[*s].label
                )));
            }
            let other = moved(i, unit_step_to(i, !forward_first(i)));
            let again = runner.run(0, std::slice::from_ref(&other))?;
            tally.count(&again);
            retried = other;
            point = &retried;
            ran = all_ran(&again[0]);
        }
        let outputs = ran.map_err(|(s, why)| {
            Error::Mismatch(format!(
                "the model failed on both sides of the calibrated value of `{}` (`{}`): \
                 {why}; its slope there cannot be measured",
                names[i],
                obs.snapshots()[s].label
            ))
        })?;
        let dx = point[i] - params[i];
        for s in 0..n_snap {
            for o in 0..n_out {
                blocks[s][[o, col]] = (outputs[s][o] - base[s][o]) / dx;
            }
        }
    }
    let calibrated_names: Vec<String> = calibrated.iter().map(|&i| names[i].clone()).collect();
    let jacobian = stack_blocks(obs, &blocks, "Jacobian")?;
    let residuals = Residuals::new(
        measured_rows(obs),
        scaled_residuals(obs, &base),
        jacobian,
        calibrated_names,
    )?;

    let mut hypotheses = Vec::new();
    let mut not_tried = Vec::new();
    let first_candidate_point = 1 + movable.len();
    for (c, effect) in candidates.iter().enumerate() {
        let mut columns: Vec<Array2<f64>> =
            vec![Array2::zeros((n_out, effect.params.len())); n_snap];
        let mut failed = None;
        for (j, p) in effect.params.iter().enumerate() {
            let k = (candidate_params
                .iter()
                .position(|&(cc, i, _)| cc == c && i == p.index))
            .expect("a point per candidate parameter");
            match all_ran(&results[first_candidate_point + k]) {
                Ok(outputs) => {
                    let dx = candidate_params[k].2 - p.absent;
                    for s in 0..n_snap {
                        for o in 0..n_out {
                            columns[s][[o, j]] = (outputs[s][o] - base[s][o]) / dx;
                        }
                    }
                }
                Err((s, why)) => {
                    failed = Some(format!(
                        "the model failed with `{}` at {} (`{}`): {why}",
                        p.name,
                        crate::number(candidate_params[k].2),
                        obs.snapshots()[s].label
                    ));
                    break;
                }
            }
        }
        if let Some(why) = failed {
            not_tried.push((effect.name.clone(), why));
            continue;
        }
        let hyp_params = (effect.params.iter())
            .map(|p| {
                HypothesisParam::bounded(p.name.clone(), p.lower - p.absent, p.upper - p.absent)
            })
            .collect();
        hypotheses.push(Hypothesis::from_snapshots(
            effect.name.clone(),
            hyp_params,
            obs,
            &columns,
        )?);
    }
    // Back in the outputs' units.
    let predicted = (base.into_iter().enumerate())
        .map(|(s, mut values)| {
            if let Some(scales) = obs.scales() {
                for (v, scale) in values.iter_mut().zip(&scales[s]) {
                    *v *= scale;
                }
            }
            values
        })
        .collect();
    Ok(Linearised {
        residuals,
        hypotheses,
        not_tried,
        predicted,
        runs: tally.runs,
        cached: tally.cached,
    })
}

/// The point, the candidates and the steps make sense together.
pub(super) fn check(
    space: &ParamSpace,
    params: &[f64],
    candidates: &[CandidateEffect],
    settings: &LineariseSettings,
) -> Result<()> {
    let bad = |name: &str, reason: String| Error::InvalidSetting {
        name: name.into(),
        reason,
    };
    for (name, v) in [
        ("unit_step", settings.unit_step),
        ("effect_step", settings.effect_step),
    ] {
        if !(v > 0.0 && v <= 0.5) {
            return Err(bad(name, format!("{v} is not in (0, 0.5]")));
        }
    }
    if params.len() != space.dim() {
        return Err(Error::Mismatch(format!(
            "{} parameter values for {} parameters",
            params.len(),
            space.dim()
        )));
    }
    let names = space.names();
    for (i, (p, v)) in space.params().iter().zip(params).enumerate() {
        if !v.is_finite() || *v < p.lower || *v > p.upper {
            return Err(Error::InvalidParam {
                name: names[i].clone(),
                reason: format!(
                    "{} is not within its bounds [{}, {}]",
                    crate::number(*v),
                    crate::number(p.lower),
                    crate::number(p.upper)
                ),
            });
        }
    }
    for (c, e) in candidates.iter().enumerate() {
        if e.params.is_empty() {
            return Err(Error::Mismatch(format!(
                "candidate `{}` has no parameter",
                e.name
            )));
        }
        if candidates[..c].iter().any(|o| o.name == e.name) {
            return Err(Error::Mismatch(format!(
                "candidate `{}` appears twice",
                e.name
            )));
        }
        for p in &e.params {
            if p.index >= space.dim() {
                return Err(Error::Mismatch(format!(
                    "candidate `{}`: parameter `{}` has index {}, but the space has {} \
                     parameters",
                    e.name,
                    p.name,
                    p.index,
                    space.dim()
                )));
            }
            let held = (space.params().get(p.index)).filter(|q| {
                q.name == p.name && q.is_fixed() && params.get(p.index) == Some(&p.absent)
            });
            if held.is_none() {
                return Err(Error::Mismatch(format!(
                    "candidate `{}`: parameter `{}` must be the space's parameter {} held \
                     fixed at its absent value {}",
                    e.name,
                    p.name,
                    p.index,
                    crate::number(p.absent)
                )));
            }
            if !(p.lower < p.upper && (p.lower..=p.upper).contains(&p.absent)) {
                return Err(Error::InvalidParam {
                    name: p.name.clone(),
                    reason: format!(
                        "candidate range [{}, {}] must be increasing and hold its absent value {}",
                        crate::number(p.lower),
                        crate::number(p.upper),
                        crate::number(p.absent)
                    ),
                });
            }
        }
    }
    Ok(())
}
