//! Where a calibrated hall model fails and which physical effect is missing: the
//! built-in simulator supplies the Jacobians (cheap, whatever model was calibrated), each
//! effect kind supplies its candidate placements, and `kalibre_core::diagnose` ranks them.

use ndarray::Array2;
use rayon::prelude::*;
use serde_json::{json, Value};

use kalibre_core::diagnose::{
    diagnose, DiagnoseSettings, Diagnosis, Hypothesis, HypothesisParam, Residuals,
};
use kalibre_core::ParamSpace;

use crate::effects::{Effect, EffectRegistry};
use crate::hall::{EffectSpec, Hall};
use crate::sim::{SimConfig, Simulator};
use crate::snapshots::{self, HallSnapshot, OperatingState};
use crate::{Error, ParamLayout, Result};

/// Settings of a hall diagnosis.
///
/// | Name | Default | Meaning |
/// |---|---|---|
/// | `sim` | [`SimConfig::default`] | the simulator that supplies the Jacobians |
/// | `unit_step` | 0.01 | finite-difference step of calibrated parameters (unit box) |
/// | `effect_step` | 0.05 | finite-difference step of effect parameters (share of their range) |
/// | `diagnose` | [`DiagnoseSettings::default`] | ranking, significance, held-out check |
#[derive(Debug, Clone)]
pub struct HallDiagnosisSettings {
    /// Simulator configuration.
    pub sim: SimConfig,
    /// Step of calibrated parameters in the unit box.
    pub unit_step: f64,
    /// Step of effect parameters as a share of their range.
    pub effect_step: f64,
    /// The generic diagnosis settings.
    pub diagnose: DiagnoseSettings,
}

impl Default for HallDiagnosisSettings {
    fn default() -> Self {
        HallDiagnosisSettings {
            sim: SimConfig::default(),
            unit_step: 0.01,
            effect_step: 0.05,
            diagnose: DiagnoseSettings::default(),
        }
    }
}

/// A diagnosis with the `hall.json` entry each hypothesis suggests.
#[derive(Debug, Clone)]
pub struct HallDiagnosis {
    /// The ranked hypotheses.
    pub diagnosis: Diagnosis,
    /// Per hypothesis (same order as `diagnosis.hypotheses`): the `effects` entry to add,
    /// with the fitted parameter values.
    pub suggestions: Vec<EffectSpec>,
}

impl HallDiagnosis {
    /// The `kalibre.diagnosis/1` JSON of `formats.md`.
    pub fn to_json(&self) -> Value {
        let hyps: Vec<Value> = self
            .diagnosis
            .hypotheses
            .iter()
            .zip(&self.suggestions)
            .map(|(h, s)| {
                json!({
                    "effect": s.kind,
                    "name": h.name,
                    "explained_fraction": h.explained_fraction,
                    "predicted_mae_c": h.predicted_mae,
                    "significant": h.significant,
                    "inert": h.inert,
                    "identifiable": h.identifiable,
                    "delta_bic": h.delta_bic,
                    "held_out_improvement": h.held_out_improvement,
                    "suggestion": s,
                })
            })
            .collect();
        json!({ "schema": "kalibre.diagnosis/1", "mae_c": self.diagnosis.mae, "hypotheses": hyps })
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

/// One simulator run of the diagnosis: alpha per server and effect values.
struct Job {
    snapshot: usize,
    alpha: Vec<f64>,
    effects: Vec<Vec<f64>>,
    extra: Option<(usize, Vec<f64>)>,
}

/// Diagnoses `hall` at calibrated parameters `params` (in the order of the hall's
/// [`ParamLayout`], e.g. a report's best parameters) against `snaps`.
pub fn diagnose_hall(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
    registry: &EffectRegistry,
    settings: &HallDiagnosisSettings,
) -> Result<HallDiagnosis> {
    let obs = snapshots::to_observations(hall, snaps)?;
    let effects = registry.build_all(hall)?;
    let layout = ParamLayout::new(hall, &effects)?;
    let space: &ParamSpace = layout.space();
    space.check_physical(params)?;
    let sim = Simulator::new(hall, settings.sim.clone())?;
    let candidates: Vec<(EffectSpec, Box<dyn Effect>)> = registry
        .kinds()
        .iter()
        .filter_map(|k| registry.get(k))
        .flat_map(|f| f.candidates(hall))
        .filter(|spec| !hall.effects.contains(spec))
        .map(|spec| registry.build(&spec, hall).map(|e| (spec, e)))
        .collect::<Result<_>>()?;

    let alpha0 = layout.alpha_per_server(params);
    let values0: Vec<Vec<f64>> = (0..effects.len())
        .map(|e| layout.effect_values(params, e).to_vec())
        .collect();
    let n_snap = snaps.len();
    let unit = space.to_unit(params)?;
    // Calibrated parameters: forward (backward at the upper bound) steps in the unit box.
    let mut steps = Vec::with_capacity(space.dim());
    for i in 0..space.dim() {
        let mut u = unit.clone();
        u[i] = if u[i] + settings.unit_step <= 1.0 {
            u[i] + settings.unit_step
        } else {
            u[i] - settings.unit_step
        };
        let p = space.from_unit(&u)?;
        steps.push((p[i] - params[i], p));
    }
    let mut jobs = Vec::new();
    for s in 0..n_snap {
        jobs.push(Job {
            snapshot: s,
            alpha: alpha0.clone(),
            effects: values0.clone(),
            extra: None,
        });
        for (_, p) in &steps {
            let vals = (0..effects.len())
                .map(|e| layout.effect_values(p, e).to_vec())
                .collect();
            jobs.push(Job {
                snapshot: s,
                alpha: layout.alpha_per_server(p),
                effects: vals,
                extra: None,
            });
        }
        for (c, (_, e)) in candidates.iter().enumerate() {
            let v: Vec<f64> = e
                .parameters()
                .iter()
                .map(|p| p.initial + settings.effect_step * (p.upper - p.lower))
                .collect();
            jobs.push(Job {
                snapshot: s,
                alpha: alpha0.clone(),
                effects: values0.clone(),
                extra: Some((c, v)),
            });
        }
    }
    let states: Vec<&OperatingState> = snaps.iter().map(|s| &s.state).collect();
    let outputs: Vec<Vec<f64>> = jobs
        .par_iter()
        .map(|job| {
            let mut list: Vec<(&dyn Effect, &[f64])> = effects
                .iter()
                .zip(&job.effects)
                .map(|(e, v)| (e.as_ref(), v.as_slice()))
                .collect();
            if let Some((c, v)) = &job.extra {
                list.push((candidates[*c].1.as_ref(), v.as_slice()));
            }
            sim.solve(states[job.snapshot], &job.alpha, &list)
                .map(|sol| sol.sensor_c().to_vec())
        })
        .collect::<Result<_>>()?;

    let per_snap = 1 + steps.len() + candidates.len();
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
                .map(|(i, (h, _))| column(s, 1 + i, *h))
                .collect();
            block(cols)
        })
        .collect();
    let residuals = Residuals::from_observations(&obs, &base, &jac, space.names())?;
    let mut hypotheses = Vec::with_capacity(candidates.len());
    for (c, (spec, e)) in candidates.iter().enumerate() {
        let ps = e.parameters();
        let name = candidate_name(spec);
        let hp: Vec<HypothesisParam> = ps
            .iter()
            .map(|p| {
                HypothesisParam::bounded(
                    format!("{}/{}", spec.kind, p.name),
                    p.lower - p.initial,
                    p.upper - p.initial,
                )
            })
            .collect();
        let blocks: Vec<Array2<f64>> = (0..n_snap)
            .map(|s| {
                // One finite difference moves every parameter of the candidate at once;
                // candidates of the built-in kinds have one parameter each.
                let cols = ps
                    .iter()
                    .map(|p| {
                        column(
                            s,
                            1 + steps.len() + c,
                            settings.effect_step * (p.upper - p.lower),
                        )
                    })
                    .collect();
                block(cols)
            })
            .collect();
        hypotheses.push(Hypothesis::from_snapshots(name, hp, &obs, &blocks)?);
    }
    let diagnosis = diagnose(&residuals, &hypotheses, &settings.diagnose)?;
    let suggestions = diagnosis
        .hypotheses
        .iter()
        .map(|h| {
            let (spec, e) = candidates
                .iter()
                .find(|(s, _)| candidate_name(s) == h.name)
                .ok_or_else(|| Error::Mismatch(format!("unknown hypothesis `{}`", h.name)))?;
            let mut spec = spec.clone();
            for p in e.parameters() {
                let dq = h
                    .fitted
                    .get(&format!("{}/{}", spec.kind, p.name))
                    .unwrap_or(0.0);
                let v = (p.initial + dq).clamp(p.lower, p.upper);
                spec.fields
                    .insert(p.name.clone(), json!((v * 1e4).round() / 1e4));
            }
            Ok(spec)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(HallDiagnosis {
        diagnosis,
        suggestions,
    })
}
