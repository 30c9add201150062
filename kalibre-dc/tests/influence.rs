//! The sensors' influence from the simulator's flow (`Simulator::sensor_influence`)
//! against forward runs: superposition of every server's rise, one server's rise changed
//! at fixed flow, the maximum principle, with and without effects; and the graph's edges
//! built from it.

#[path = "support/sim_halls.rs"]
mod sim_halls;

use kalibre_dc::hall::{Aisle, Hall};
use kalibre_dc::sim::{
    RackRecirculation, SensorInfluence, SimConfig, SimMods, Simulator, Solution,
};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::surrogate::{Adjacency, AdjacencySettings};
use sim_halls::{demo_hall, uniform_state, varied_state};

/// Alpha varying from server to server, so the flow is not symmetric.
fn varied_alpha(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.1 + 0.04 * ((i as f64) * 1.3).cos())
        .collect()
}

/// Every sensor reads the supply plus the influence times the servers' rises (the supply
/// must be one temperature).
fn assert_superposition(sol: &Solution, inf: &SensorInfluence) {
    for (k, row) in inf.per_sensor.iter().enumerate() {
        let warmed: f64 = row
            .iter()
            .zip(sol.server_exhaust_c.iter().zip(&sol.server_intake_c))
            .map(|(g, (exhaust, intake))| g * (exhaust - intake))
            .sum();
        let reading = sol.sensor_c()[k] - sol.supply_c;
        assert!(
            (reading - warmed).abs() < 1e-5,
            "sensor {k}: reads {reading:.6} K over the supply, the influence gives {warmed:.6}"
        );
    }
}

/// The demo hall with its simulator, a state with one setpoint for every CRAC (so the
/// supply is one temperature) and varied power, and alpha varied server by server.
fn demo_run() -> (Hall, Simulator, OperatingState, Vec<f64>) {
    let hall = demo_hall();
    let sim = Simulator::new(&hall, SimConfig::default()).expect("topology");
    let state = varied_state(&hall, 19.0, 0.9, 400.0);
    let alpha = varied_alpha(hall.server_count());
    (hall, sim, state, alpha)
}

#[test]
fn every_sensor_is_the_supply_plus_the_influence_times_the_rises() {
    // The supply is one temperature: the rest of every sensor's reading is what the
    // servers' rises put there.
    let (hall, sim, state, alpha) = demo_run();
    let sol = sim.solve(&state, &alpha, &[]).expect("run");
    let (_, inf) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    assert_eq!(inf.per_sensor.len(), hall.sensors.len());
    assert!(inf.max_rel_residual <= SimConfig::default().heat_tol);
    assert_superposition(&sol, &inf);
}

#[test]
fn sensors_in_the_rooms_corners_get_their_influence() {
    // Stagnant corner air once broke the adjoint's BiCGSTAB down in its first
    // iterations; it now restarts and converges.
    use kalibre_dc::synth::{generate_hall, Preset, SynthOptions};
    let mut hall = generate_hall(&SynthOptions::new(Preset::Demo, 1)).expect("demo hall");
    let state = varied_state(&hall, 19.0, 0.9, 400.0);
    let alpha = varied_alpha(hall.server_count());
    let [lx, ly, lz] = hall.room.size_m;
    let corners = [
        [0.0, 0.0, 0.0],
        [0.05, 0.05, 0.05],
        [lx, 0.0, 0.0],
        [0.0, ly, lz],
        [lx, ly, lz],
        [lx - 0.05, ly - 0.05, 0.05],
    ];
    for (sensor, p) in hall.sensors.iter_mut().zip(corners) {
        sensor.position_m = p;
    }
    hall.validate("demo").expect("corners are in the room");
    let sim = Simulator::new(&hall, SimConfig::default()).expect("topology");
    let sol = sim.solve(&state, &alpha, &[]).expect("run");
    let (_, inf) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    assert!(inf.max_rel_residual <= SimConfig::default().heat_tol);
    assert_superposition(&sol, &inf);
}

#[test]
fn the_influence_sees_the_runs_effects() {
    let (hall, sim, state, alpha) = demo_run();
    // Exhaust drawn back to the intakes inside two racks: transfers without a rise.
    let mut mods = SimMods::new(hall.cracs.len());
    for rack in [2, 17] {
        mods.rack_recirculation.push(RackRecirculation {
            rack,
            fraction: 0.25,
            z_m: None,
        });
    }
    let (sol, inf) = sim
        .sensor_influence_with_mods(&state, &alpha, &mods)
        .expect("influence");
    let (_, plain) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    assert_ne!(inf.per_sensor, plain.per_sensor);
    assert_superposition(&sol, &inf);
}

#[test]
fn one_servers_rise_at_fixed_flow_moves_the_sensors_as_its_column_says() {
    let (hall, sim, state, alpha) = demo_run();
    let base = sim.solve(&state, &alpha, &[]).expect("run");
    let (_, inf) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    // Power up by 10 % and alpha down by as much keeps the server's flow, so the flow
    // field is the same and only its rise grows by 10 %.
    for j in [0, 37, 150, hall.server_count() - 1] {
        let mut st = state.clone();
        let mut a = alpha.clone();
        st.power_w[j] *= 1.1;
        a[j] /= 1.1;
        let run = sim.solve(&st, &a, &[]).expect("run");
        let rise = base.server_exhaust_c[j] - base.server_intake_c[j];
        for k in 0..hall.sensors.len() {
            let moved = run.sensor_c()[k] - base.sensor_c()[k];
            let predicted = inf.per_sensor[k][j] * 0.1 * rise;
            assert!(
                (moved - predicted).abs() < 1e-6 + 1e-4 * predicted.abs(),
                "server {j}, sensor {k}: moved {moved:.3e} K, the influence says {predicted:.3e}"
            );
        }
    }
}

#[test]
fn influence_is_non_negative_and_an_idle_server_has_none() {
    let hall = demo_hall();
    let sim = Simulator::new(&hall, SimConfig::default()).expect("topology");
    let mut state = uniform_state(&hall, 18.0, 1.0, 350.0);
    state.power_w[5] = 0.0;
    let alpha = varied_alpha(hall.server_count());
    let (_, inf) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    for (k, row) in inf.per_sensor.iter().enumerate() {
        // Upwind advection-diffusion keeps a maximum principle: a warmer exhaust never
        // cools a sensor.
        let low = row.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(low > -1e-9, "sensor {k}: influence {low:.3e} < 0");
        assert_eq!(row[5], 0.0, "sensor {k}: the idle server has influence");
    }
    // Every hot-aisle sensor is reached by some exhaust.
    for (k, s) in hall.sensors.iter().enumerate() {
        if s.aisle == Aisle::Hot {
            let top = inf.per_sensor[k].iter().copied().fold(0.0, f64::max);
            assert!(
                top > 1e-3,
                "hot-aisle sensor {} is reached by no server",
                s.id
            );
        }
    }
}

#[test]
fn influence_edges_keep_the_graphs_shape_and_refuse_bad_input() {
    let hall = demo_hall();
    let sim = Simulator::new(&hall, SimConfig::default()).expect("topology");
    let state = uniform_state(&hall, 18.0, 1.0, 350.0);
    let alpha = varied_alpha(hall.server_count());
    let (_, inf) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    let geometric = Adjacency::from_hall(&hall, &AdjacencySettings::default()).expect("graph");
    let adj = geometric
        .clone()
        .with_server_influence(&inf.per_sensor, &state.power_w, 0.01)
        .expect("edges");
    assert_eq!(adj.cs, geometric.cs, "the CRAC edges stay geometric");
    for (k, s) in hall.sensors.iter().enumerate() {
        let row = adj.ss.range(k);
        if s.aisle == Aisle::Hot {
            let sum: f64 = adj.ss.val[row.clone()].iter().sum();
            assert!((sum - 1.0).abs() < 1e-12, "row {k} sums to {sum}");
            // The strongest edge is the server the flow carries most of to the sensor.
            let best = (0..hall.server_count())
                .max_by(|&a, &b| {
                    (inf.per_sensor[k][a] / state.power_w[a])
                        .total_cmp(&(inf.per_sensor[k][b] / state.power_w[b]))
                })
                .expect("servers");
            let strongest = row
                .clone()
                .max_by(|&a, &b| adj.ss.val[a].total_cmp(&adj.ss.val[b]))
                .map(|e| adj.ss.col[e] as usize);
            assert_eq!(strongest, Some(best), "row {k}");
        } else {
            assert!(row.is_empty(), "cold-aisle sensor {k} got server edges");
        }
    }
    let short = &inf.per_sensor[..3];
    assert!(geometric
        .clone()
        .with_server_influence(short, &state.power_w, 0.01)
        .is_err());
    let mut nan = inf.per_sensor.clone();
    let hot = (0..hall.sensors.len())
        .find(|&k| hall.sensors[k].aisle == Aisle::Hot)
        .expect("a hot-aisle sensor");
    nan[hot][2] = f64::NAN;
    let e = geometric
        .clone()
        .with_server_influence(&nan, &state.power_w, 0.01)
        .expect_err("NaN influence");
    assert!(e.to_string().contains("not finite"), "{e}");
    let e = geometric
        .with_server_influence(&inf.per_sensor, &state.power_w, 1.5)
        .expect_err("cut above 1");
    assert!(e.to_string().contains("influence_cut"), "{e}");
}

#[test]
fn the_graph_takes_influence_edges_only_from_the_built_in_flow() {
    use kalibre_dc::calibration::{HallCalibrationSettings, SERVER_INFLUENCE_CUT};
    use kalibre_dc::calibration_model::hall_surrogate;
    use kalibre_dc::ParamLayout;

    let hall = demo_hall();
    let layout = ParamLayout::new(&hall, &[]).expect("layout");
    let settings = HallCalibrationSettings {
        server_influence: Some(SERVER_INFLUENCE_CUT),
        ..HallCalibrationSettings::default()
    };
    // Another model (OpenFOAM, a command) gives no flow: refused by the setting's name.
    let e = hall_surrogate(&hall, &layout, &settings, None).expect_err("no flow");
    assert!(e.to_string().contains("server_influence"), "{e}");
    let sim = Simulator::new(&hall, SimConfig::default()).expect("topology");
    let state = uniform_state(&hall, 18.0, 1.0, 350.0);
    let graph = hall_surrogate(&hall, &layout, &settings, Some((&sim, &state))).expect("graph");
    let geometric = Adjacency::from_hall(&hall, &AdjacencySettings::default()).expect("graph");
    assert_eq!(graph.adjacency().cs, geometric.cs);
    assert_ne!(graph.adjacency().ss, geometric.ss);
    // A cold-aisle sensor has no heating block, so edges there are refused.
    let cold = (0..hall.sensors.len())
        .find(|&k| hall.sensors[k].aisle == Aisle::Cold)
        .expect("a cold-aisle sensor");
    let mut bad = graph.adjacency().clone();
    let mut rows: Vec<Vec<(u32, f64)>> = (0..bad.ss.rows())
        .map(|k| {
            bad.ss
                .range(k)
                .map(|e| (bad.ss.col[e], bad.ss.val[e]))
                .collect()
        })
        .collect();
    rows[cold] = vec![(0, 1.0)];
    bad.ss.row_ptr = vec![0];
    bad.ss.col.clear();
    bad.ss.val.clear();
    for row in rows {
        for (c, v) in row {
            bad.ss.col.push(c);
            bad.ss.val.push(v);
        }
        bad.ss.row_ptr.push(bad.ss.col.len());
    }
    let e = graph.with_adjacency(bad).expect_err("cold-aisle edges");
    assert!(e.to_string().contains("cold-aisle"), "{e}");
}

#[test]
fn the_racks_shares_add_up_to_each_sensors_warming() {
    use kalibre_dc::sim::{rack_heat, write_rack_heat};

    let (hall, sim, state, alpha) = demo_run();
    let (sol, inf) = sim
        .sensor_influence(&state, &alpha, &[])
        .expect("influence");
    let all = rack_heat(&hall, "t0", &sol, &inf, 0.0).expect("every rack");
    for (k, sensor) in hall.sensors.iter().enumerate() {
        let rows: Vec<_> = all.iter().filter(|r| r.sensor == sensor.id).collect();
        let warming = sol.sensor_c()[k] - sol.supply_c;
        if rows.is_empty() {
            assert!(
                warming < 0.01 + 1e-5,
                "{}: warmed {warming} K, no rows",
                sensor.id
            );
            continue;
        }
        let total: f64 = rows.iter().map(|r| r.warming_k).sum();
        assert!(
            (total - warming).abs() < 1e-5,
            "{}: {total} vs {warming}",
            sensor.id
        );
        let shares: f64 = rows.iter().map(|r| r.share).sum();
        assert!(
            (shares - 1.0).abs() < 1e-9,
            "{}: shares sum to {shares}",
            sensor.id
        );
        assert!(rows.windows(2).all(|w| w[0].warming_k >= w[1].warming_k));
    }
    // The cut keeps the large shares only, and the CSV has one line per row.
    let big = rack_heat(&hall, "t0", &sol, &inf, 0.2).expect("large shares");
    assert!(!big.is_empty() && big.len() < all.len());
    assert!(big.iter().all(|r| r.share >= 0.2));
    let csv = write_rack_heat(&big);
    assert!(csv.starts_with("snapshot,sensor,rack,warming_k,share\n"));
    assert_eq!(csv.lines().count(), 1 + big.len());
    assert!(rack_heat(&hall, "t0", &sol, &inf, 1.5).is_err());
    let mut short = inf.clone();
    short.per_sensor.pop();
    assert!(rack_heat(&hall, "t0", &sol, &short, 0.0).is_err());
}
