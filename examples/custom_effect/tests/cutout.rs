//! The downstream `cutout_bypass` effect: it moves the readings it should, its entries are
//! checked with typed errors, the diagnosis ranks it, and calibrating it lowers the error.
//! Figures in the comments were measured on the default `DemoOptions` (demo seed 7, the
//! cut-out `HA1-08` at x 6.9, y 4.2 m carrying 10 % of the supply, noise 0.15 C).

use std::sync::OnceLock;

use kalibre::core::Model;
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::{Aisle, EffectSpec, Hall};
use kalibre::dc::sim::SimConfig;
use kalibre::dc::{Error, HallModel};
use kalibre_custom_effect::story::{
    best_cutout, calibrate, demo_hall, diagnose, with_effect, DemoHall, DemoOptions,
};
use kalibre_custom_effect::{cutout_spec, registry, KIND};
use serde_json::json;

fn reg() -> EffectRegistry {
    registry().expect("cutout_bypass registers next to the built-in kinds")
}

fn demo() -> &'static DemoHall {
    static DEMO: OnceLock<DemoHall> = OnceLock::new();
    DEMO.get_or_init(|| demo_hall(&DemoOptions::default(), &reg()).expect("demo hall"))
}

/// Readings of snapshot 0 at the hall's initial alphas, with `effects`.
fn readings(hall: &Hall, effects: &[EffectSpec]) -> Vec<f64> {
    let mut h = hall.clone();
    h.effects = effects.to_vec();
    let model = HallModel::with_registry(&h, SimConfig::default(), &reg()).expect("model");
    let p = model.layout().space().initial();
    model
        .evaluate(&demo().snapshots[0].state, &p)
        .expect("solve")
        .values
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0), |(s, n), x| (s + x, n + 1));
    s / n as f64
}

#[test]
fn the_cutout_cools_the_hot_aisle_at_the_tile_and_starves_the_cold_aisles() {
    let hall = &demo().hall;
    let tile = |f| cutout_spec("HA1-08", [6.9, 4.2], Some(f));
    let base = readings(hall, &[]);
    // A closed cut-out is no cut-out.
    assert_eq!(readings(hall, &[tile(0.0)]), base);
    let half = readings(hall, &[tile(0.05)]);
    let full = readings(hall, &[tile(0.1)]);
    let near: Vec<usize> = hall
        .sensors
        .iter()
        .enumerate()
        .filter(|(_, s)| {
            s.aisle == Aisle::Hot && (s.position_m[0] - 6.9).hypot(s.position_m[1] - 4.2) < 1.0
        })
        .map(|(k, _)| k)
        .collect();
    assert_eq!(
        near.len(),
        2,
        "two hot-aisle sensors within 1 m of the tile"
    );
    // Supply air at the tile cools the exhaust around it (measured -1.98 C on average,
    // -3.5 C at h-B09-17), more with more flow.
    let d_full = mean(near.iter().map(|&k| full[k] - base[k]));
    let d_half = mean(near.iter().map(|&k| half[k] - base[k]));
    assert!(
        d_full < -1.0,
        "near-tile hot sensors change by {d_full:.3} C"
    );
    assert!(
        d_full < d_half && d_half < 0.0,
        "{d_half:.3} then {d_full:.3} C"
    );
    // The air it takes is missing at the regular tiles: the cold aisles warm (measured
    // +1.9 C on average).
    let cold: Vec<usize> = (0..hall.sensors.len())
        .filter(|&k| hall.sensors[k].aisle == Aisle::Cold)
        .collect();
    let d_cold = mean(cold.iter().map(|&k| full[k] - base[k]));
    assert!(d_cold > 0.5, "cold-aisle sensors change by {d_cold:.3} C");
}

#[test]
fn bad_entries_get_typed_errors_naming_the_field() {
    let hall = &demo().hall;
    let registry = reg();
    let cases = [
        (
            json!({"kind": KIND, "position_m": [6.9, 4.2]}),
            "`tile`",
            "missing",
        ),
        (
            json!({"kind": KIND, "tile": "T"}),
            "`position_m`",
            "missing",
        ),
        (
            json!({"kind": KIND, "tile": "T", "position_m": [11.9, 4.2]}),
            "`position_m`",
            "inside the room",
        ),
        (
            json!({"kind": KIND, "tile": "T", "position_m": [6.9, 4.2], "flow_fraction": 0.4}),
            "`flow_fraction`",
            "outside [0, 0.3]",
        ),
        (
            json!({"kind": KIND, "tile": "T", "position_m": [6.9, 4.2], "flow_fraction_bounds": [0, 0.9]}),
            "`flow_fraction_bounds`",
            "within [0, 0.3]",
        ),
        (
            json!({"kind": KIND, "tile": "T", "position_m": [6.9, 4.2], "size_m": [0, 0.6]}),
            "`size_m`",
            "(0, 2]",
        ),
        (
            json!({"kind": KIND, "tile": "T", "position_m": "6.9,4.2"}),
            "`position_m`",
            "array of 2 numbers",
        ),
        (
            json!({"kind": KIND, "tile": "T", "position_m": [6.9, 4.2], "fraction": 0.1}),
            "`fraction`",
            "unknown field",
        ),
    ];
    for (v, field, needle) in cases {
        let spec: EffectSpec = serde_json::from_value(v.clone()).expect("an entry");
        match registry.build(&spec, hall) {
            Err(e @ Error::Effect { .. }) => {
                let msg = e.to_string();
                assert!(
                    msg.contains(KIND) && msg.contains(field) && msg.contains(needle),
                    "{v}: {msg}"
                );
            }
            other => panic!("{v}: expected an effect error, got {other:?}"),
        }
    }
    // Registering the kind twice is refused.
    assert!(reg()
        .with(Box::new(kalibre_custom_effect::CutoutBypassFactory))
        .is_err());
}

#[test]
fn diagnosis_at_the_true_alphas_ranks_the_hidden_tile_among_the_supply_bypasses() {
    let d = demo();
    let registry = reg();
    let diag = diagnose(&d.hall, &d.snapshots, &d.true_alpha_type, &registry).expect("diagnose");
    let hyps = &diag.diagnosis.hypotheses;
    // Measured: bypass behind B08 (explained 0.874), bypass behind A08 (0.864), then
    // cutout_bypass HA1-08 (0.853, fitted 0.074 against 0.1): supply air entering the hot
    // aisle at the same place, which the 24 sensors barely tell apart.
    let (rank, suggestion) = best_cutout(&diag).expect("a cut-out hypothesis");
    assert!(rank < 3, "rank {}: {:?}", rank + 1, &hyps[..5]);
    assert_eq!(suggestion.fields["tile"], "HA1-08", "{suggestion:?}");
    assert!(hyps[rank].significant, "{:?}", hyps[rank]);
    for h in &hyps[..3] {
        assert!(
            h.name.starts_with("bypass(") || h.name.starts_with("cutout_bypass("),
            "the top three are supply bypasses: {:?}",
            &hyps[..3]
        );
    }
}

#[test]
fn after_calibrating_alpha_the_cutout_is_ranked_and_calibrating_it_lowers_the_error() {
    let d = demo();
    let registry = reg();
    let settings = HallCalibrationSettings::default();
    let first = calibrate(&d.hall, &d.snapshots, &registry, &settings).expect("alpha alone");
    // Measured: 2.901 -> 0.785 C, against 0.397 C for the model at the truth (its grid
    // error and the noise) and 0.12 C for the noise alone. The stall criterion:
    // at least twice the noise-only floor.
    assert!(
        first.mae_after() > 2.0 * d.noise_mae_c,
        "alpha alone stalls: {:.3} C against the noise-only floor {:.3} C",
        first.mae_after(),
        d.noise_mae_c
    );
    let best = first.calibration.report.best.params.values();
    let diag = diagnose(&d.hall, &d.snapshots, &best, &registry).expect("diagnose");
    let hyps = &diag.diagnosis.hypotheses;
    // Measured: bypass behind B09 first (explained 0.542), cutout_bypass HA1-09 (the
    // neighbour of the true tile) second (0.494), significant; HA1-08 itself fourth.
    let (rank, suggestion) = best_cutout(&diag).expect("a cut-out hypothesis");
    assert!(rank < 3, "rank {}: {:?}", rank + 1, &hyps[..5]);
    assert!(hyps[rank].significant, "{:?}", hyps[rank]);
    let x = suggestion.fields["position_m"][0].as_f64().expect("x");
    assert!(
        (x - 6.9).abs() <= 0.6 + 1e-9,
        "within one tile of the truth: {suggestion:?}"
    );
    // Adding it and calibrating alpha with its flow fraction from the hall's initial
    // guess: measured 0.785 -> 0.479 C (-39 %; fitted flow_fraction 0.079 at HA1-09).
    let second = calibrate(
        &with_effect(&d.hall, suggestion),
        &d.snapshots,
        &registry,
        &settings,
    )
    .expect("alpha + cut-out");
    assert!(
        second.mae_after() < 0.8 * first.mae_after(),
        "{:.3} C after, {:.3} C before",
        second.mae_after(),
        first.mae_after()
    );
    let names = second.calibration.model.layout().space().names();
    assert_eq!(
        names.last().map(String::as_str),
        Some("cutout_bypass/flow_fraction")
    );
}
