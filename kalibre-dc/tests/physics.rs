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
    // The form: rho cp Q_supply (T_return - T_supply) = sum P.
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
