//! Effects: the registry's errors, spec round trips, and that each effect moves the
//! readings it should, in the expected direction only.

#[path = "support/sim_halls.rs"]
mod sim_halls;

use kalibre_core::{Model, Param, Scale};
use kalibre_dc::effects::{from_spec, Effect, EffectFactory, EffectRegistry};
use kalibre_dc::hall::{EffectSpec, Hall, Side};
use kalibre_dc::sim::{AirLink, SimConfig, SimMods, Simulator};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::{Error, HallModel};
use serde_json::{json, Value};
use sim_halls::{contained_hall, demo_hall, uniform_state};

fn spec(v: Value) -> EffectSpec {
    serde_json::from_value(v).expect("spec json")
}

fn effect_error(v: Value, hall: &Hall) -> String {
    match from_spec(&spec(v), hall) {
        Err(e @ Error::Effect { .. }) => e.to_string(),
        Err(e) => panic!("wrong error type: {e}"),
        Ok(e) => panic!("accepted: {e:?}"),
    }
}

/// Sensor readings with and without one effect at the given values.
fn with_and_without(
    hall: &Hall,
    state: &OperatingState,
    alpha: f64,
    e: &dyn Effect,
    values: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let sim = Simulator::new(hall, SimConfig::default()).expect("sim");
    let a = vec![alpha; hall.server_count()];
    let base = sim.solve(state, &a, &[]).expect("base").sensor_c().to_vec();
    let on = sim
        .solve(state, &a, &[(e, values)])
        .expect("with effect")
        .sensor_c()
        .to_vec();
    (base, on)
}

fn idx(hall: &Hall, id: &str) -> usize {
    hall.sensors
        .iter()
        .position(|s| s.id == id)
        .unwrap_or_else(|| panic!("no sensor {id}"))
}

#[test]
fn bad_entries_get_errors_naming_the_field() {
    let hall = demo_hall();
    let cases = [
        (json!({"kind": "leakage"}), "unknown effect kind"),
        (json!({"kind": "bypass", "fraction": 0.1}), "`position_m`"),
        (
            json!({"kind": "bypass", "behind_rack": "A01", "fracton": 0.1}),
            "field `fracton`: unknown field",
        ),
        (
            json!({"kind": "bypass", "behind_rack": "A01", "fraction": 0.9}),
            "field `fraction`: 0.9 is outside [0, 0.5]",
        ),
        (
            json!({"kind": "bypass", "behind_rack": "Z99"}),
            "field `behind_rack`: no rack `Z99`",
        ),
        (
            json!({"kind": "bypass", "position_m": [11.8, 1.0], "size_m": [0.6, 0.6]}),
            "field `position_m`",
        ),
        (
            json!({"kind": "crac_supply_offset", "crac": "crac-9"}),
            "field `crac`: no CRAC `crac-9`",
        ),
        (
            json!({"kind": "crac_supply_offset", "offset_c": "cold"}),
            "field `offset_c`: expected a finite number",
        ),
        (
            json!({"kind": "crac_supply_offset", "offset_c_bounds": [2.0, -2.0]}),
            "field `offset_c_bounds`",
        ),
        (
            json!({"kind": "rack_recirculation"}),
            "field `rack`: missing",
        ),
        (
            json!({"kind": "rack_recirculation", "rack": "A01", "z_m": [1.5, 2.5]}),
            "field `z_m`",
        ),
        (
            json!({"kind": "rack_recirculation", "rack": "A01", "fraction": -0.1}),
            "field `fraction`",
        ),
        (json!({"kind": "containment_leakage"}), "no containment"),
        // A typo is named before the required field it leaves missing.
        (
            json!({"kind": "bypass", "foo": 1}),
            "field `foo`: unknown field",
        ),
        (
            json!({"kind": "rack_recirculation", "rak": "A01"}),
            "field `rak`: unknown field",
        ),
        (
            json!({"kind": "crac_supply_offset", "offset_c_bound": [0, 1]}),
            "field `offset_c_bound`: unknown field (known: crac, offset_c, offset_c_bounds)",
        ),
    ];
    for (v, want) in cases {
        let msg = effect_error(v.clone(), &hall);
        assert!(msg.contains(want), "{v}: `{msg}` lacks `{want}`");
    }
    let ch = contained_hall(false);
    let msg = effect_error(
        json!({"kind": "containment_leakage", "sides": ["north"]}),
        &ch,
    );
    assert!(msg.contains("field `sides`"), "{msg}");
    let msg = effect_error(
        json!({"kind": "containment_leakage", "containment": 3}),
        &ch,
    );
    assert!(msg.contains("field `containment`"), "{msg}");
}

#[test]
fn specs_round_trip_and_name_parameters() {
    let hall = demo_hall();
    for v in [
        json!({"kind": "crac_supply_offset", "crac": "crac-2", "offset_c": -1.5}),
        json!({"kind": "bypass", "position_m": [4.0, 0.6], "size_m": [0.6, 0.4], "fraction": 0.1, "fraction_bounds": [0.0, 0.3]}),
        json!({"kind": "bypass", "behind_rack": "B03", "depth_m": 0.6}),
        json!({"kind": "rack_recirculation", "rack": "A05", "z_m": [1.0, 1.2], "fraction": 0.2}),
    ] {
        let e = from_spec(&spec(v.clone()), &hall).expect("build");
        let again = from_spec(&e.to_spec(), &hall).expect("rebuild");
        assert_eq!(e.parameters(), again.parameters(), "{v}");
        assert_eq!(e.to_spec(), again.to_spec());
    }
    let mut h = demo_hall();
    h.effects = vec![
        spec(json!({"kind": "crac_supply_offset"})),
        spec(json!({"kind": "bypass", "behind_rack": "A01"})),
    ];
    let m = HallModel::new(&h, SimConfig::default()).expect("model");
    let names = m.layout().space().names();
    assert!(
        names.contains(&"crac_supply_offset/offset_c".to_string()),
        "{names:?}"
    );
    assert!(names.contains(&"bypass/fraction".to_string()), "{names:?}");
    let mut bad = demo_hall();
    bad.effects = vec![spec(
        json!({"kind": "bypass", "behind_rack": "A01", "fraction": 2.0}),
    )];
    let err = HallModel::new(&bad, SimConfig::default()).expect_err("out of range");
    assert!(err.to_string().contains("effects/0"), "{err}");
}

/// A downstream kind: a forced link moving hot-aisle air into the cold aisle.
#[derive(Debug)]
struct Fan;
impl Effect for Fan {
    fn kind(&self) -> &str {
        "test_fan"
    }
    fn parameters(&self) -> Vec<Param> {
        vec![Param::new("flow_m3_s", 0.0, 1.0, 0.2, Scale::Linear).expect("param")]
    }
    fn to_spec(&self) -> EffectSpec {
        spec(json!({"kind": "test_fan"}))
    }
    fn modify(&self, v: &[f64], _h: &Hall, m: &mut SimMods) -> kalibre_dc::Result<()> {
        m.air_links.push(AirLink {
            from: kalibre_dc::hall::Aabb {
                min: [7.8, 1.0, 0.2],
                max: [8.4, 1.8, 1.0],
            },
            to: kalibre_dc::hall::Aabb {
                min: [7.8, 3.0, 0.2],
                max: [8.4, 3.4, 1.0],
            },
            flow_m3_s: v[0],
        });
        Ok(())
    }
}
struct FanFactory;
impl EffectFactory for FanFactory {
    fn kind(&self) -> &str {
        "test_fan"
    }
    fn build(&self, _s: &EffectSpec, _h: &Hall) -> kalibre_dc::Result<Box<dyn Effect>> {
        Ok(Box::new(Fan))
    }
}

#[test]
fn downstream_kinds_register_and_run() {
    let mut reg = EffectRegistry::builtin();
    reg.register(Box::new(FanFactory)).expect("register");
    assert!(
        reg.register(Box::new(FanFactory)).is_err(),
        "duplicate kind accepted"
    );
    let mut hall = demo_hall();
    hall.effects = vec![spec(json!({"kind": "test_fan"}))];
    assert!(
        HallModel::new(&hall, SimConfig::default()).is_err(),
        "builtin registry knows test_fan"
    );
    let m = HallModel::with_registry(&hall, SimConfig::default(), &reg).expect("model");
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    let mut p = m.layout().space().initial();
    let on = m.evaluate(&state, &p).expect("run").values;
    *p.last_mut().expect("fan param") = 0.0;
    let off = m.evaluate(&state, &p).expect("run").values;
    let c = idx(&hall, "c-A11-0");
    assert!(
        on[c] > off[c] + 0.2,
        "link moved hot air into the cold aisle: {} vs {}",
        on[c],
        off[c]
    );
    for k in [
        "crac_supply_offset",
        "bypass",
        "rack_recirculation",
        "containment_leakage",
    ] {
        assert!(reg.get(k).is_some());
    }
    assert!(!reg
        .get("rack_recirculation")
        .expect("kind")
        .candidates(&hall)
        .is_empty());
}

#[test]
fn crac_offset_shifts_every_reading_down() {
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    let all = from_spec(&spec(json!({"kind": "crac_supply_offset"})), &hall).expect("effect");
    let (base, on) = with_and_without(&hall, &state, 0.12, all.as_ref(), &[-1.0]);
    for (b, o) in base.iter().zip(&on) {
        assert!((o - b + 1.0).abs() < 1e-5, "shift {}", o - b);
    }
    let one = from_spec(
        &spec(json!({"kind": "crac_supply_offset", "crac": "crac-1"})),
        &hall,
    )
    .expect("effect");
    let (base, on) = with_and_without(&hall, &state, 0.12, one.as_ref(), &[-1.0]);
    // One of four floor CRACs: the plenum mixes, so every reading falls, by at most 1 C.
    for (b, o) in base.iter().zip(&on) {
        assert!(o - b < -0.05 && o - b > -1.0 - 1e-9, "shift {}", o - b);
    }
}

#[test]
fn rack_recirculation_warms_that_racks_intake_only() {
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    let e = from_spec(
        &spec(json!({"kind": "rack_recirculation", "rack": "A11", "z_m": [1.2, 1.6]})),
        &hall,
    )
    .expect("effect");
    let (base, on) = with_and_without(&hall, &state, 0.12, e.as_ref(), &[0.3]);
    let c = idx(&hall, "c-A11-1");
    assert!(on[c] > base[c] + 0.5, "c-A11-1 {} -> {}", base[c], on[c]);
    let h = idx(&hall, "h-A11-1");
    assert!(
        on[h] > base[h] + 0.2,
        "its exhaust is hotter: {} -> {}",
        base[h],
        on[h]
    );
    // Elsewhere readings barely move: the rack now draws less from the cold aisle, so
    // neighbours may even cool slightly.
    for (i, (b, o)) in base.iter().zip(&on).enumerate() {
        if !hall.sensors[i].id.contains("A11") {
            assert!(
                (o - b).abs() < 0.1,
                "{} moved {}",
                hall.sensors[i].id,
                o - b
            );
        }
    }
}

#[test]
fn bypass_cools_the_hot_aisle_behind_and_starves_the_cold_aisle() {
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    let e = from_spec(
        &spec(json!({"kind": "bypass", "behind_rack": "A08"})),
        &hall,
    )
    .expect("effect");
    let (base, on) = with_and_without(&hall, &state, 0.13, e.as_ref(), &[0.2]);
    let h = idx(&hall, "h-A08-0");
    assert!(on[h] < base[h] - 0.5, "h-A08-0 {} -> {}", base[h], on[h]);
    let cold: Vec<usize> = (0..hall.sensors.len())
        .filter(|&i| hall.sensors[i].id.starts_with("c-"))
        .collect();
    for &i in &cold {
        assert!(
            on[i] - base[i] > -0.02,
            "{} cooled by {}",
            hall.sensors[i].id,
            base[i] - on[i]
        );
    }
    let rise: f64 = cold.iter().map(|&i| on[i] - base[i]).sum::<f64>() / cold.len() as f64;
    assert!(rise > 0.05, "cold aisle mean rise {rise}");
}

#[test]
fn containment_leakage_draws_hot_air_out_where_the_panels_open() {
    // Sealed hot-aisle containment (only the default panel leakage connects the sides):
    // 100 servers at 500 W, alpha 0.15 draw 3.5 m3/s against 3.0 m3/s of supply, so the
    // deficit must come out of the hot aisle through the panels. Opening the -x end
    // draws it there.
    let hall = contained_hall(false);
    let state = uniform_state(&hall, 18.0, 0.6, 500.0);
    let e = from_spec(
        &spec(json!({"kind": "containment_leakage", "sides": ["-x"]})),
        &hall,
    )
    .expect("effect");
    let (base, on) = with_and_without(&hall, &state, 0.15, e.as_ref(), &[0.5]);
    let d = |id: &str| on[idx(&hall, id)] - base[idx(&hall, id)];
    let report: Vec<String> = hall
        .sensors
        .iter()
        .map(|s| format!("{} {:+.3}", s.id, d(&s.id)))
        .collect();
    for id in ["c-A02-0", "c-B02-0"] {
        assert!(d(id) > 0.1, "{id} rose only {}: {report:?}", d(id));
    }
    for id in ["c-A10-0", "c-B10-0"] {
        assert!(
            d(id) < 0.0,
            "{id} at the closed end rose {}: {report:?}",
            d(id)
        );
    }
}

#[test]
fn bypass_candidates_leave_the_tiles_a_share_beside_the_halls_own_openings() {
    let registry = EffectRegistry::builtin();
    let factory = registry.get("bypass").expect("bypass kind");
    let rack = demo_hall().racks[0].id.clone();
    let upper_of = |c: &EffectSpec| c.fields.get("fraction_bounds").map(|b| b[1].as_f64());

    // No openings yet: the default bounds, written as defaults (no field).
    let clean = demo_hall();
    let candidates = factory.candidates(&clean);
    assert_eq!(candidates.len(), clean.racks.len());
    assert!(candidates.iter().all(|c| upper_of(c).is_none()));

    // One default bypass (upper 0.5): the candidates stop at 0.45, and the hall with
    // any one of them added is a hall every check accepts.
    let mut one = demo_hall();
    one.effects
        .push(spec(json!({"kind": "bypass", "behind_rack": rack})));
    let candidates = factory.candidates(&one);
    assert!(!candidates.is_empty());
    for c in &candidates {
        assert_eq!(upper_of(c), Some(Some(0.45)), "{c:?}");
        let mut next = one.clone();
        next.effects.push(c.clone());
        if c.fields["behind_rack"] == json!(rack) {
            continue; // the hall's own placement, which the diagnosis skips
        }
        registry
            .check_hall(&next, "hall.json")
            .expect("hall with a candidate");
        HallModel::new(&next, SimConfig::default()).expect("model with a candidate");
    }

    // The same two at their default bounds could take the whole supply: refused.
    let mut both = one.clone();
    let other = &one.racks[1].id;
    both.effects
        .push(spec(json!({"kind": "bypass", "behind_rack": other})));
    match HallModel::new(&both, SimConfig::default()) {
        Err(Error::Effect { kind, message }) => {
            assert_eq!(kind, "bypass");
            assert!(message.starts_with("effects/1: "), "{message}");
            assert!(message.contains("take the whole supply"), "{message}");
        }
        other => panic!("expected Error::Effect, got {other:?}"),
    }

    // Openings that may take 0.96 of it leave no room: no bypass candidates at all.
    both.effects[1]
        .fields
        .insert("fraction_bounds".into(), json!([0.0, 0.46]));
    registry
        .check_hall(&both, "hall.json")
        .expect("0.96 in all");
    assert!(factory.candidates(&both).is_empty());
}

/// A bypass is an opening of the raised floor's plenum: a hall whose CRACs all blow
/// through their fronts has none, so the entry is refused and the diagnosis proposes
/// none, while one floor CRAC is enough for both.
#[test]
fn a_hall_without_a_plenum_has_no_bypass() {
    use kalibre_dc::hall::SupplyKind;
    let registry = EffectRegistry::builtin();
    let factory = registry.get("bypass").expect("bypass kind");
    let mut front = demo_hall();
    front.tiles.clear();
    front
        .cracs
        .iter_mut()
        .for_each(|c| c.supply = SupplyKind::Front);
    let rack = front.racks[0].id.clone();
    let e = effect_error(json!({"kind": "bypass", "behind_rack": rack}), &front);
    assert!(
        e.contains("an opening of the raised floor's plenum") && e.contains("`front`"),
        "{e}"
    );
    assert!(factory.candidates(&front).is_empty());
    let mut mixed = demo_hall();
    mixed.cracs[0].supply = SupplyKind::Front;
    assert!(from_spec(
        &spec(json!({"kind": "bypass", "behind_rack": rack})),
        &mixed
    )
    .is_ok());
    assert!(!factory.candidates(&mixed).is_empty());
}

#[test]
fn a_floor_opening_partly_under_a_rack_is_refused_like_one_wholly_under_it() {
    let hall = demo_hall();
    let r = &hall.racks[0];
    let [x, y] = [r.position_m[0], r.position_m[1]];
    let [dx, dy] = [r.size_m[0], r.size_m[1]];
    // Wholly under, half under (straddling the rack's x edge), and touching its edge.
    let under = json!({"kind": "bypass", "position_m": [x + 0.1 * dx, y + 0.1 * dy], "size_m": [0.5 * dx, 0.5 * dy]});
    let partly =
        json!({"kind": "bypass", "position_m": [x - 0.5 * dx, y], "size_m": [dx, 0.5 * dy]});
    let id = &r.id;
    assert!(effect_error(under, &hall).contains(&format!("lies under rack `{id}`")));
    let e = effect_error(partly, &hall);
    assert!(e.contains(&format!("runs partly under rack `{id}`")), "{e}");
    assert!(e.contains("position_m"), "{e}");
    let touching =
        spec(json!({"kind": "bypass", "position_m": [x - 0.4, y], "size_m": [0.4, 0.4]}));
    if let Err(e) = from_spec(&touching, &hall) {
        // Only another solid beside the rack may refuse it, never this rack.
        assert!(!e.to_string().contains(&format!("`{id}`")), "{e}");
    }
}

/// A floor opening on a tile would deliver that floor's supply twice (the tile's share
/// and the opening's): refused like overlapping tiles, touching allowed.
#[test]
fn a_floor_opening_over_a_tile_is_refused() {
    let hall = demo_hall();
    let t = &hall.tiles[0];
    let [x, y] = t.position_m;
    let [dx, dy] = t.size_m;
    let over = json!({"kind": "bypass", "position_m": [x + 0.25 * dx, y + 0.25 * dy], "size_m": [0.5 * dx, 0.5 * dy]});
    let e = effect_error(over, &hall);
    assert!(e.contains("the opening overlaps tile 0 (/tiles/0)"), "{e}");
    assert!(e.contains("position_m"), "{e}");
    // Beside the tile, touching its edge.
    let beside = spec(json!({"kind": "bypass", "position_m": [x - 0.2, y], "size_m": [0.2, dy]}));
    if let Err(e) = from_spec(&beside, &hall) {
        assert!(!e.to_string().contains("overlaps tile 0"), "{e}");
    }
}

/// Two floor openings that overlap (two entries, or an opening on a strip behind a
/// rack) could not be told apart where they do: refused naming both entries; openings
/// that only touch pass.
#[test]
fn overlapping_openings_are_refused_touching_ones_pass() {
    let registry = EffectRegistry::builtin();
    let hall = demo_hall();
    let r = &hall.racks[0];
    let back = if r.inlet == Side::MinusY {
        r.position_m[1] + r.size_m[1]
    } else {
        r.position_m[1]
    };
    let opening = |x: f64, y: f64| {
        spec(
            json!({"kind": "bypass", "position_m": [x, y], "size_m": [0.2, 0.2],
                    "fraction_bounds": [0.0, 0.2]}),
        )
    };
    let strip = spec(json!({"kind": "bypass", "behind_rack": r.id, "fraction_bounds": [0.0, 0.2]}));
    let y = if r.inlet == Side::MinusY {
        back + 0.1
    } else {
        back - 0.3
    };
    let x = r.position_m[0] + 0.1;
    for (first, second, what) in [
        (strip.clone(), opening(x, y), "on the strip"),
        (opening(x, y), opening(x + 0.1, y + 0.1), "two openings"),
    ] {
        let mut both = hall.clone();
        both.effects.extend([first, second]);
        let e = registry
            .check_hall(&both, "hall.json")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("hall.json: /effects/1"), "{what}: {e}");
        assert!(
            e.contains("its floor opening overlaps effects/0's"),
            "{what}: {e}"
        );
    }
    let mut touching = hall.clone();
    touching
        .effects
        .extend([opening(x, y), opening(x + 0.2, y)]);
    registry
        .check_hall(&touching, "hall.json")
        .expect("openings that touch");
}

/// A whole-hall supply offset beside per-CRAC offsets for every CRAC sets each CRAC's
/// offset twice (the whole-hall one is their sum's direction): refused, naming the
/// entries. One CRAC short of every one, the two can be told apart and pass.
#[test]
fn a_whole_hall_offset_beside_one_for_every_crac_is_refused() {
    let registry = EffectRegistry::builtin();
    let mut hall = demo_hall();
    assert!(hall.cracs.len() > 1);
    hall.effects
        .push(spec(json!({"kind": "crac_supply_offset"})));
    let ids: Vec<String> = hall.cracs.iter().map(|c| c.id.clone()).collect();
    for id in &ids[..ids.len() - 1] {
        hall.effects
            .push(spec(json!({"kind": "crac_supply_offset", "crac": id})));
    }
    registry
        .check_hall(&hall, "hall.json")
        .expect("one CRAC without its own entry");
    hall.effects.push(spec(
        json!({"kind": "crac_supply_offset", "crac": ids.last().unwrap()}),
    ));
    let last = hall.effects.len() - 1;
    match HallModel::new(&hall, SimConfig::default()) {
        Err(Error::Effect { kind, message }) => {
            assert_eq!(kind, "crac_supply_offset");
            assert!(
                message.starts_with(&format!("effects/{last}: with effects/0 (every CRAC)")),
                "{message}"
            );
            assert!(message.contains("set twice"), "{message}");
        }
        other => panic!("expected Error::Effect, got {other:?}"),
    }
    let e = registry
        .check_hall(&hall, "hall.json")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with(&format!("hall.json: /effects/{last}")), "{e}");
}

/// The y range (m) of the floor strip a `bypass` behind `rack` opens, or the entry's
/// error.
fn strip_y(hall: &Hall, rack: &str) -> Result<[f64; 2], String> {
    let e = from_spec(
        &spec(json!({"kind": "bypass", "behind_rack": rack, "fraction": 0.1})),
        hall,
    )
    .map_err(|e| e.to_string())?;
    let mut mods = SimMods::new(hall.cracs.len());
    e.modify(&[0.1], hall, &mut mods).unwrap();
    let r = mods.supply_openings[0].region;
    Ok([r.min[1], r.max[1]])
}

/// The strip behind a rack ends at a CRAC (or rack) behind the exhaust, as it ends at
/// the wall: no air enters under a solid. A rack whose exhaust touches one has no strip.
#[test]
fn a_strip_behind_a_rack_ends_at_the_solid_behind_it() {
    let strip = strip_y;
    let mut hall = demo_hall();
    // Row A (y 1.8-3.0) exhausts towards -y; a CRAC 0.2 m behind A01 (x 1.8-2.4).
    hall.cracs[0].position_m = [1.8, 0.0, 0.0];
    hall.cracs[0].size_m = [0.9, 1.6, 2.0];
    let near = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
    let got = strip(&hall, "A01").unwrap();
    assert!(near(got, [1.6, 1.8]), "{got:?}");
    let got = strip(&hall, "A05").unwrap();
    assert!(near(got, [1.4, 1.8]), "{got:?}");
    // Touching the rack's back: refused by name.
    hall.cracs[0].size_m = [0.9, 1.8, 2.0];
    let e = strip(&hall, "A01").unwrap_err();
    assert!(
        e.contains("rack `A01` exhausts against CRAC `crac-1`"),
        "{e}"
    );
    assert!(e.contains("behind_rack"), "{e}");
    // Nor is it a diagnosis candidate; nor A02, whose back the CRAC (x 1.8-2.7) also
    // touches; every other rack is.
    assert!(strip(&hall, "A02").is_err());
    let factory = EffectRegistry::builtin();
    let candidates = factory.get("bypass").unwrap().candidates(&hall);
    assert_eq!(candidates.len(), hall.racks.len() - 2);
    let named = |id: &str| {
        candidates
            .iter()
            .any(|c| c.fields["behind_rack"] == json!(id))
    };
    assert!(!named("A01") && !named("A02") && named("A03"));
}

/// A tile behind a rack ends the strip as a solid does: the floor there already
/// delivers the tile's share, so an opening over it would count that air twice (as a
/// `position_m` opening over a tile is refused). A tile at the rack's back leaves none.
#[test]
fn a_strip_behind_a_rack_ends_at_a_tile_behind_it() {
    let strip = |hall: &Hall| strip_y(hall, "A01");
    let mut hall = demo_hall();
    let rack = hall.racks.iter().find(|r| r.id == "A01").unwrap().clone();
    let (x0, back) = (rack.position_m[0], rack.position_m[1]);
    let open = strip(&hall).unwrap();
    assert!(
        (open[1] - back).abs() < 1e-9 && open[0] < back - 0.3,
        "{open:?}"
    );
    // Row A exhausts towards -y: a tile 0.2 m behind A01's back, over its width.
    let mut tile = hall.tiles[0].clone();
    tile.position_m = [x0, back - 0.2 - 0.4];
    tile.size_m = [rack.size_m[0], 0.4];
    hall.tiles.push(tile);
    hall.validate("hall.json").unwrap();
    let got = strip(&hall).unwrap();
    assert!((got[0] - (back - 0.2)).abs() < 1e-9, "{got:?}");
    assert!((got[1] - back).abs() < 1e-9, "{got:?}");
    // At the rack's back: refused by name, and not a diagnosis candidate.
    let last = hall.tiles.len() - 1;
    hall.tiles[last].position_m[1] = back - 0.4;
    let e = strip(&hall).unwrap_err();
    assert!(
        e.contains(&format!(
            "rack `A01` exhausts against tile {last} (/tiles/{last})"
        )),
        "{e}"
    );
    let candidates = EffectRegistry::builtin()
        .get("bypass")
        .unwrap()
        .candidates(&hall);
    assert!(!candidates
        .iter()
        .any(|c| c.fields["behind_rack"] == json!("A01")));
}
