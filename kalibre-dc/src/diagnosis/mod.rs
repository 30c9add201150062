//! Where a calibrated hall model fails and which physical effect is missing: a solver
//! supplies the Jacobians (the built-in simulator, cheap, at the calibrated parameters; or
//! the calibrated model itself, see [`EffectSolver`]), each effect kind
//! supplies its candidate placements, and `kalibre_core::diagnose` ranks them.

mod odd_snapshots;
mod refit;
mod settings;
mod solver;
mod worst_sensors;

pub use odd_snapshots::{odd_snapshots, OddSnapshot};
pub use refit::{Refit, RefitStep};
pub use settings::HallDiagnosisSettings;
pub use solver::EffectSolver;
pub use worst_sensors::{worst_sensors, worst_sensors_json, WORST_SENSORS_SHOWN};

use ndarray::Array2;
use rayon::prelude::*;
use serde_json::{json, Value};

use kalibre_core::diagnose::{
    diagnose, Diagnosis, Hypothesis, HypothesisParam, Residuals, CLOSE_ALTERNATIVE_BIC,
};
use kalibre_core::ParamSpace;

use crate::effects::{openings_overlap, placement, supply_openings, Effect, EffectRegistry};
use crate::hall::{Aabb, EffectSpec, Hall};
use crate::sim::Simulator;
use crate::snapshots::{self, HallSnapshot, OperatingState};
use crate::{Error, ParamLayout, Result};

/// Adds each reading's squared difference between `other` and `base` (snapshot x
/// sensor) to `u2`.
fn add_spread(u2: &mut [Vec<f64>], other: &[Vec<f64>], base: &[Vec<f64>]) {
    for ((u, o), b) in u2.iter_mut().zip(other).zip(base) {
        for ((u, o), b) in u.iter_mut().zip(o).zip(b) {
            *u += (o - b).powi(2);
        }
    }
}

/// The square roots of `u2` (snapshot x sensor) at the measured readings, in the
/// residuals' row order: snapshot-major, measured sensors only.
fn measured_sqrt(snaps: &[HallSnapshot], u2: &[Vec<f64>]) -> Vec<f64> {
    snaps
        .iter()
        .zip(u2)
        .flat_map(|(snap, u2)| {
            snap.sensor_c
                .iter()
                .zip(u2)
                .filter(|(m, _)| m.is_some())
                .map(|(_, u2)| u2.sqrt())
        })
        .collect()
}

/// A diagnosis with the `hall.json` entry each hypothesis suggests.
#[derive(Debug, Clone)]
pub struct HallDiagnosis {
    /// The ranked hypotheses.
    pub diagnosis: Diagnosis,
    /// Per hypothesis (same order as `diagnosis.hypotheses`): its placement as an
    /// `effects` entry, with the fitted parameter values clamped into their ranges. A
    /// hypothesis fitted outside its range has no entry to add (clamped, its value is
    /// the effect's absence, or the end of a range the data ask to go beyond): see
    /// [`HallDiagnosis::entry`], which is what every listing offers.
    pub suggestions: Vec<EffectSpec>,
    /// Candidates that were not tried, and why (a kind the solver cannot represent, or
    /// a failed run).
    pub not_tried: Vec<NotTried>,
    /// The leading hypotheses refit with the solver (`refit_top`), and what they ran.
    pub refits: Vec<Refit>,
}

/// Candidates left out of a diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct NotTried {
    /// The candidate (`bypass(behind_rack=B3)`), or the kind when every candidate of it
    /// was left out.
    pub candidate: String,
    /// How many candidates this stands for.
    pub count: usize,
    /// Why.
    pub reason: String,
}

/// A hypothesis's flags in words, as every listing shows them (the CLI's, the demo's,
/// the story's HTML), e.g. `significant, not identifiable`.
pub fn hypothesis_flags(
    significant: bool,
    refuted: bool,
    inert: bool,
    identifiable: bool,
    in_range: bool,
) -> String {
    [
        (significant, "significant"),
        (refuted, "refuted by its model runs"),
        (inert, "inert"),
        (!identifiable, "not identifiable"),
        (!in_range, "fitted outside its range"),
    ]
    .iter()
    .filter(|f| f.0)
    .map(|f| f.1)
    .collect::<Vec<_>>()
    .join(", ")
}

/// For a significant hypothesis below the best significant one (`best_name`, with share
/// `best_share` of the residual): when the two explain more than the whole residual
/// between them they read the same part of it, so it is another placement (or kind) of
/// one effect, not a second effect; this says so. `None` when their shares leave room
/// for two effects. `bic_above_best`: its BIC less the best's (not finite when unknown).
pub fn alternative_note(
    best_name: &str,
    best_share: f64,
    share: f64,
    bic_above_best: f64,
) -> Option<String> {
    if best_share + share <= 1.0 {
        return None;
    }
    let apart = if !bic_above_best.is_finite() {
        String::new()
    } else if bic_above_best < CLOSE_ALTERNATIVE_BIC {
        format!(
            "; the data cannot tell the two apart (BIC {bic_above_best:+.1}, within \
             {CLOSE_ALTERNATIVE_BIC:.0})"
        )
    } else {
        format!("; {best_name} fits better (BIC {bic_above_best:+.1})")
    };
    Some(format!(
        "an alternative to {best_name}, not a second effect: between them they would explain \
         {:.0} % of the residual, so they read the same part of it{apart}",
        100.0 * (best_share + share)
    ))
}

impl HallDiagnosis {
    /// The `effects` entry to add for hypothesis `i` (in `diagnosis.hypotheses`' order),
    /// or `None` when it was fitted outside its range: then no entry gives what the data
    /// ask (a bypass at a negative share clamps to 0, an entry that does nothing).
    pub fn entry(&self, i: usize) -> Option<&EffectSpec> {
        let h = self.diagnosis.hypotheses.get(i)?;
        self.suggestions.get(i).filter(|_| h.in_range)
    }

    /// The `kalibre.diagnosis/1` JSON of `formats.md`.
    pub fn to_json(&self) -> Value {
        let hyps: Vec<Value> = self
            .diagnosis
            .hypotheses
            .iter()
            .zip(&self.suggestions)
            .enumerate()
            .map(|(i, (h, s))| {
                json!({
                    "effect": s.kind,
                    "name": h.name,
                    "explained_fraction": h.explained_fraction,
                    "predicted_mae_c": h.predicted_mae,
                    "significant": h.significant,
                    "refuted_by_model_runs": h.refuted,
                    "inert": h.inert,
                    "identifiable": h.identifiable,
                    "fitted": h.fitted,
                    "in_range": h.in_range,
                    "ranges": h.ranges,
                    "current_change": h.current_change,
                    "delta_bic": h.delta_bic,
                    "held_out_improvement": h.held_out_improvement,
                    "single_output_delta_bic": h.single_output_delta_bic,
                    "carried_by": h.carried_by,
                    "sensor_bias_delta_bic": h.sensor_bias_delta_bic,
                    "ambiguous_with": h.ambiguous_with,
                    // `null` for a fit outside its range: no entry gives it.
                    "suggestion": self.entry(i),
                })
            })
            .collect();
        let unexplained: Vec<Value> = self
            .diagnosis
            .unexplained
            .iter()
            .map(|u| {
                json!({
                    "sensor": u.output,
                    "mean_residual_c": u.mean_residual,
                    "rms_scales": u.rms_scales,
                    "model_form_c": u.model_form_c,
                })
            })
            .collect();
        let mut doc = json!({
            "schema": "kalibre.diagnosis/1",
            "mae_c": self.diagnosis.mae,
            "noise_sigma_c": self.diagnosis.noise_sigma,
            "model_form_share": self.diagnosis.model_form_share,
            "hypotheses": hyps,
            "unexplained_sensors": unexplained,
        });
        let close = self.diagnosis.close_alternatives();
        if let (Some(best), false) = (self.diagnosis.significant().next(), close.is_empty()) {
            doc["close_alternatives"] = close
                .iter()
                .map(|h| json!({"name": h.name, "bic_above_best": h.delta_bic - best.delta_bic}))
                .collect();
        }
        if !self.refits.is_empty() {
            doc["refits"] = json!(self.refits);
        }
        if !self.not_tried.is_empty() {
            doc["not_tried"] = self
                .not_tried
                .iter()
                .map(|n| json!({"candidate": n.candidate, "count": n.count, "reason": n.reason}))
                .collect();
        }
        doc
    }
}

/// A readable name of a candidate placement, e.g. `rack_recirculation(rack=A01)`.
fn candidate_name(spec: &EffectSpec) -> String {
    if spec.fields.is_empty() {
        return spec.kind.clone();
    }
    let fields: Vec<String> = spec
        .fields
        .iter()
        .map(|(k, v)| match v {
            Value::String(s) => format!("{k}={s}"),
            other => format!("{k}={other}"),
        })
        .collect();
    format!("{}({})", spec.kind, fields.join(","))
}

/// A candidate's parameter value at which the effect is absent: 0 (clamped into its
/// bounds). The base run has no such effect at all, so each hypothesis is linearised
/// from there and its fitted change is the parameter's value.
fn absent(p: &kalibre_core::Param) -> f64 {
    0.0_f64.clamp(p.lower, p.upper)
}

/// The finite-difference step of an effect parameter: `effect_step` of its range.
fn effect_step_size(settings: &HallDiagnosisSettings, p: &kalibre_core::Param) -> f64 {
    settings.effect_step * (p.upper - p.lower)
}

/// The hall's effects with their values, as a solver takes them.
fn effect_list<'a>(
    effects: &'a [Box<dyn Effect>],
    values: &'a [Vec<f64>],
) -> Vec<(&'a dyn Effect, &'a [f64])> {
    effects
        .iter()
        .zip(values)
        .map(|(e, v)| (e.as_ref(), v.as_slice()))
        .collect()
}

/// A candidate's hypothesis name: [`candidate_name`], with the next free `#k` when its
/// parameters would be named as calibrated ones (a candidate of defaults only, of a kind
/// the hall already has: the suffix its entry gets once added).
fn hypothesis_name(spec: &EffectSpec, effect: &dyn Effect, calibrated: &[String]) -> String {
    let name = candidate_name(spec);
    let params = effect.parameters();
    let clashes = |n: &str| {
        params
            .iter()
            .any(|p| calibrated.contains(&hypothesis_param(n, &p.name)))
    };
    if !clashes(&name) {
        return name;
    }
    (2..)
        .map(|k| format!("{name}#{k}"))
        .find(|n| !clashes(n))
        .expect("some suffix is free")
}

/// The name of a hypothesis parameter: unique across candidates and (by
/// [`hypothesis_name`]) distinct from the calibrated `<kind>/<param>` of an effect the hall
/// already has.
fn hypothesis_param(candidate: &str, param: &str) -> String {
    format!("{candidate}/{param}")
}

/// One simulator run of the diagnosis: alpha per server and effect values.
struct Job {
    snapshot: usize,
    alpha: Vec<f64>,
    effects: Vec<Vec<f64>>,
    extra: Option<(usize, Vec<f64>)>,
}

/// How many candidate placements of `registry`'s kinds `solver` can represent in `hall`:
/// a diagnosis solves each once per snapshot.
pub fn candidates_tried(
    hall: &Hall,
    registry: &EffectRegistry,
    solver: &dyn EffectSolver,
) -> usize {
    registry
        .kinds()
        .iter()
        .filter(|k| solver.supports(k))
        .filter_map(|k| registry.get(k))
        .map(|f| f.candidates(hall).len())
        .sum()
}

/// Diagnoses `hall` at calibrated parameters `params` (in the order of the hall's
/// [`ParamLayout`], e.g. a report's best parameters) against `snaps`, with the built-in
/// simulator (`settings.sim`) supplying every solve.
pub fn diagnose_hall(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
    registry: &EffectRegistry,
    settings: &HallDiagnosisSettings,
) -> Result<HallDiagnosis> {
    let sim = Simulator::new(hall, settings.sim.clone())?;
    diagnose_hall_with(hall, snaps, params, registry, settings, &sim)
}

/// As [`diagnose_hall`], with `solver` supplying every solve (`settings.sim` is unused).
/// Candidates of kinds the solver cannot represent are not tried; a candidate whose run
/// fails is dropped; both are listed in [`HallDiagnosis::not_tried`]. The base run and
/// the calibrated parameters' steps must succeed.
pub fn diagnose_hall_with(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
    registry: &EffectRegistry,
    settings: &HallDiagnosisSettings,
    solver: &dyn EffectSolver,
) -> Result<HallDiagnosis> {
    settings.check()?;
    let obs = snapshots::to_observations(hall, snaps)?;
    let effects = registry.build_all(hall)?;
    let layout = ParamLayout::new(hall, &effects)?;
    let space: &ParamSpace = layout.space();
    space.check_physical(params)?;
    if let Some(e) = effects.iter().find(|e| !solver.supports(e.kind())) {
        return Err(Error::Mismatch(format!(
            "the hall's effect `{}` cannot be represented by {}",
            e.kind(),
            solver.name()
        )));
    }
    // A candidate the hall already has (same kind and placement, whatever its parameter
    // values) is no hypothesis: it is calibrated already.
    let present: Vec<EffectSpec> = hall
        .effects
        .iter()
        .zip(&effects)
        .map(|(spec, e)| placement(spec, e.as_ref()))
        .collect();
    let mut not_tried = Vec::new();
    for kind in registry.kinds() {
        let n = registry.get(kind).map_or(0, |f| f.candidates(hall).len());
        if n > 0 && !solver.supports(kind) {
            not_tried.push(NotTried {
                candidate: kind.to_string(),
                count: n,
                reason: format!("{} cannot represent it", solver.name()),
            });
        }
    }
    let candidates: Vec<(EffectSpec, Box<dyn Effect>)> = registry
        .kinds()
        .iter()
        .filter(|k| solver.supports(k))
        .filter_map(|k| registry.get(k))
        .flat_map(|f| f.candidates(hall))
        .map(|spec| registry.build(&spec, hall).map(|e| (spec, e)))
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .filter(|(spec, e)| !present.contains(&placement(spec, e.as_ref())))
        .collect();
    // A candidate whose opening overlaps one of the hall's could not be told from it (a
    // hall with both is refused), so it is no hypothesis either.
    let hall_openings: Vec<Aabb> = effects
        .iter()
        .flat_map(|e| supply_openings(e.as_ref(), hall))
        .collect();
    let (candidates, overlapping): (Vec<_>, Vec<_>) = candidates.into_iter().partition(|(_, e)| {
        openings_overlap(&supply_openings(e.as_ref(), hall), &hall_openings).is_none()
    });
    let calibrated_names = space.names();
    for (spec, e) in &overlapping {
        not_tried.push(NotTried {
            candidate: hypothesis_name(spec, e.as_ref(), &calibrated_names),
            count: 1,
            reason: "its opening would overlap an opening the hall has".into(),
        });
    }

    let alpha0 = layout.alpha_per_server(params);
    let values0: Vec<Vec<f64>> = (0..effects.len())
        .map(|e| layout.effect_values(params, e).to_vec())
        .collect();
    let n_snap = snaps.len();
    let unit = space.to_unit(params)?;
    // Calibrated parameters: forward (backward at the upper bound) steps in the unit box.
    // A fixed parameter (equal bounds) cannot move: no step and no run, a zero column
    // (which the fits leave out) instead of a 0 / 0.
    let mut steps: Vec<Option<(f64, Vec<f64>)>> = Vec::with_capacity(space.dim());
    for i in 0..space.dim() {
        if space.params()[i].is_fixed() {
            steps.push(None);
            continue;
        }
        let mut u = unit.clone();
        u[i] = if u[i] + settings.unit_step <= 1.0 {
            u[i] + settings.unit_step
        } else {
            u[i] - settings.unit_step
        };
        let p = space.from_unit(&u)?;
        steps.push(Some((p[i] - params[i], p)));
    }
    // `None`: a fixed parameter's step, not run.
    let mut jobs: Vec<Option<Job>> = Vec::new();
    for s in 0..n_snap {
        jobs.push(Some(Job {
            snapshot: s,
            alpha: alpha0.clone(),
            effects: values0.clone(),
            extra: None,
        }));
        for step in &steps {
            jobs.push(step.as_ref().map(|(_, p)| {
                Job {
                    snapshot: s,
                    alpha: layout.alpha_per_server(p),
                    effects: (0..effects.len())
                        .map(|e| layout.effect_values(p, e).to_vec())
                        .collect(),
                    extra: None,
                }
            }));
        }
        for (c, (_, e)) in candidates.iter().enumerate() {
            let v: Vec<f64> = e
                .parameters()
                .iter()
                .map(|p| absent(p) + effect_step_size(settings, p))
                .collect();
            jobs.push(Some(Job {
                snapshot: s,
                alpha: alpha0.clone(),
                effects: values0.clone(),
                extra: Some((c, v)),
            }));
        }
    }
    let states: Vec<&OperatingState> = snaps.iter().map(|s| &s.state).collect();
    let outputs: Vec<Result<Vec<f64>>> = jobs
        .par_iter()
        .map(|job| {
            let Some(job) = job else {
                return Ok(Vec::new());
            };
            let mut list = effect_list(&effects, &job.effects);
            if let Some((c, v)) = &job.extra {
                list.push((candidates[*c].1.as_ref(), v.as_slice()));
            }
            solver.solve(states[job.snapshot], &job.alpha, &list)
        })
        .collect();
    let per_snap = 1 + steps.len() + candidates.len();
    // The base and the calibrated parameters' steps are needed; a candidate whose run
    // failed in any snapshot is dropped.
    let mut failed: Vec<Option<String>> = vec![None; candidates.len()];
    let mut outputs_ok: Vec<Vec<f64>> = Vec::with_capacity(outputs.len());
    for (j, out) in outputs.into_iter().enumerate() {
        let slot = j % per_snap;
        match out {
            Ok(v) => outputs_ok.push(v),
            Err(e) if slot <= steps.len() => return Err(e),
            Err(e) => {
                failed[slot - 1 - steps.len()].get_or_insert(e.to_string());
                outputs_ok.push(Vec::new());
            }
        }
    }
    let outputs = outputs_ok;
    let n_out = hall.sensors.len();
    let base: Vec<Vec<f64>> = (0..n_snap).map(|s| outputs[s * per_snap].clone()).collect();
    let column = |s: usize, j: usize, h: f64| -> Vec<f64> {
        outputs[s * per_snap + j]
            .iter()
            .zip(&base[s])
            .map(|(y, y0)| (y - y0) / h)
            .collect()
    };
    let block =
        |cols: Vec<Vec<f64>>| Array2::from_shape_fn((n_out, cols.len()), |(k, c)| cols[c][k]);
    let jac: Vec<Array2<f64>> = (0..n_snap)
        .map(|s| {
            let cols = steps
                .iter()
                .enumerate()
                .map(|(i, step)| match step {
                    Some((h, _)) => column(s, 1 + i, *h),
                    None => vec![0.0; n_out],
                })
                .collect();
            block(cols)
        })
        .collect();
    let mut residuals = Residuals::from_observations(&obs, &base, &jac, space.names())?;
    // Each row's model uncertainty: the finer grid's change (numerical), and the
    // model-form variants' changes in quadrature, each run at the calibrated point.
    let list = effect_list(&effects, &values0);
    let spread_of = |others: &[&dyn EffectSolver]| -> Result<Vec<f64>> {
        let mut u2 = vec![vec![0.0; n_out]; n_snap];
        for other in others {
            let out: Vec<Vec<f64>> = states
                .par_iter()
                .map(|st| other.solve(st, &alpha0, &list))
                .collect::<Result<_>>()?;
            add_spread(&mut u2, &out, &base);
        }
        Ok(measured_sqrt(snaps, &u2))
    };
    if let Some(factor) = settings.refine_factor {
        if let Some(fine) = solver.refined(factor)? {
            residuals = residuals.with_uncertainty(spread_of(&[fine.as_ref()])?)?;
        }
    }
    if settings.model_form {
        let variants = solver.model_form_variants()?;
        if !variants.is_empty() {
            let others: Vec<&dyn EffectSolver> = variants.iter().map(|v| v.as_ref()).collect();
            residuals = residuals.with_model_form(spread_of(&others)?)?;
        }
    }
    let names: Vec<String> = candidates
        .iter()
        .map(|(spec, e)| hypothesis_name(spec, e.as_ref(), &calibrated_names))
        .collect();
    let mut ranked: Vec<refit::Candidate> = Vec::with_capacity(candidates.len());
    for (c, (_, e)) in candidates.iter().enumerate() {
        let ps = e.parameters();
        let name = names[c].clone();
        if let Some(reason) = &failed[c] {
            not_tried.push(NotTried {
                candidate: name,
                count: 1,
                reason: format!("a run failed: {reason}"),
            });
            continue;
        }
        let hp: Vec<HypothesisParam> = ps
            .iter()
            .map(|p| {
                HypothesisParam::bounded(
                    hypothesis_param(&name, &p.name),
                    p.lower - absent(p),
                    p.upper - absent(p),
                )
            })
            .collect();
        let blocks: Vec<Array2<f64>> = (0..n_snap)
            .map(|s| {
                // One finite difference moves every parameter of the candidate at once;
                // candidates of the built-in kinds have one parameter each.
                let cols = ps
                    .iter()
                    .map(|p| column(s, 1 + steps.len() + c, effect_step_size(settings, p)))
                    .collect();
                block(cols)
            })
            .collect();
        ranked.push(refit::Candidate {
            effect: e.as_ref(),
            hypothesis: Hypothesis::from_snapshots(name, hp, &obs, &blocks)?,
        });
    }
    let hypotheses: Vec<Hypothesis> = ranked.iter().map(|c| c.hypothesis.clone()).collect();
    let mut diagnosis = diagnose(&residuals, &hypotheses, &settings.diagnose)?;
    let mut refits = Vec::new();
    if settings.refit_top > 0 && settings.refit_iterations > 0 {
        let lin = refit::Linearisation {
            layout: &layout,
            space,
            effects: &effects,
            params,
            obs: &obs,
            states: &states,
            base: &base,
            jac: &jac,
            residuals: &residuals,
        };
        (diagnosis, refits) = refit::refit_leading(&lin, &mut ranked, diagnosis, settings, solver)?;
    }
    let suggestions = diagnosis
        .hypotheses
        .iter()
        .map(|h| {
            let (spec, e) = names
                .iter()
                .position(|n| *n == h.name)
                .map(|c| &candidates[c])
                .ok_or_else(|| Error::Mismatch(format!("unknown hypothesis `{}`", h.name)))?;
            let mut spec = spec.clone();
            for p in e.parameters() {
                let dq = h
                    .fitted
                    .get(&hypothesis_param(&h.name, &p.name))
                    .unwrap_or(0.0);
                let v = (absent(&p) + dq).clamp(p.lower, p.upper);
                spec.fields
                    .insert(p.name.clone(), json!((v * 1e4).round() / 1e4));
            }
            Ok(spec)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(HallDiagnosis {
        diagnosis,
        suggestions,
        not_tried,
        refits,
    })
}
