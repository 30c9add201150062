//! The built-in model's fingerprint leaves out what a run at given parameter values does
//! not depend on (the calibrated parameters' bounds and initial values), and its legacy
//! fingerprint is exactly what earlier versions journaled runs under, so that their
//! journals are still read.

use kalibre_core::Model;
use kalibre_dc::hall::Hall;
use kalibre_dc::sim::SimConfig;
use kalibre_dc::HallModel;

/// of-dev-clean as shipped.
fn plain() -> Hall {
    serde_json::from_str(include_str!("../../data/openfoam/of-dev-clean/hall.json")).unwrap()
}

/// of-dev-clean with two effects, one with bounds of its own and one at its defaults.
fn hall() -> Hall {
    let mut json = serde_json::to_value(plain()).unwrap();
    json["effects"] = serde_json::json!([
        { "kind": "crac_supply_offset", "crac": "crac-1", "offset_c": 0.5,
          "offset_c_bounds": [-2.0, 2.0] },
        { "kind": "rack_recirculation", "rack": "A1" }
    ]);
    serde_json::from_value(json).unwrap()
}

fn model(hall: &Hall) -> HallModel {
    HallModel::new(hall, SimConfig::default()).unwrap()
}

/// The hall with other bounds and initial values for alpha and for the effects.
fn searched_elsewhere(hall: &Hall) -> Hall {
    let mut h = hall.clone();
    h.server_types[0].alpha_cfm_per_w.max = 1.0;
    h.server_types[1].alpha_cfm_per_w.min = 0.05;
    h.server_types[2].alpha_cfm_per_w.initial = 0.4;
    if let Some(offset) = h.effects.first_mut() {
        let f = &mut offset.fields;
        f.insert("offset_c_bounds".into(), serde_json::json!([-1.0, 1.5]));
        f.insert("offset_c".into(), serde_json::json!(-0.25));
    }
    if let Some(recirculation) = h.effects.get_mut(1) {
        let f = &mut recirculation.fields;
        f.insert("fraction".into(), serde_json::json!(0.3));
        f.insert("fraction_bounds".into(), serde_json::json!([0.0, 0.6]));
    }
    h
}

/// 64-bit FNV-1a, as the model hashes.
fn fnv1a(parts: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in parts {
        for b in p.iter().chain(b"\x00") {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// The fingerprint as versions up to this change computed it: the hall's physics JSON
/// (bounds and initial values included), the configuration and the effects' entries.
fn old_formula(hall: &Hall, config: &SimConfig) -> String {
    let model = HallModel::new(hall, config.clone()).unwrap();
    let specs: Vec<_> = model.effects().iter().map(|e| e.to_spec()).collect();
    format!(
        "kalibre-dc-sim/3:{:016x}",
        fnv1a(&[
            hall.physics_json().as_bytes(),
            serde_json::to_string(config).unwrap().as_bytes(),
            serde_json::to_string(&specs).unwrap().as_bytes(),
        ])
    )
}

/// Pinned before the change: what `HallModel::new` gave these halls with the default
/// configuration (`fingerprint()` then). Journals written then hold these.
#[test]
fn the_legacy_fingerprint_is_the_one_earlier_versions_gave() {
    let pinned = [
        (plain(), "kalibre-dc-sim/3:c6490c6057133148"),
        (hall(), "kalibre-dc-sim/3:e8e1a706edf323d9"),
    ];
    for (h, then) in pinned {
        let m = model(&h);
        assert_eq!(m.legacy_fingerprints(), vec![then.to_string()]);
        assert_eq!(old_formula(&h, &SimConfig::default()), then);
        assert_ne!(m.fingerprint(), then, "the new fingerprint is another hash");
    }
    // The old formula, bounds and initial values included, on any hall and grid.
    let config = SimConfig::default().with_cell_m(0.1);
    let h = searched_elsewhere(&hall());
    let m = HallModel::new(&h, config.clone()).unwrap();
    assert_eq!(m.legacy_fingerprints(), vec![old_formula(&h, &config)]);
    assert_ne!(
        m.legacy_fingerprints(),
        model(&hall()).legacy_fingerprints()
    );
}

#[test]
fn bounds_and_initial_values_are_not_in_the_fingerprint() {
    for h in [plain(), hall()] {
        let fingerprint = model(&h).fingerprint();
        assert_eq!(model(&searched_elsewhere(&h)).fingerprint(), fingerprint);
        // The physics is: a CRAC's flow, where an effect acts, the grid.
        let mut cooler = h.clone();
        cooler.cracs[0].rated_flow_m3_s *= 1.1;
        assert_ne!(model(&cooler).fingerprint(), fingerprint);
        let finer = HallModel::new(&h, SimConfig::default().with_cell_m(0.1)).unwrap();
        assert_ne!(finer.fingerprint(), fingerprint);
    }
    let mut lower = hall();
    lower.effects[1]
        .fields
        .insert("z_m".into(), serde_json::json!([0.0, 1.0]));
    assert_ne!(model(&lower).fingerprint(), model(&hall()).fingerprint());
}

/// With alpha fixed, every run takes its initial value: that is physics.
#[test]
fn a_fixed_alpha_is_in_the_fingerprint() {
    let mut fixed = hall();
    fixed.calibrate.alpha = kalibre_dc::hall::AlphaMode::Fixed;
    let fingerprint = model(&fixed).fingerprint();
    let mut wider = fixed.clone();
    wider.server_types[0].alpha_cfm_per_w.max = 1.0;
    assert_eq!(model(&wider).fingerprint(), fingerprint);
    let mut other = fixed.clone();
    other.server_types[0].alpha_cfm_per_w.initial = 0.4;
    assert_ne!(model(&other).fingerprint(), fingerprint);
    assert_ne!(model(&hall()).fingerprint(), fingerprint);
}

/// A hall with `front` CRACs changed model when their supply came to enter along the
/// jet: its fingerprint is not the one of the face release, and it has no legacy one
/// (runs journaled before are another model's). A hall of floor CRACs keeps its own.
#[test]
fn front_supply_along_the_jet_is_another_model() {
    use kalibre_dc::sim::FrontSupply;
    let mut front = plain();
    front.tiles.clear();
    front.cracs[0].supply = kalibre_dc::hall::SupplyKind::Front;
    let jet = model(&front);
    let face = HallModel::new(
        &front,
        SimConfig::default().with_front_supply(FrontSupply::Face),
    )
    .unwrap();
    assert_ne!(jet.fingerprint(), face.fingerprint());
    assert!(jet.legacy_fingerprints().is_empty());
    // A floor hall: the option is not written, so its fingerprints are as before.
    let floor = model(&plain());
    let floor_face = HallModel::new(
        &plain(),
        SimConfig::default().with_front_supply(FrontSupply::Face),
    )
    .unwrap();
    assert_eq!(floor.legacy_fingerprints().len(), 1);
    assert_ne!(
        floor.fingerprint(),
        floor_face.fingerprint(),
        "the option is in the config"
    );
}
