//! The held-out cases of `openfoam_heldout`: the development hall with hidden effects
//! at places, sizes and true alphas that the development data do not have.

use kalibre::dc::hall::Hall;
use serde_json::{json, Value};

/// One held-out case: true alphas (web, db, gpu in cfm/W), the hidden effect as a
/// `hall.json` effect entry, and the hypothesis the diagnosis should put on top.
pub struct HeldOut {
    pub name: String,
    pub alpha: [f64; 3],
    /// The hall's aisle containment entries, if any (in its `hall.json`: the user knows it).
    pub containment: Option<fn() -> Value>,
    pub effect: Option<Value>,
    pub expected: Option<String>,
}

/// The development hall's cold aisle contained up to the racks' top (2.0 m): doors at
/// x 2.4 and 5.4, a roof; its long sides are the racks' intakes.
fn cold_aisle_containment() -> Value {
    json!([{ "kind": "cold_aisle", "min_m": [2.4, 1.8, 0.0], "max_m": [5.4, 3.0, 2.0] }])
}

/// Both hot aisles contained up to the ceiling (3.0 m), with the return grilles above
/// them inside: doors at x 2.4 and 5.4, a panel above each row.
fn hot_aisle_containment() -> Value {
    json!([
        { "kind": "hot_aisle", "min_m": [2.4, 0.0, 0.0], "max_m": [5.4, 0.8, 3.0] },
        { "kind": "hot_aisle", "min_m": [2.4, 4.0, 0.0], "max_m": [5.4, 4.8, 3.0] },
    ])
}

/// The cases. Geometry (`data/openfoam/README.md`): racks 0.6 m wide at x = 2.4 ... 4.8;
/// row A y 0.8-1.8 (hot aisle y 0-0.8 behind it), row B y 3.0-4.0 (hot aisle y 4.0-4.8);
/// each rack's servers span z 0-1.0 and 1.0-2.0. The development data hide an offset of
/// -1 C, a slot through B4 at z 1.0-1.2 and a cutout behind B3 at 10 %; these differ in
/// sign, rack, row, height and size, and no cutout sits exactly on a candidate's strip.
pub fn cases() -> Vec<HeldOut> {
    vec![
        HeldOut {
            name: "ho-clean".into(),
            alpha: [0.15, 0.14, 0.11],
            containment: None,
            effect: None,
            expected: None,
        },
        HeldOut {
            name: "ho-offset-warm".into(),
            alpha: [0.12, 0.18, 0.14],
            containment: None,
            effect: Some(json!({"kind": "crac_supply_offset", "offset_c": 0.8})),
            expected: Some("crac_supply_offset".into()),
        },
        HeldOut {
            name: "ho-slot-A2-top".into(),
            alpha: [0.13, 0.17, 0.12],
            containment: None,
            effect: Some(json!({
                "kind": "rack_recirculation", "rack": "A2", "z_m": [1.8, 2.0], "fraction": 0.17,
            })),
            expected: Some("rack_recirculation(rack=A2)".into()),
        },
        HeldOut {
            name: "ho-slot-A4-low".into(),
            alpha: [0.14, 0.16, 0.13],
            containment: None,
            effect: Some(json!({
                "kind": "rack_recirculation", "rack": "A4", "z_m": [0.8, 1.0], "fraction": 0.2,
            })),
            expected: Some("rack_recirculation(rack=A4)".into()),
        },
        HeldOut {
            name: "ho-cutout-A2".into(),
            alpha: [0.13, 0.17, 0.12],
            containment: None,
            effect: Some(json!({
                "kind": "bypass", "position_m": [3.0, 0.2], "size_m": [0.6, 0.4], "fraction": 0.1,
            })),
            expected: Some("bypass(behind_rack=A2)".into()),
        },
        HeldOut {
            name: "ho-cutout-B4".into(),
            alpha: [0.15, 0.14, 0.11],
            containment: None,
            effect: Some(json!({
                "kind": "bypass", "position_m": [4.4, 4.2], "size_m": [0.4, 0.4], "fraction": 0.08,
            })),
            expected: Some("bypass(behind_rack=B4)".into()),
        },
        HeldOut {
            name: "ho-clean-2".into(),
            alpha: [0.11, 0.19, 0.13],
            containment: None,
            effect: None,
            expected: None,
        },
        HeldOut {
            name: "ho-slot-A3-mid".into(),
            alpha: [0.13, 0.17, 0.12],
            containment: None,
            effect: Some(json!({
                "kind": "rack_recirculation", "rack": "A3", "z_m": [1.0, 1.2], "fraction": 0.17,
            })),
            expected: Some("rack_recirculation(rack=A3)".into()),
        },
        HeldOut {
            name: "ho-slot-B2-wide".into(),
            alpha: [0.12, 0.18, 0.14],
            containment: None,
            effect: Some(json!({
                "kind": "rack_recirculation", "rack": "B2", "z_m": [1.0, 1.4], "fraction": 0.25,
            })),
            expected: Some("rack_recirculation(rack=B2)".into()),
        },
        HeldOut {
            name: "ho-cutout-A4-big".into(),
            alpha: [0.14, 0.16, 0.13],
            containment: None,
            effect: Some(json!({
                "kind": "bypass", "position_m": [4.2, 0.2], "size_m": [0.6, 0.4], "fraction": 0.15,
            })),
            expected: Some("bypass(behind_rack=A4)".into()),
        },
        // Session 22: the OpenFOAM case can be contained. A contained hall, clean, and
        // the same hall with its +x door half open.
        HeldOut {
            name: "ho-contained-clean".into(),
            alpha: [0.14, 0.15, 0.12],
            containment: Some(cold_aisle_containment),
            effect: None,
            expected: None,
        },
        HeldOut {
            name: "ho-contained-door-open".into(),
            alpha: [0.13, 0.17, 0.12],
            containment: Some(cold_aisle_containment),
            effect: Some(json!({
                "kind": "containment_leakage", "containment": 0, "sides": ["+x"], "open_fraction": 0.5,
            })),
            expected: Some(r#"containment_leakage(containment=0,sides=["+x"])"#.into()),
        },
        // Session 23: the returns take no inflow, so hot aisles can be contained too.
        HeldOut {
            name: "ho-hot-contained-clean".into(),
            alpha: [0.12, 0.16, 0.13],
            containment: Some(hot_aisle_containment),
            effect: None,
            expected: None,
        },
        HeldOut {
            name: "ho-hot-contained-door-open".into(),
            alpha: [0.15, 0.15, 0.11],
            containment: Some(hot_aisle_containment),
            effect: Some(json!({
                "kind": "containment_leakage", "containment": 1, "sides": ["-x"], "open_fraction": 0.5,
            })),
            expected: Some(r#"containment_leakage(containment=1,sides=["-x"])"#.into()),
        },
    ]
}

/// `--sweep blanking`: the development hall's missing blanking panel (a slot at z
/// 1.0-1.2 m through the rack, about 0.16 of its flow) moved to each rack in turn, at the
/// development data's true alphas. A hidden hall "like" the development ones is most
/// likely this: the same effect at another place.
pub fn blanking_sweep(hall: &Hall) -> Vec<HeldOut> {
    hall.racks
        .iter()
        .map(|r| HeldOut {
            name: format!("sweep-slot-{}", r.id),
            alpha: [0.13, 0.17, 0.12],
            containment: None,
            effect: Some(json!({
                "kind": "rack_recirculation", "rack": r.id, "z_m": [1.0, 1.2], "fraction": 0.16,
            })),
            expected: Some(format!("rack_recirculation(rack={})", r.id)),
        })
        .collect()
}
