//! `kalibre simulate --model openfoam`: OpenFOAM through the command line, at given
//! parameters. Needs OpenFOAM (CI installs it); fails, never skips, without it.

use std::process::Command;

mod openfoam_common;
use openfoam_common::*;

/// At the true alphas, one snapshot through the CLI, decomposed over two processes
/// (`--np 2`), reproduces the development hall's noise-free OpenFOAM readings and its
/// servers' intakes, and the case is meshed beside `--out`.
#[test]
fn simulate_with_openfoam_reproduces_the_openfoam_data() {
    require_openfoam();
    let dir = tmp("simulate-cli");
    // The first snapshot only: one solve, on both cores (`tests/openfoam.rs` solves the
    // same hall serially through the library).
    let csv = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let t0: Vec<&str> = csv
        .lines()
        .enumerate()
        .filter(|(i, l)| *i == 0 || l.starts_with("t0,"))
        .map(|(_, l)| l)
        .collect();
    std::fs::write(dir.join("t0.csv"), t0.join("\n") + "\n").unwrap();
    let truth = truth("of-dev-clean");
    let alphas: serde_json::Map<String, serde_json::Value> = truth["alpha_true_cfm_per_w"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(t, a)| (format!("alpha/{t}"), a.clone()))
        .collect();
    std::fs::write(
        dir.join("truth-params.json"),
        serde_json::to_string(&alphas).unwrap(),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_kalibre"))
        .args(["simulate", "--model", "openfoam", "--np", "2", "--hall"])
        .arg(data("of-dev-clean/hall.json"))
        .arg("--snapshots")
        .arg(dir.join("t0.csv"))
        .arg("--params")
        .arg(dir.join("truth-params.json"))
        .arg("--out")
        .arg(dir.join("pred.csv"))
        .arg("--servers")
        .arg(dir.join("servers.csv"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("t0: OpenFOAM solved in"), "{stdout}");
    assert!(
        dir.join("openfoam").is_dir(),
        "the case is meshed beside --out"
    );
    let pred = std::fs::read_to_string(dir.join("pred.csv")).unwrap();
    let want = &truth["snapshots"]["t0"]["sensor_c_noise_free"];
    let (mut sum, mut n) = (0.0, 0);
    for line in pred.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!((f[0], f[1]), ("t0", "sensor_c"), "{line}");
        let got: f64 = f[3].parse().unwrap();
        sum += (got - want[f[2]].as_f64().unwrap()).abs();
        n += 1;
    }
    assert_eq!(n, 24, "{pred}");
    // The datasets' own noise is 0.15 C; the hall's initial alphas are 4.9 C off.
    let mae = sum / n as f64;
    assert!(mae < 0.15, "MAE {mae:.3} C against the OpenFOAM data");
    // Every server's intake, as the dataset's OpenFOAM run sampled it, and an exhaust
    // warmer by the power over the flow's heat capacity.
    let want = &truth["snapshots"]["t0"]["server_intake_c"];
    let servers = std::fs::read_to_string(dir.join("servers.csv")).unwrap();
    let (mut sum, mut n) = (0.0, 0);
    for line in servers.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |k: usize| f[k].parse::<f64>().unwrap();
        let (power_w, flow_m3_s, intake_c, exhaust_c) = (num(4), num(5), num(6), num(7));
        sum += (intake_c - want[f[1]].as_f64().unwrap()).abs();
        n += 1;
        let rise_k = power_w / (1.2 * 1005.0 * flow_m3_s);
        assert!((exhaust_c - intake_c - rise_k).abs() < 1e-6, "{line}");
    }
    assert_eq!(n, 20, "{servers}");
    let mae = sum / n as f64;
    assert!(
        mae < 0.15,
        "intakes: MAE {mae:.3} C against the OpenFOAM data"
    );
    assert!(
        stdout.contains("t0: 0 of 20 server intakes above 27.0 C"),
        "{stdout}"
    );
}
