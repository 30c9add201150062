//! Tile jets (`sim::jets`) and the diagnosis's model-form uncertainty built on them: the
//! links release exactly the tiles' supply, inside the room and above their tiles, and
//! the uncertainty they add does not hide a clear effect.

use kalibre_dc::diagnosis::{diagnose_hall, EffectSolver, HallDiagnosisSettings};
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::SupplyKind;
use kalibre_dc::sim::jets::draw_matched_links;
use kalibre_dc::sim::{tile_flows_m3_s, Simulator};
use kalibre_dc::HallModel;

#[path = "support/demo_offset.rs"]
mod demo_offset;
use demo_offset::demo;

#[test]
fn jets_release_each_tiles_supply_once_inside_the_room() {
    let (s, params) = demo();
    let model = HallModel::new(&s.hall, Default::default()).unwrap();
    let alpha = model.layout().alpha_per_server(&params);
    let hall = &s.hall;
    for snap in &s.snapshots {
        let state = &snap.state;
        let supply_m3_s: f64 = hall
            .cracs
            .iter()
            .zip(&state.fan_speed)
            .map(|(c, f)| c.rated_flow_m3_s * f)
            .sum();
        let tiles = tile_flows_m3_s(hall, state, 0.0);
        let total: f64 = tiles.iter().sum();
        assert!((total - supply_m3_s).abs() < 1e-12 * supply_m3_s);
        let links = draw_matched_links(hall, state, &alpha, 0.0, 0.0);
        let released: f64 = links.iter().map(|l| l.flow_m3_s).sum();
        assert!(
            (released - supply_m3_s).abs() < 1e-9 * supply_m3_s,
            "{released} of {supply_m3_s} m3/s"
        );
        for (t, flow) in hall.tiles.iter().zip(&tiles) {
            // Each tile's links start at its own floor box, and release its share.
            let own: f64 = links
                .iter()
                .filter(|l| l.from.min[0] == t.position_m[0] && l.from.min[1] == t.position_m[1])
                .map(|l| l.flow_m3_s)
                .sum();
            assert!((own - flow).abs() < 1e-9 * flow, "{own} vs {flow}");
        }
        for l in &links {
            assert!(l.flow_m3_s > 0.0);
            for k in 0..3 {
                assert!(l.to.min[k] >= 0.0 && l.to.max[k] <= hall.room.size_m[k] + 1e-9);
                assert!(l.to.min[k] < l.to.max[k]);
            }
            // Released straight above the tile it comes from.
            assert_eq!((l.to.min[0], l.to.min[1]), (l.from.min[0], l.from.min[1]));
            assert!(l.to.min[2] >= l.from.min[2]);
        }
    }
}

#[test]
fn tiles_deliver_what_front_supply_and_openings_leave() {
    // As the simulator splits the supply: front-supply CRACs blow through their fronts,
    // and openings (bypass effects) take their share of every CRAC's flow.
    let (s, _) = demo();
    let mut hall = s.hall.clone();
    hall.cracs[0].supply = SupplyKind::Front;
    let state = &s.snapshots[0].state;
    let flows: Vec<f64> = hall
        .cracs
        .iter()
        .zip(&state.fan_speed)
        .map(|(c, f)| c.rated_flow_m3_s * f)
        .collect();
    let supply_m3_s: f64 = flows.iter().sum();
    let opening_share = 0.1;
    let tiles: f64 = tile_flows_m3_s(&hall, state, opening_share).iter().sum();
    let fronts = (1.0 - opening_share) * flows[0];
    let openings = opening_share * supply_m3_s;
    assert!(
        (tiles + fronts + openings - supply_m3_s).abs() < 1e-12 * supply_m3_s,
        "tiles {tiles} + fronts {fronts} + openings {openings} vs supply {supply_m3_s} m3/s"
    );
    assert!(tiles < (1.0 - opening_share) * supply_m3_s - 0.1);
}

#[test]
fn the_model_form_uncertainty_keeps_a_clear_offset() {
    let (s, params) = demo();
    let settings = HallDiagnosisSettings {
        model_form: true,
        ..HallDiagnosisSettings::default()
    };
    let with = diagnose_hall(
        &s.hall,
        &s.snapshots,
        &params,
        &EffectRegistry::builtin(),
        &settings,
    )
    .unwrap();
    let top = with.diagnosis.significant().next().map(|h| h.name.as_str());
    assert_eq!(top, Some("crac_supply_offset"), "{:#?}", with.diagnosis);
    // The uncertainty is there: the variant reads otherwise than the model.
    let sim = Simulator::new(&s.hall, Default::default()).unwrap();
    let variants = sim.model_form_variants().unwrap();
    assert_eq!(variants.len(), 1);
    let model = HallModel::new(&s.hall, Default::default()).unwrap();
    let alpha = model.layout().alpha_per_server(&params);
    let state = &s.snapshots[0].state;
    let base = EffectSolver::solve(&sim, state, &alpha, &[]).unwrap();
    let jets = variants[0].solve(state, &alpha, &[]).unwrap();
    let moved = base
        .iter()
        .zip(&jets)
        .map(|(b, j)| (j - b).abs())
        .fold(0.0, f64::max);
    assert!(moved.is_finite() && moved > 0.1, "largest change {moved} C");
}

/// A `front` CRAC against the x = 0 wall of a long room: where it stands along the wall,
/// its air leaves through the face opposite the wall, never through an end face (which
/// faces more of the room), and enters along its jet: in front of its +x face, from the
/// face to the wall across the room, in equal parts along the way.
#[test]
fn a_front_crac_blows_away_from_its_wall_wherever_it_stands_along_it() {
    use kalibre_dc::hall::Hall;
    use kalibre_dc::snapshots::OperatingState;
    for y_m in [0.6, 5.0, 9.4] {
        let text = format!(
            r#"{{"schema": "kalibre.hall/1", "name": "long", "room": {{"size_m": [4.0, 12.0, 3.0]}},
            "server_types": [{{"id": "t", "alpha_cfm_per_w": {{"initial": 0.12, "min": 0.01, "max": 3.0}}}}],
            "cracs": [{{"id": "k", "position_m": [0.0, {y_m}, 0.0], "size_m": [0.8, 2.0, 2.0],
                        "rated_flow_m3_s": 2.0, "supply": "front"}}],
            "racks": [{{"id": "R", "position_m": [2.4, 3.0, 0.0], "size_m": [0.6, 1.0, 2.0], "inlet": "-x",
                        "units": 42, "servers": [{{"id": "S", "type": "t", "u": 1, "height_u": 42}}]}}],
            "sensors": [{{"id": "s", "position_m": [2.0, 6.0, 1.0], "aisle": "cold"}}]}}"#
        );
        let hall = Hall::from_json_str(&text, "long.json").unwrap();
        let sim = Simulator::new(&hall, Default::default()).unwrap();
        let state = OperatingState {
            label: "t0".into(),
            setpoint_c: vec![18.0],
            fan_speed: vec![0.5],
            power_w: vec![3000.0],
        };
        let sol = sim.solve(&state, &[0.12], &[]).unwrap();
        let grid = sim.grid();
        let cell = grid.d[0];
        let (mut ahead, mut elsewhere) = (0.0, 0.0);
        let mut along_x = vec![0.0; grid.n[0]];
        for (c, &q) in sol.source_m3_s.iter().enumerate() {
            let [x, y, z] = grid.cell_centre(c);
            // Supply cells: below the CRAC's top, not the rack's exhaust (y 3-4).
            if q <= 0.0 || z > 2.0 || (y > 3.0 - cell && y < 4.0 + cell && x > 2.4) {
                continue;
            }
            if x > 0.8 && y > y_m && y < y_m + 2.0 {
                ahead += q;
                along_x[grid.ijk(c)[0]] += q;
            } else {
                elsewhere += q;
            }
        }
        assert!(
            (ahead - 1.0).abs() < 1e-9,
            "y {y_m}: {ahead} m3/s in front of +x"
        );
        assert_eq!(
            elsewhere, 0.0,
            "y {y_m}: {elsewhere} m3/s through an end face"
        );
        // The rack (y 3-4) is beside every placement's jet, so each path runs to the
        // wall at x = 4 m: from the first cell beyond the face, every cell column gets
        // the same share.
        let first = (0.8 / cell).round() as usize;
        let shares = &along_x[first..];
        assert!(
            shares
                .iter()
                .all(|q| (q - 1.0 / shares.len() as f64).abs() < 1e-9),
            "y {y_m}: {along_x:?}"
        );
    }
}
