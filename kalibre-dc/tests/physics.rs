//! Physics checks of the built-in simulator on halls built in code: energy and mass
//! balance, mirror symmetry, the response to alpha, recirculation and bypass, and the
//! sensitivity of demo readings to halving the cell size.

#[path = "support/sim_halls.rs"]
mod sim_halls;

use kalibre_dc::hall::Hall;
use kalibre_dc::sim::{SimConfig, Simulator, Solution};
use kalibre_dc::snapshots::OperatingState;
use sim_halls::{demo_hall, mirror_x, uniform_state, varied_state};

fn solve(
    hall: &Hall,
    config: SimConfig,
    state: &OperatingState,
    alpha: f64,
) -> (Simulator, Solution) {
    let sim = Simulator::new(hall, config).expect("topology");
    let alpha = vec![alpha; hall.server_count()];
    let sol = sim.solve(state, &alpha, &[]).expect("solve");
    (sim, sol)
}

/// The largest mass imbalance of a fluid cell (m3/s) and the sources' norm it is
/// measured against.
fn worst_cell_imbalance(sim: &Simulator, sol: &Solution) -> (f64, f64) {
    let worst = (sol.mass_imbalance_m3_s(sim.grid()).iter().zip(sim.solid()))
        .filter(|(_, s)| !**s)
        .map(|(v, _)| v.abs())
        .fold(0.0, f64::max);
    let src_norm = sol.source_m3_s.iter().map(|v| v * v).sum::<f64>().sqrt();
    (worst, src_norm)
}

fn mean_of(hall: &Hall, sol: &Solution, prefix: &str) -> f64 {
    let v: Vec<f64> = hall
        .sensors
        .iter()
        .zip(sol.sensor_c())
        .filter(|(s, _)| s.id.starts_with(prefix))
        .map(|(_, t)| *t)
        .collect();
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn energy_balance_within_one_percent() {
    let hall = demo_hall();
    let state = varied_state(&hall, 18.0, 0.9, 400.0);
    let (_, sol) = solve(&hall, SimConfig::default(), &state, 0.12);
    let rho_cp = 1.2 * 1005.0;
    // The issue's form: rho cp Q_supply (T_return - T_supply) = sum P.
    let removed = rho_cp * sol.supply_flow_m3_s * (sol.return_c - sol.supply_c);
    let rel = (removed - sol.power_w) / sol.power_w;
    assert!(
        rel.abs() < 0.01,
        "energy balance off by {:.4} %",
        100.0 * rel
    );
    assert!(
        sol.energy_balance_error().abs() < 1e-4,
        "flux form: {}",
        sol.energy_balance_error()
    );
    assert!((sol.return_flow_m3_s - sol.supply_flow_m3_s).abs() < 1e-6 * sol.supply_flow_m3_s);
}

#[test]
fn mass_balances_per_cell_to_solver_tolerance() {
    let hall = demo_hall();
    let state = varied_state(&hall, 18.0, 0.9, 400.0);
    let (sim, sol) = solve(&hall, SimConfig::default(), &state, 0.12);
    let (worst, src_norm) = worst_cell_imbalance(&sim, &sol);
    // CG stops at a relative residual of 1e-9: no cell can be off by more than that norm.
    assert!(
        worst <= 1e-9 * src_norm * 1.0001,
        "worst cell imbalance {worst:e} m3/s (source norm {src_norm:e})"
    );
    assert!(sol.pressure_stats.rel_residual <= 1e-9);
}

/// The demo hall with its CRACs blowing through their fronts (their supply released
/// along the jet), with its ceiling grilles and without (the CRAC tops return the air):
/// the heat the servers put in leaves with the air, the supply comes back whole, and
/// every cell balances its mass.
#[test]
fn front_supply_along_the_jet_balances_energy_and_mass() {
    let mut front = demo_hall();
    front.tiles.clear();
    for c in &mut front.cracs {
        c.supply = kalibre_dc::hall::SupplyKind::Front;
    }
    let mut bare = front.clone();
    bare.returns.clear();
    for hall in [front, bare] {
        let state = varied_state(&hall, 18.0, 0.9, 400.0);
        let (sim, sol) = solve(&hall, SimConfig::default(), &state, 0.12);
        let rho_cp = 1.2 * 1005.0;
        let removed = rho_cp * sol.supply_flow_m3_s * (sol.return_c - sol.supply_c);
        let rel = (removed - sol.power_w) / sol.power_w;
        let grilles = !hall.returns.is_empty();
        assert!(
            rel.abs() < 0.01,
            "grilles {grilles}: off by {:.4} %",
            100.0 * rel
        );
        assert!(sol.energy_balance_error().abs() < 1e-4, "grilles {grilles}");
        assert!((sol.return_flow_m3_s - sol.supply_flow_m3_s).abs() < 1e-6 * sol.supply_flow_m3_s);
        let (worst, src_norm) = worst_cell_imbalance(&sim, &sol);
        assert!(
            worst <= 1e-9 * src_norm * 1.0001,
            "grilles {grilles}: {worst:e}"
        );
    }
}

#[test]
fn mirrored_hall_gives_mirrored_readings() {
    let hall = demo_hall();
    let state = varied_state(&hall, 18.0, 0.9, 400.0);
    // Tight tolerances: the comparison is of two solves, each exact only to its solver
    // accuracy (the relative residual is poorly scaled in stagnant cells).
    let cfg = SimConfig::default().with_tolerances(1e-12, 1e-13);
    let (_, a) = solve(&hall, cfg.clone(), &state, 0.12);
    let (_, b) = solve(&mirror_x(&hall), cfg, &state, 0.12);
    for ((s, x), y) in hall.sensors.iter().zip(a.sensor_c()).zip(b.sensor_c()) {
        assert!((x - y).abs() < 1e-4, "sensor {}: {x} vs mirrored {y}", s.id);
    }
}

#[test]
fn lower_alpha_gives_a_hotter_hot_aisle() {
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    let (_, hi) = solve(&hall, SimConfig::default(), &state, 0.15);
    let (_, lo) = solve(&hall, SimConfig::default(), &state, 0.10);
    let (h_hi, h_lo) = (mean_of(&hall, &hi, "h-"), mean_of(&hall, &lo, "h-"));
    assert!(
        h_lo > h_hi + 1.0,
        "hot aisle {h_lo} at alpha 0.10 vs {h_hi} at 0.15"
    );
}

#[test]
fn drawing_more_than_the_supply_warms_the_cold_aisle() {
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    // Supply 7.9 m3/s; alpha 0.10 draws 5.8 m3/s, alpha 0.25 draws 14.5 m3/s.
    let (_, under) = solve(&hall, SimConfig::default(), &state, 0.10);
    let (_, over) = solve(&hall, SimConfig::default(), &state, 0.25);
    let (c_under, c_over) = (mean_of(&hall, &under, "c-"), mean_of(&hall, &over, "c-"));
    assert!(c_under < 18.5, "cold aisle with bypass {c_under}");
    assert!(
        c_over > c_under + 1.0,
        "cold aisle {c_over} when servers draw twice the supply vs {c_under}"
    );
}

#[test]
fn supply_above_server_draw_cools_the_hot_aisle() {
    let hall = demo_hall();
    let state_lo = uniform_state(&hall, 18.0, 0.75, 400.0);
    let state_hi = uniform_state(&hall, 18.0, 1.0, 400.0);
    // Server draw 6.9 m3/s; supply 6.6 vs 8.8 m3/s.
    let (_, lo) = solve(&hall, SimConfig::default(), &state_lo, 0.12);
    let (_, hi) = solve(&hall, SimConfig::default(), &state_hi, 0.12);
    let (h_lo, h_hi) = (mean_of(&hall, &lo, "h-"), mean_of(&hall, &hi, "h-"));
    assert!(
        h_hi < h_lo - 0.3,
        "hot aisle {h_hi} with surplus supply vs {h_lo}"
    );
    // The surplus bypasses the servers: the return is cooler than the exhaust.
    let exhaust = hi.server_exhaust_c.iter().sum::<f64>() / hi.server_exhaust_c.len() as f64;
    assert!(
        hi.return_c < exhaust - 0.5,
        "return {} vs mean exhaust {exhaust}",
        hi.return_c
    );
}

#[test]
fn vtk_output_holds_every_field() {
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 400.0);
    let (sim, sol) = solve(&hall, SimConfig::default().with_cell_m(0.4), &state, 0.12);
    let dir = std::env::temp_dir().join(format!("kalibre-vtk-{}", std::process::id()));
    let path = kalibre_dc::sim::write_vtk(&dir, &sim, &sol).expect("vtk");
    let text = std::fs::read_to_string(&path).expect("read back");
    let n = sim.grid().len();
    assert!(text.starts_with("# vtk DataFile Version 3.0"));
    assert!(text.contains(&format!("CELL_DATA {n}")));
    for field in [
        "SCALARS temperature_c",
        "SCALARS pressure",
        "SCALARS solid",
        "VECTORS velocity_m_s",
    ] {
        assert!(text.contains(field), "missing {field}");
    }
    // Header (8 lines) + 3 scalar blocks of 2 + n lines + a vector block of 1 + n lines.
    assert_eq!(text.lines().count(), 8 + 3 * (2 + n) + 1 + n);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// A hall of one row of four racks (one server each, drawing from -y at y 2.4-3.6 m), a
/// tile in front of each, one floor CRAC, a ceiling return behind the row and a cold
/// aisle contained at y 1.4-2.4 m up to 2 m; every sensor a cold-aisle one.
struct RowHall<'a> {
    room_x_m: f64,
    crac_position_m: [f64; 3],
    crac_size_m: [f64; 3],
    rack_x_m: [f64; 4],
    /// Each tile's x and open fraction.
    tiles: [(f64, f64); 4],
    return_x_m: f64,
    aisle_x_m: [f64; 2],
    sensors: &'a [(String, [f64; 3])],
}

impl RowHall<'_> {
    fn hall(&self) -> Hall {
        let list = |items: Vec<String>| items.join(",");
        let v = |p: [f64; 3]| format!("[{},{},{}]", p[0], p[1], p[2]);
        let racks = (self.rack_x_m.iter().enumerate())
            .map(|(i, x)| {
                format!(
                    r#"{{"id":"R{i}","position_m":[{x},2.4,0.0],"size_m":[0.6,1.2,2.0],"inlet":"-y",
                    "units":40,"servers":[{{"id":"S{i}","type":"t","u":1,"height_u":40}}]}}"#
                )
            })
            .collect();
        let tiles = (self.tiles.iter())
            .map(|(x, f)| {
                format!(r#"{{"position_m":[{x},1.6],"size_m":[0.6,0.6],"open_fraction":{f}}}"#)
            })
            .collect();
        let sensors = (self.sensors.iter())
            .map(|(id, p)| format!(r#"{{"id":"{id}","position_m":{},"aisle":"cold"}}"#, v(*p)))
            .collect();
        let json = format!(
            r#"{{"schema":"kalibre.hall/1","name":"row","room":{{"size_m":[{},4.8,3.0]}},
            "server_types":[{{"id":"t","alpha_cfm_per_w":{{"initial":0.12,"min":0.01,"max":3.0}}}}],
            "cracs":[{{"id":"cr","position_m":{},"size_m":{},"rated_flow_m3_s":1.5,"supply":"floor"}}],
            "racks":[{}],"tiles":[{}],
            "returns":[{{"position_m":[{},3.8],"size_m":[1.6,0.4]}}],
            "containment":[{{"kind":"cold_aisle","min_m":[{},1.4,0.0],"max_m":[{},2.4,2.0]}}],
            "sensors":[{}]}}"#,
            self.room_x_m,
            v(self.crac_position_m),
            v(self.crac_size_m),
            list(racks),
            list(tiles),
            self.return_x_m,
            self.aisle_x_m[0],
            self.aisle_x_m[1],
            list(sensors),
        );
        Hall::from_json_str(&json, "row.json").unwrap()
    }
}

/// A sensor within half a cell of a containment panel reads the air on its own side: its
/// interpolation used to blend the cell centres on both sides, degrees apart (1 cm inside
/// a cold aisle's door it read 6 C warmer than the aisle). Its model's fingerprint says
/// so, and has no legacy one: runs journaled before read across the panel.
#[test]
fn a_sensor_beside_a_containment_panel_reads_its_own_side() {
    // The cold aisle: x 1.6-4.0, y 1.4-2.4, up to 2 m; its -x door at x 1.6, its roof at
    // z 2. Each pair: a cell centre and a point 1 cm from the panel, on one side.
    let sensors = [
        ("in", [1.7, 2.0, 1.0]),
        ("in_door", [1.61, 2.0, 1.0]),
        ("out_door", [1.59, 2.0, 1.0]),
        ("out", [1.5, 2.0, 1.0]),
        ("roof_in", [2.9, 2.0, 1.9]),
        ("roof_in_door", [2.9, 2.0, 1.99]),
        ("roof_out_door", [2.9, 2.0, 2.01]),
        ("roof_out", [2.9, 2.0, 2.1]),
    ]
    .map(|(id, p)| (id.to_string(), p));
    let hall = RowHall {
        room_x_m: 6.0,
        crac_position_m: [0.0, 0.8, 0.0],
        crac_size_m: [0.8, 1.6, 2.0],
        rack_x_m: [1.6, 2.2, 2.8, 3.4],
        tiles: [(1.6, 0.25), (2.2, 0.5), (2.8, 0.25), (3.4, 0.4)],
        return_x_m: 2.0,
        aisle_x_m: [1.6, 4.0],
        sensors: &sensors,
    }
    .hall();
    let state = OperatingState {
        label: "t0".into(),
        setpoint_c: vec![18.0],
        fan_speed: vec![0.8],
        power_w: vec![5500.0, 6000.0, 5500.0, 5900.0],
    };
    let (sim, sol) = solve(&hall, SimConfig::default(), &state, 0.12);
    assert_eq!(sim.sensors_beside_panels(), &[1, 2, 5, 6]);
    let t = |id: &str| sol.sensor_c()[sensors.iter().position(|(s, _)| s == id).unwrap()];
    for (near, centre, other_side) in [
        ("in_door", "in", "out"),
        ("out_door", "out", "in"),
        ("roof_in_door", "roof_in", "roof_out"),
        ("roof_out_door", "roof_out", "roof_in"),
    ] {
        let across = (t(centre) - t(other_side)).abs();
        assert!(across > 1.0, "{centre} / {other_side}: {across} C apart");
        assert!(
            (t(near) - t(centre)).abs() < 0.25 * across,
            "{near} {:.2} C: its side's {centre} reads {:.2}, the other side's {other_side} {:.2}",
            t(near),
            t(centre),
            t(other_side)
        );
    }
    let model = kalibre_dc::HallModel::new(&hall, SimConfig::default()).unwrap();
    assert!(kalibre_core::Model::legacy_fingerprints(&model).is_empty());
}

/// A hall symmetric about x = 3.1 m whose racks and cold-aisle containment have their x
/// edges on the 0.2 m grid's cell centres (half-cell ties) reads symmetrically: the
/// containment's planes go outward at a tie, as the racks' cells do. They used to snap one
/// way only, and mirrored sensors read up to 0.65 C apart.
#[test]
fn a_symmetric_hall_at_half_cell_ties_reads_symmetrically() {
    let pairs = [
        ("door", [1.5, 2.0, 1.0]),
        ("in", [2.0, 2.3, 1.5]),
        ("room", [1.2, 1.1, 2.5]),
        ("hot", [2.2, 3.7, 1.5]),
    ];
    let sensors: Vec<(String, [f64; 3])> = pairs
        .iter()
        .flat_map(|(id, p)| {
            [("L", p[0]), ("R", 6.2 - p[0])]
                .map(|(side, x)| (format!("{side}-{id}"), [x, p[1], p[2]]))
        })
        .collect();
    let hall = RowHall {
        room_x_m: 6.2,
        crac_position_m: [2.7, 0.0, 0.0],
        crac_size_m: [0.8, 0.8, 2.0],
        rack_x_m: [1.9, 2.5, 3.1, 3.7],
        tiles: [(1.9, 0.25), (2.5, 0.5), (3.1, 0.5), (3.7, 0.25)],
        return_x_m: 2.3,
        aisle_x_m: [1.9, 4.3],
        sensors: &sensors,
    }
    .hall();
    let grid = kalibre_dc::sim::Grid::new(hall.room.size_m, 0.2);
    assert!(kalibre_dc::sim::containment_side_on_cell_centre(
        &hall, &grid
    ));
    let state = OperatingState {
        label: "t0".into(),
        setpoint_c: vec![18.0],
        fan_speed: vec![0.6],
        power_w: vec![3000.0, 2800.0, 2800.0, 3000.0],
    };
    let (_, sol) = solve(&hall, SimConfig::default(), &state, 0.12);
    let t = sol.sensor_c();
    for (k, (id, _)) in pairs.iter().enumerate() {
        let (l, r) = (t[2 * k], t[2 * k + 1]);
        assert!((l - r).abs() < 1e-6, "{id}: L {l} C, R {r} C");
    }
    // The edge warning names where the cells put the edges: outward at a tie.
    let moved = kalibre_dc::sim::off_grid_edges(&hall, 0.2);
    let first = moved
        .iter()
        .find(|e| e.pointer == "/racks/0/position_m")
        .unwrap();
    assert_eq!((first.given_m, first.placed_m), (1.9, 1.8));
}
