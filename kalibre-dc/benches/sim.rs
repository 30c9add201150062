//! Simulator benchmark (harness = false): prints cells, iterations, seconds and peak
//! memory for a demo-sized and a hall-a-sized hall over grid sizes (multigrid, plus the
//! Jacobi reference at the default grid), then the realism
//! check against the OpenFOAM development datasets.
//!
//! `cargo bench -p kalibre-dc --bench sim` (each case runs in a child process so that its
//! peak memory is its own). `-- --quick` runs fewer cases; `-- --realism` only the
//! OpenFOAM comparison.

#[path = "../tests/support/sim_halls.rs"]
mod sim_halls;

use std::collections::BTreeMap;
use std::process::Command;
use std::time::Instant;

use kalibre_dc::effects::from_spec;
use kalibre_dc::hall::{EffectSpec, Hall};
use kalibre_dc::sim::{Preconditioner, SimConfig, Simulator};
use kalibre_dc::snapshots::OperatingState;
use serde_json::Value;

const CASE_ENV: &str = "KALIBRE_SIM_BENCH_CASE";

fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// Runs one case in this process and prints one tab-separated line.
fn run_case(spec: &str) {
    let mut it = spec.split(':');
    let name = it.next().unwrap_or("demo");
    let cell: f64 = it.next().and_then(|v| v.parse().ok()).unwrap_or(0.2);
    let reps: usize = it.next().and_then(|v| v.parse().ok()).unwrap_or(5);
    let pc = match it.next() {
        Some("jacobi") => Preconditioner::Jacobi,
        _ => Preconditioner::Multigrid,
    };
    let (hall, power) = match name {
        "hall-a" => (sim_halls::hall_a(), 250.0),
        _ => (sim_halls::demo_hall(), 400.0),
    };
    let t0 = Instant::now();
    let cfg = SimConfig::default()
        .with_cell_m(cell)
        .with_preconditioner(pc);
    let sim = Simulator::new(&hall, cfg).expect("topology");
    let setup_s = t0.elapsed().as_secs_f64();
    let state = sim_halls::varied_state(&hall, 18.0, 0.9, power);
    let alpha = vec![0.12; hall.server_count()];
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..reps {
        let t = Instant::now();
        let sol = sim.solve(&state, &alpha, &[]).expect("solve");
        times.push(t.elapsed().as_secs_f64());
        last = Some(sol);
    }
    times.sort_by(|a, b| a.total_cmp(b));
    let sol = last.expect("at least one rep");
    println!(
        "{name}\t{cell}\t{}\t{}\t{}\t{}\t{}\t{}\t{:.4}\t{:.4}\t{:.1}\t{:.2e}",
        if pc == Preconditioner::Jacobi {
            "Jacobi"
        } else {
            "multigrid"
        },
        sim.grid().len(),
        sim.fluid_cells(),
        hall.server_count(),
        sol.pressure_stats.iterations,
        sol.heat_stats.iterations,
        times[times.len() / 2],
        setup_s,
        peak_rss_mb(),
        sol.energy_balance_error(),
    );
}

fn perf_table(quick: bool) {
    let mut cases: Vec<String> = Vec::new();
    let demo: &[f64] = if quick {
        &[0.4, 0.2]
    } else {
        &[0.4, 0.3, 0.2, 0.15, 0.1]
    };
    let hall_a: &[f64] = if quick {
        &[0.4, 0.2]
    } else {
        &[0.5, 0.4, 0.3, 0.25, 0.2]
    };
    for c in demo {
        cases.push(format!("demo:{c}:7"));
    }
    for c in hall_a {
        cases.push(format!("hall-a:{c}:5"));
    }
    // The Jacobi reference at the default grid: the solver before multigrid.
    cases.push("demo:0.2:3:jacobi".into());
    cases.push("hall-a:0.2:3:jacobi".into());
    let exe = std::env::current_exe().expect("current exe");
    println!("| hall | cell m | preconditioner | cells | fluid | servers | CG iter | BiCGSTAB iter | solve s (median) | setup s | peak MB | energy err |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for case in cases {
        let out = Command::new(&exe)
            .env(CASE_ENV, &case)
            .output()
            .expect("run case");
        let line = String::from_utf8_lossy(&out.stdout);
        let line = line.trim();
        if !out.status.success() || line.is_empty() {
            println!(
                "| {case} | failed: {} |",
                String::from_utf8_lossy(&out.stderr).trim()
            );
            continue;
        }
        println!("| {} |", line.replace('\t', " | "));
    }
}

/// Operating states from a `snapshots.csv` (parsed here so the bench needs no reader).
fn states(hall: &Hall, csv: &str) -> Vec<OperatingState> {
    let mut by: BTreeMap<String, OperatingState> = BTreeMap::new();
    let crac_ix = |id: &str| hall.cracs.iter().position(|c| c.id == id);
    let srv: Vec<String> = hall.servers().map(|s| s.server.id.clone()).collect();
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 4 {
            continue;
        }
        let v: f64 = f[3].trim().parse().expect("value");
        let st = by
            .entry(f[0].to_string())
            .or_insert_with(|| OperatingState {
                label: f[0].to_string(),
                setpoint_c: vec![0.0; hall.cracs.len()],
                fan_speed: vec![0.0; hall.cracs.len()],
                power_w: vec![0.0; srv.len()],
            });
        match f[1] {
            "setpoint_c" => st.setpoint_c[crac_ix(f[2]).expect("crac")] = v,
            "fan_speed" => st.fan_speed[crac_ix(f[2]).expect("crac")] = v,
            "power_w" => st.power_w[srv.iter().position(|s| s == f[2]).expect("server")] = v,
            _ => {}
        }
    }
    by.into_values().collect()
}

fn realism() {
    let root = std::path::Path::new("/work/shared/data/openfoam");
    let load = |d: &str| -> (Hall, Vec<OperatingState>, Value) {
        let dir = root.join(d);
        let hall: Hall =
            serde_json::from_str(&std::fs::read_to_string(dir.join("hall.json")).expect("hall"))
                .expect("hall json");
        let st = states(
            &hall,
            &std::fs::read_to_string(dir.join("snapshots.csv")).expect("csv"),
        );
        let truth: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).expect("truth"))
                .expect("truth json");
        (hall, st, truth)
    };
    let (hall, states, truth) = load("of-dev-clean");
    let alpha: Vec<f64> = hall
        .servers()
        .map(|s| {
            truth["alpha_true_cfm_per_w"][&s.server.server_type]
                .as_f64()
                .expect("alpha")
        })
        .collect();
    let cfg = SimConfig::default();
    let sim = Simulator::new(&hall, cfg.clone()).expect("sim");
    println!("\nRealism: of-dev-clean at the true alphas vs OpenFOAM noise-free (C)");
    println!("| snapshot | MAE cold | MAE hot | MAE all | max abs | bias cold | bias hot |");
    println!("|---|---|---|---|---|---|---|");
    let mut clean_pred = Vec::new();
    let mut per_sensor = vec![0.0; hall.sensors.len()];
    for st in &states {
        let sol = sim.solve(st, &alpha, &[]).expect("solve");
        let of = &truth["snapshots"][&st.label]["sensor_c_noise_free"];
        let (mut ec, mut eh, mut nc, mut nh, mut mx, mut bc, mut bh) =
            (0.0, 0.0, 0.0, 0.0, 0.0f64, 0.0, 0.0);
        for (i, (s, p)) in hall.sensors.iter().zip(sol.sensor_c()).enumerate() {
            let o = of[&s.id].as_f64().expect("truth value");
            let e = p - o;
            per_sensor[i] += e / states.len() as f64;
            mx = mx.max(e.abs());
            if s.id.starts_with("c-") {
                ec += e.abs();
                bc += e;
                nc += 1.0;
            } else {
                eh += e.abs();
                bh += e;
                nh += 1.0;
            }
        }
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:+.2} | {:+.2} |",
            st.label,
            ec / nc,
            eh / nh,
            (ec + eh) / (nc + nh),
            mx,
            bc / nc,
            bh / nh
        );
        clean_pred.push(sol.sensor_c().to_vec());
    }
    let worst: Vec<String> = {
        let mut v: Vec<(usize, f64)> = per_sensor.iter().copied().enumerate().collect();
        v.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        v.iter()
            .take(6)
            .map(|(i, e)| format!("{} {:+.2}", hall.sensors[*i].id, e))
            .collect()
    };
    println!(
        "largest mean errors (model - OpenFOAM): {}",
        worst.join(", ")
    );

    // Effect footprints: model(effect on) - model(clean) vs OpenFOAM(effect) - OpenFOAM(clean).
    let effect = |kind: &str, fields: Value| -> EffectSpec {
        let mut m = fields.as_object().cloned().unwrap_or_default();
        m.remove("kind");
        EffectSpec {
            kind: kind.into(),
            fields: m,
        }
    };
    let b4 = hall.racks.iter().position(|r| r.id == "B4").expect("B4");
    let b4_flow: f64 = hall
        .servers()
        .filter(|s| s.rack_index == b4)
        .map(|s| alpha[s.index] * states[0].power_w[s.index] * 4.71947e-4)
        .sum();
    let cases = [
        (
            "of-dev-crac-offset",
            effect(
                "crac_supply_offset",
                serde_json::json!({"crac": "crac-1", "offset_c": -1.0}),
            ),
        ),
        (
            "of-dev-blanking",
            effect(
                "rack_recirculation",
                serde_json::json!({"rack": "B4", "z_m": [1.0, 1.2], "fraction": 0.055 / b4_flow}),
            ),
        ),
        (
            "of-dev-bypass",
            effect(
                "bypass",
                serde_json::json!({"position_m": [3.6, 4.2], "size_m": [0.6, 0.4], "fraction": 0.1}),
            ),
        ),
    ];
    println!("\nEffect footprints (mean over snapshots of effect-on minus clean, C)");
    println!("| dataset | effect | sensors OpenFOAM moves >= 0.3 C | model footprint there | sign agreement | footprint MAE (all sensors) |");
    println!("|---|---|---|---|---|---|");
    let (clean_h, _, clean_truth) = (hall.clone(), (), truth.clone());
    for (dir, spec) in cases {
        let (_, _, t) = load(dir);
        let e = from_spec(&spec, &clean_h).expect("effect");
        let p = e.parameters().iter().map(|p| p.initial).collect::<Vec<_>>();
        let mut model_fp = vec![0.0; clean_h.sensors.len()];
        let mut of_fp = vec![0.0; clean_h.sensors.len()];
        for (si, st) in states.iter().enumerate() {
            let sol = sim.solve(st, &alpha, &[(e.as_ref(), &p)]).expect("solve");
            for (i, s) in clean_h.sensors.iter().enumerate() {
                let n = states.len() as f64;
                model_fp[i] += (sol.sensor_c()[i] - clean_pred[si][i]) / n;
                let a = t["snapshots"][&st.label]["sensor_c_noise_free"][&s.id]
                    .as_f64()
                    .expect("v");
                let b = clean_truth["snapshots"][&st.label]["sensor_c_noise_free"][&s.id]
                    .as_f64()
                    .expect("v");
                of_fp[i] += (a - b) / n;
            }
        }
        let affected: Vec<usize> = (0..of_fp.len())
            .filter(|&i| of_fp[i].abs() >= 0.3)
            .collect();
        let agree = affected
            .iter()
            .filter(|&&i| of_fp[i] * model_fp[i] > 0.0)
            .count();
        let desc: Vec<String> = affected
            .iter()
            .map(|&i| {
                format!(
                    "{} {:+.2}/{:+.2}",
                    clean_h.sensors[i].id, of_fp[i], model_fp[i]
                )
            })
            .collect();
        let mae = of_fp
            .iter()
            .zip(&model_fp)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / of_fp.len() as f64;
        println!(
            "| {dir} | {} | {} | {} | {agree}/{} | {mae:.2} |",
            spec.kind,
            affected.len(),
            desc.join(", "),
            affected.len()
        );
    }
}

/// Sensor change of the demo hall when the cell size halves.
fn grid_convergence() {
    let hall = sim_halls::demo_hall();
    let state = sim_halls::varied_state(&hall, 18.0, 0.9, 400.0);
    let alpha = vec![0.12; hall.server_count()];
    let run = |cell: f64| {
        let sim = Simulator::new(&hall, SimConfig::default().with_cell_m(cell)).expect("sim");
        sim.solve(&state, &alpha, &[])
            .expect("solve")
            .sensor_c()
            .to_vec()
    };
    println!("\nGrid convergence (demo hall, 24 sensors)");
    println!("| cells m | max abs change C | mean abs change C | worst sensor |");
    println!("|---|---|---|---|");
    for (a, b) in [(0.4, 0.2), (0.2, 0.1)] {
        let (x, y) = (run(a), run(b));
        let d: Vec<f64> = x.iter().zip(&y).map(|(p, q)| (p - q).abs()).collect();
        let (wi, w) =
            d.iter()
                .copied()
                .enumerate()
                .fold((0, 0.0), |acc, (i, v)| if v > acc.1 { (i, v) } else { acc });
        println!(
            "| {a} -> {b} | {w:.3} | {:.3} | {} |",
            d.iter().sum::<f64>() / d.len() as f64,
            hall.sensors[wi].id
        );
    }
}

fn main() {
    if let Ok(case) = std::env::var(CASE_ENV) {
        run_case(&case);
        return;
    }
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    if !args.iter().any(|a| a == "--realism") {
        perf_table(quick);
    }
    realism();
    grid_convergence();
}
