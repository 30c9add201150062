//! The simulator's linear solvers: the multigrid-preconditioned solves agree with the
//! Jacobi-preconditioned reference, the default tolerances stay within a millikelvin of
//! tight solves, and the answer is bit-identical at one and two threads.

#[path = "support/sim_halls.rs"]
mod sim_halls;

use kalibre_dc::hall::Hall;
use kalibre_dc::sim::{
    AirLink, Preconditioner, RackRecirculation, SimConfig, SimMods, Simulator, Solution,
    WallOpening, WallSide,
};
use kalibre_dc::snapshots::OperatingState;
use sim_halls::{contained_hall, demo_hall, hall_a, varied_state};

/// Effects that touch every solver path: opened containment panels (a per-run pressure
/// hierarchy), in-rack recirculation and a forced link (non-local heat couplings).
fn busy_mods(hall: &Hall) -> SimMods {
    let mut m = SimMods::new(hall.cracs.len());
    m.supply_offset_c[0] = -0.5;
    m.wall_openings.push(WallOpening {
        containment: 0,
        sides: vec![WallSide::MinusX],
        open_fraction: 0.3,
    });
    m.rack_recirculation.push(RackRecirculation {
        rack: 3,
        fraction: 0.1,
        z_m: Some([1.0, 1.4]),
    });
    m.air_links.push(AirLink {
        from: kalibre_dc::hall::Aabb {
            min: [4.0, 3.4, 2.4],
            max: [5.0, 3.8, 2.8],
        },
        to: kalibre_dc::hall::Aabb {
            min: [4.0, 0.4, 0.2],
            max: [5.0, 0.8, 0.6],
        },
        flow_m3_s: 0.05,
    });
    m
}

fn run(hall: &Hall, cfg: SimConfig, state: &OperatingState, mods: &SimMods) -> Solution {
    let sim = Simulator::new(hall, cfg).expect("topology");
    let alpha = vec![0.12; hall.server_count()];
    sim.solve_with_mods(state, &alpha, mods).expect("solve")
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn multigrid_agrees_with_jacobi_reference() {
    let cases = [
        (demo_hall(), 0.3, SimMods::new(4)),
        (contained_hall(true), 0.3, busy_mods(&contained_hall(true))),
    ];
    for (hall, cell, mods) in cases {
        let state = varied_state(&hall, 18.0, 0.9, 400.0);
        let tight = SimConfig::default()
            .with_cell_m(cell)
            .with_tolerances(1e-12, 1e-12);
        let mg = run(&hall, tight.clone(), &state, &mods);
        let jac = run(
            &hall,
            tight.with_preconditioner(Preconditioner::Jacobi),
            &state,
            &mods,
        );
        // Far fewer iterations, the same answer.
        assert!(
            mg.pressure_stats.iterations * 5 < jac.pressure_stats.iterations,
            "{}: CG {} (multigrid) vs {} (Jacobi)",
            hall.name,
            mg.pressure_stats.iterations,
            jac.pressure_stats.iterations
        );
        let d = max_diff(mg.sensor_c(), jac.sensor_c());
        assert!(d < 1e-5, "{}: sensors differ by {d:e} C", hall.name);
        let d = max_diff(&mg.server_exhaust_c, &jac.server_exhaust_c);
        assert!(d < 1e-5, "{}: exhausts differ by {d:e} C", hall.name);
        let scale = jac.pressure.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let d = max_diff(&mg.pressure, &jac.pressure);
        assert!(d < 1e-8 * scale, "{}: pressure differs by {d:e}", hall.name);
    }
}

#[test]
fn default_tolerances_are_within_a_millikelvin_of_tight_solves() {
    let cases = [(demo_hall(), 0.2), (hall_a(), 0.4)];
    for (hall, cell) in cases {
        let state = varied_state(&hall, 18.0, 0.9, 300.0);
        let mods = SimMods::new(hall.cracs.len());
        let cfg = SimConfig::default().with_cell_m(cell);
        let default = run(&hall, cfg.clone(), &state, &mods);
        let tight = run(&hall, cfg.with_tolerances(1e-13, 1e-13), &state, &mods);
        let d = max_diff(default.sensor_c(), tight.sensor_c());
        assert!(
            d < 1e-3,
            "{}: sensors {d:e} C from the tight solve",
            hall.name
        );
        let d = max_diff(&default.server_exhaust_c, &tight.server_exhaust_c);
        assert!(
            d < 1e-3,
            "{}: exhausts {d:e} C from the tight solve",
            hall.name
        );
        assert!(default.energy_balance_error().abs() < 1e-6);
    }
}

#[test]
fn same_bits_at_one_and_two_threads() {
    let hall = contained_hall(true);
    let state = varied_state(&hall, 18.0, 0.9, 400.0);
    let mods = busy_mods(&hall);
    // 25,920 cells: the finest level sweeps its two halves in parallel.
    let cfg = SimConfig::default().with_cell_m(0.2);
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool")
            .install(|| run(&hall, cfg.clone(), &state, &mods))
    };
    let (one, two) = (on(1), on(2));
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&one.pressure), bits(&two.pressure));
    assert_eq!(bits(&one.temperature_c), bits(&two.temperature_c));
    assert_eq!(bits(one.sensor_c()), bits(two.sensor_c()));
    assert_eq!(one.pressure_stats, two.pressure_stats);
    assert_eq!(one.heat_stats, two.heat_stats);
}
