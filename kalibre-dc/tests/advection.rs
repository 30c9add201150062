//! The TVD advection option of the simulator (deferred correction on the upwind
//! operator): boundedness, energy balance, sharper fronts than upwind on an oblique step,
//! and upwind unchanged when the option is off. Coarse grids keep each test short in
//! debug builds.

#[path = "support/sim_halls.rs"]
mod sim_halls;

use kalibre_dc::hall::{CalibrateSpec, Crac, Hall, ReturnGrille, Room, SupplyKind};
use kalibre_dc::sim::{Advection, FrontSupply, SimConfig, Simulator, Solution};
use kalibre_dc::snapshots::OperatingState;
use sim_halls::{demo_hall, hall_a, uniform_state, varied_state};

const TVD: [Advection; 2] = [Advection::VanLeer, Advection::Minmod];

fn solve(hall: &Hall, config: SimConfig, state: &OperatingState) -> Solution {
    let sim = Simulator::new(hall, config).expect("topology");
    let alpha = vec![0.12; hall.server_count()];
    sim.solve(state, &alpha, &[]).expect("solve")
}

/// Fluid cell temperatures lie within `[min supply, max exhaust]` (to solver tolerance).
fn assert_bounded(sol: &Solution, state: &OperatingState, what: &str) {
    let lo = state.setpoint_c.iter().copied().fold(f64::MAX, f64::min);
    let hi = sol
        .server_exhaust_c
        .iter()
        .copied()
        .fold(lo, f64::max)
        .max(state.setpoint_c.iter().copied().fold(f64::MIN, f64::max));
    let tol = 1e-6 * (hi - lo).max(1.0);
    let mut bad = 0;
    let (mut tmin, mut tmax) = (f64::MAX, f64::MIN);
    for t in sol.temperature_c.iter().filter(|t| t.is_finite()) {
        tmin = tmin.min(*t);
        tmax = tmax.max(*t);
        if *t < lo - tol || *t > hi + tol {
            bad += 1;
        }
    }
    assert_eq!(
        bad, 0,
        "{what}: cells outside [{lo:.4}, {hi:.4}] C: field spans [{tmin:.4}, {tmax:.4}]"
    );
}

#[test]
fn tvd_fields_stay_bounded_and_conserve_energy() {
    // An open demo hall (recirculation round the row ends) and a contained hall-a (walls,
    // leaking panels), coarse grids.
    let cases = [
        ("demo", demo_hall(), 0.3, 400.0),
        ("hall-a", hall_a(), 0.4, 250.0),
    ];
    for (name, hall, cell, power) in cases {
        let state = varied_state(&hall, 18.0, 0.9, power);
        let up = solve(&hall, SimConfig::default().with_cell_m(cell), &state);
        assert_bounded(&up, &state, &format!("{name} upwind"));
        for scheme in TVD {
            let cfg = SimConfig::default()
                .with_cell_m(cell)
                .with_advection(scheme);
            let sol = solve(&hall, cfg, &state);
            let what = format!("{name} {scheme:?}");
            assert!(
                sol.advection_stats.passes >= 1,
                "{what}: no correction pass"
            );
            assert_bounded(&sol, &state, &what);
            let err = sol.energy_balance_error();
            assert!(err.abs() < 0.01, "{what}: energy balance off by {err:e}");
            // The issue's form: rho cp Q_supply (T_return - T_supply) = sum P.
            let removed = 1.2 * 1005.0 * sol.supply_flow_m3_s * (sol.return_c - sol.supply_c);
            let rel = (removed - sol.power_w) / sol.power_w;
            assert!(rel.abs() < 0.01, "{what}: energy balance off by {rel:e}");
            // The scheme changes the field (else the option would do nothing).
            let moved = up
                .sensor_c()
                .iter()
                .zip(sol.sensor_c())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(moved > 1e-3, "{what}: sensors moved only {moved:e} C");
        }
    }
}

/// An empty 6 x 6 x 1 m room: two front-supply CRACs side by side on the x = 0 wall (15 C
/// below y = 1.5 m, 25 C above), one ceiling return in the far corner, so the flow turns
/// through 90 degrees and the interface between the two streams crosses the grid
/// obliquely. Without diffusion its exact profile is a step.
fn step_room() -> Hall {
    let crac = |id: &str, y: f64| Crac {
        id: id.into(),
        position_m: [0.0, y, 0.0],
        size_m: [0.4, 1.5, 1.0],
        rated_flow_m3_s: 1.0,
        supply: SupplyKind::Front,
        extra: None,
    };
    Hall {
        schema: "kalibre.hall/1".into(),
        name: "oblique-step".into(),
        room: Room {
            size_m: [6.0, 6.0, 1.0],
            extra: None,
        },
        server_types: vec![],
        cracs: vec![crac("cold", 0.0), crac("warm", 1.5)],
        tiles: vec![],
        returns: vec![ReturnGrille {
            position_m: [4.5, 4.5],
            size_m: [1.5, 1.5],
            extra: None,
        }],
        racks: vec![],
        containment: vec![],
        sensors: vec![],
        calibrate: CalibrateSpec::default(),
        effects: vec![],
        extra: None,
    }
}

/// Mixing-zone area (m2) of the mid-height layer: cells whose normalised temperature is
/// strictly between 0.1 and 0.9 (the interface's smeared width times its length).
fn mixing_area(sim_grid: &kalibre_dc::sim::Grid, sol: &Solution, lo: f64, hi: f64) -> f64 {
    let k = sim_grid.n[2] / 2;
    let mut cells = 0usize;
    for j in 0..sim_grid.n[1] {
        for i in 0..sim_grid.n[0] {
            let t = sol.temperature_c[sim_grid.idx(i, j, k)];
            if !t.is_finite() {
                continue;
            }
            let th = (t - lo) / (hi - lo);
            if th > 0.1 && th < 0.9 {
                cells += 1;
            }
        }
    }
    cells as f64 * sim_grid.d[0] * sim_grid.d[1]
}

#[test]
fn oblique_step_is_sharper_with_tvd_than_upwind() {
    let hall = step_room();
    let state = OperatingState {
        label: "step".into(),
        setpoint_c: vec![15.0, 25.0],
        fan_speed: vec![1.0, 1.0],
        power_w: vec![],
    };
    let run = |scheme: Advection| {
        // Pure advection: the smearing is the scheme's own.
        // The streams enter at the CRACs' faces (not along their jets, which would
        // release them all the way across): the step starts at the wall.
        let cfg = SimConfig::default()
            .with_cell_m(0.1)
            .with_diffusivity_m2_s(0.0)
            .with_advection(scheme)
            .with_advection_outer(100, 1e-6)
            .with_front_supply(FrontSupply::Face);
        let sim = Simulator::new(&hall, cfg).expect("topology");
        let sol = sim.solve(&state, &[], &[]).expect("solve");
        let area = mixing_area(sim.grid(), &sol, 15.0, 25.0);
        (sol, area)
    };
    let (up, up_area) = run(Advection::Upwind);
    assert_bounded(&up, &state, "step upwind");
    // The interface runs about 6 m through the room; upwind smears it over several cells.
    assert!(up_area > 0.5, "upwind mixing zone only {up_area} m2");
    for scheme in TVD {
        let (sol, area) = run(scheme);
        let what = format!("step {scheme:?} {:?}", sol.advection_stats);
        assert_bounded(&sol, &state, &what);
        eprintln!("{what}: mixing zone {area:.3} m2, upwind {up_area:.3} m2");
        assert!(
            area < 0.6 * up_area,
            "{what}: mixing zone {area:.3} m2 against upwind {up_area:.3} m2"
        );
    }
}

#[test]
fn upwind_option_is_the_unchanged_default() {
    let hall = demo_hall();
    let state = varied_state(&hall, 18.0, 0.9, 400.0);
    // Old configuration files have no advection fields, and a default configuration
    // serialises without them (model fingerprints stay as they were).
    let old = r#"{"cell_m":0.3,"diffusivity_m2_s":0.01,"containment_leak_fraction":0.02,
        "pressure_tol":1e-9,"heat_tol":1e-9,"max_iterations":20000,
        "air_density_kg_m3":1.2,"air_cp_j_kg_k":1005.0}"#;
    let parsed: SimConfig = serde_json::from_str(old).expect("old config parses");
    assert_eq!(parsed, SimConfig::default().with_cell_m(0.3));
    assert_eq!(parsed.advection, Advection::Upwind);
    let json = serde_json::to_string(&SimConfig::default()).expect("serialise");
    assert!(!json.contains("advection"), "{json}");
    let tvd: SimConfig = serde_json::from_str(
        &serde_json::to_string(&SimConfig::default().with_advection(Advection::VanLeer))
            .expect("serialise"),
    )
    .expect("round trip");
    assert_eq!(tvd.advection, Advection::VanLeer);

    let a = solve(&hall, parsed.clone(), &state);
    let b = solve(
        &hall,
        parsed
            .with_advection(Advection::Upwind)
            .with_advection_outer(50, 1e-6),
        &state,
    );
    assert_eq!(a.advection_stats.passes, 0);
    assert_eq!(b.advection_stats.passes, 0);
    assert_eq!(a.heat_stats, b.heat_stats);
    // Bit-identical fields (NaN in solids compares by bits).
    assert!(a
        .temperature_c
        .iter()
        .zip(&b.temperature_c)
        .all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn uniform_temperature_gets_no_correction() {
    // All supply at one temperature and no heat: the field is uniform, every limited
    // difference vanishes, and TVD returns the upwind field after one pass.
    let hall = demo_hall();
    let state = uniform_state(&hall, 18.0, 0.9, 0.0);
    let cfg = SimConfig::default().with_cell_m(0.3);
    let up = solve(&hall, cfg.clone(), &state);
    for scheme in TVD {
        let sol = solve(&hall, cfg.clone().with_advection(scheme), &state);
        assert_eq!(sol.advection_stats.passes, 1, "{scheme:?}");
        let dev = up
            .temperature_c
            .iter()
            .zip(&sol.temperature_c)
            .filter(|(a, _)| a.is_finite())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(dev < 1e-6, "{scheme:?}: moved {dev:e} C");
        assert!(sol.advection_stats.last_change_c < 1e-6);
    }
}

#[test]
fn bad_pass_settings_are_rejected() {
    let hall = demo_hall();
    for cfg in [
        SimConfig::default().with_advection_outer(0, 1e-3),
        SimConfig::default().with_advection_outer(101, 1e-3),
        SimConfig::default().with_advection_outer(10, 0.0),
        SimConfig::default().with_advection_outer(10, f64::NAN),
    ] {
        let err = Simulator::new(&hall, cfg)
            .expect_err("rejected")
            .to_string();
        assert!(err.contains("advection_"), "{err}");
    }
    let bad: Result<SimConfig, _> = serde_json::from_str(
        r#"{"cell_m":0.2,"diffusivity_m2_s":0.01,"containment_leak_fraction":0.02,
        "pressure_tol":1e-9,"heat_tol":1e-9,"max_iterations":20000,
        "air_density_kg_m3":1.2,"air_cp_j_kg_k":1005.0,"advection":"central"}"#,
    );
    assert!(bad.is_err());
}
