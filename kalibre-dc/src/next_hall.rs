//! The next hall: a calibrated hall with a diagnosed effect added, warm-started where the
//! diagnosis's fit puts it (what `kalibre diagnose --write-hall` writes, and what the
//! story recalibrates).
//!
//! The diagnosis fits an effect jointly with the calibrated parameters: its predicted MAE
//! is the model's with the effect at its fitted value *and* the parameters moved by their
//! joint change ([`HypothesisResult::current_change`]). With the effect alone at that
//! value and the alphas left where the calibration had them, the hall reads worse than
//! predicted (0.540 C against a predicted 0.203 C on the demo's hall, session 49). So
//! [`refitted_params`] moves the parameters too, and the next hall starts at the point
//! whose MAE the diagnosis predicted.

use kalibre_core::calibrate::{NamedValues, Report};
use kalibre_core::diagnose::HypothesisResult;
use kalibre_core::ParamSpace;

use crate::effects::EffectRegistry;
use crate::hall::{AlphaMode, EffectSpec, Hall};
use crate::{HallModel, ParamLayout, Result};

/// The calibrated parameters `params` moved by hypothesis `h`'s joint change, each kept
/// within its bounds: the point at which `h`'s predicted MAE is linearised. Parameters
/// the change does not name stay as they are.
pub fn refitted_params(
    params: &NamedValues,
    space: &ParamSpace,
    h: &HypothesisResult,
) -> NamedValues {
    NamedValues(
        params
            .0
            .iter()
            .map(|(name, x)| {
                let moved = x + h.current_change.get(name).unwrap_or(0.0);
                let bounded = match space.params().iter().find(|p| &p.name == name) {
                    Some(p) => moved.clamp(p.lower, p.upper),
                    None => moved,
                };
                (name.clone(), bounded)
            })
            .collect(),
    )
}

/// The hall with `entry` added, warm-started at `params` (the parameters of `model`, by
/// name): each type's initial alpha is its value there (the mean over its servers when
/// alpha is per server), each effect already present starts at its values there, and the
/// new one at the values `entry` carries (the diagnosis's fitted ones).
pub fn with_effect_at(
    hall: &Hall,
    params: &NamedValues,
    model: &HallModel,
    registry: &EffectRegistry,
    entry: &EffectSpec,
) -> Result<Hall> {
    let layout: &ParamLayout = model.layout();
    let mut next = hall.clone();
    let values = params.values();
    if layout.mode() != AlphaMode::Fixed {
        let per_server = layout.alpha_per_server(&values);
        let mut sums = std::collections::BTreeMap::<&str, (f64, usize)>::new();
        for (s, a) in hall.servers().zip(&per_server) {
            let e = sums.entry(s.server.server_type.as_str()).or_default();
            e.0 += a;
            e.1 += 1;
        }
        for t in &mut next.server_types {
            if let Some((sum, n)) = sums.get(t.id.as_str()).filter(|(_, n)| *n > 0) {
                let b = &mut t.alpha_cfm_per_w;
                b.initial = (sum / *n as f64).clamp(b.min, b.max);
            }
        }
    }
    for (e, (effect, spec)) in model
        .effects()
        .iter()
        .zip(next.effects.iter_mut())
        .enumerate()
    {
        for (p, v) in effect
            .parameters()
            .iter()
            .zip(layout.effect_values(&values, e))
        {
            spec.fields
                .insert(p.name.clone(), serde_json::json!(v.clamp(p.lower, p.upper)));
        }
    }
    // Check the entry builds on this hall before adding it.
    registry.build(entry, &next)?;
    next.effects.push(entry.clone());
    next.validate("hall with the suggested effect")?;
    Ok(next)
}

/// [`with_effect_at`] the calibrated parameters moved by hypothesis `h`'s joint refit
/// ([`refitted_params`]), `entry` being `h`'s suggestion: the hall whose MAE at its
/// initial values is what the diagnosis predicted (to its linearisation).
pub fn with_effect_refitted(
    hall: &Hall,
    report: &Report,
    model: &HallModel,
    registry: &EffectRegistry,
    h: &HypothesisResult,
    entry: &EffectSpec,
) -> Result<Hall> {
    let params = refitted_params(&report.best.params, model.layout().space(), h);
    with_effect_at(hall, &params, model, registry, entry)
}

/// [`with_effect_at`] the calibrated parameters themselves (`report.best.params`), not
/// refitted beside the effect.
pub fn with_effect_from_report(
    hall: &Hall,
    report: &Report,
    model: &HallModel,
    registry: &EffectRegistry,
    entry: &EffectSpec,
) -> Result<Hall> {
    with_effect_at(hall, &report.best.params, model, registry, entry)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibre_core::Scale;

    fn hypothesis(change: &[(&str, f64)]) -> HypothesisResult {
        let json = serde_json::json!({
            "name": "h", "explained_fraction": 0.5, "predicted_mae": 0.2, "delta_bic": -20.0,
            "held_out_improvement": 0.3, "significant": true, "inert": false,
            "identifiable": true, "independence": 1.0, "movement_sigma": 10.0,
            "collinear_with": [], "added_rank": 1, "fitted": {"q": 1.0}, "in_range": true,
            "current_change": change.iter().map(|(n, v)| (n.to_string(), serde_json::json!(v)))
                .collect::<serde_json::Map<String, serde_json::Value>>(),
        });
        serde_json::from_value(json).expect("a hypothesis record")
    }

    #[test]
    fn refitted_params_move_by_the_joint_change_within_bounds() {
        let mut space = ParamSpace::new();
        for name in ["alpha/a", "alpha/b", "alpha/c"] {
            space = space.with(name, 0.05, 0.3, 0.1, Scale::Linear).unwrap();
        }
        let names: Vec<String> = space.names();
        let best = NamedValues::new(&names, &[0.1, 0.29, 0.2]);
        let h = hypothesis(&[("alpha/a", 0.02), ("alpha/b", 0.05)]);
        let moved = refitted_params(&best, &space, &h);
        assert!((moved.get("alpha/a").unwrap() - 0.12).abs() < 1e-12);
        // Beyond its upper bound: held there.
        assert_eq!(moved.get("alpha/b"), Some(0.3));
        // Not in the change: unmoved.
        assert_eq!(moved.get("alpha/c"), Some(0.2));
    }
}
