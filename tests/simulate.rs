//! End-to-end tests of `kalibre simulate` on the small OpenFOAM development hall: the
//! predictions, every server's air, where each sensor's warming comes from, the what-ifs
//! and their headroom, and a closed stdout.

mod cli_support;

use cli_support::{assert_input_error, data, kalibre, on_dataset, run, stderr, tmp};

#[test]
fn simulate_writes_predictions_and_vtk() {
    let dir = tmp("simulate");
    let hall = data("of-dev-clean/hall.json");
    let snaps = data("of-dev-clean/snapshots.csv");
    let params = dir.join("params.json");
    std::fs::write(
        &params,
        r#"{ "alpha/web": 0.13, "alpha/db": 0.17, "alpha/gpu": 0.12 }"#,
    )
    .unwrap();
    // `simulate` of `snapshots` at `params`, predictions to `<name>.csv`, fields to `name`.
    let simulate = |snapshots: &std::path::Path, name: &str| {
        run(kalibre()
            .args(["simulate", "--hall"])
            .arg(&hall)
            .arg("--snapshots")
            .arg(snapshots)
            .arg("--params")
            .arg(&params)
            .arg("--out")
            .arg(dir.join(name).with_extension("csv"))
            .arg("--vtk")
            .arg(dir.join(name)))
    };
    let out = dir.join("vtk.csv");
    let o = simulate(&snaps, "vtk");
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(&out).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], "snapshot,kind,id,value");
    assert_eq!(rows.len(), 1 + 3 * 24);
    assert!(rows[1..].iter().all(|r| r.contains(",sensor_c,")));
    // Every reading lies between the coldest setpoint and a plausible exhaust temperature.
    for r in &rows[1..] {
        let v: f64 = r.rsplit(',').next().unwrap().parse().unwrap();
        assert!((17.0..60.0).contains(&v), "implausible reading {r}");
    }
    for label in ["t0", "t1", "t2"] {
        let vtk = std::fs::read_to_string(dir.join("vtk").join(format!("{label}.vtk"))).unwrap();
        assert!(vtk.starts_with("# vtk DataFile"));
        assert!(vtk.contains("temperature_c") && vtk.contains("velocity_m_s"));
    }
    // Labels that would share one file: refused before any solve, not one snapshot's
    // fields silently replaced by another's.
    let text = std::fs::read_to_string(&snaps).unwrap();
    let relabelled = text.replace("\nt0,", "\na/b,").replace("\nt1,", "\na_b,");
    let clash = dir.join("clash.csv");
    std::fs::write(&clash, relabelled).unwrap();
    let o = simulate(&clash, "clash-vtk");
    assert_input_error(
        &o,
        "--vtk: snapshots `a/b` and `a_b` would both be written to a_b.vtk",
    );
    assert!(!dir.join("clash-vtk").exists());
}

#[test]
fn simulate_writes_each_servers_air_and_counts_warm_intakes() {
    let dir = tmp("servers");
    let (web, db, gpu) = (0.13, 0.17, 0.12);
    let params = dir.join("params.json");
    std::fs::write(
        &params,
        format!(r#"{{ "alpha/web": {web}, "alpha/db": {db}, "alpha/gpu": {gpu} }}"#),
    )
    .unwrap();
    let table = dir.join("servers.csv");
    let limit_c = 19.0;
    let o = run(on_dataset("simulate", "of-dev-clean")
        .arg("--params")
        .arg(&params)
        .arg("--out")
        .arg(dir.join("pred.csv"))
        .arg("--servers")
        .arg(&table)
        .arg(format!("--inlet-limit-c={limit_c}")));
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(&table).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(
        rows[0],
        [
            "snapshot",
            "server",
            "rack",
            "type",
            "power_w",
            "flow_m3_s",
            "intake_c",
            "exhaust_c"
        ]
    );
    assert_eq!(rows.len(), 1 + 3 * 20, "3 snapshots x 20 servers");
    let num = |s: &str| -> f64 { s.parse().unwrap() };
    let rho_cp = 1.2 * 1005.0;
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    let mut warm_in_all = 0;
    for label in ["t0", "t1", "t2"] {
        let mut warm = 0;
        for r in rows[1..].iter().filter(|r| r[0] == label) {
            let alpha = match r[3] {
                "web" => web,
                "db" => db,
                "gpu" => gpu,
                other => panic!("unexpected type {other}"),
            };
            let (power, flow, intake, exhaust) = (num(r[4]), num(r[5]), num(r[6]), num(r[7]));
            // The flow is the hall's definition of alpha, and the exhaust carries the
            // server's whole power: energy balance per server.
            assert!(
                (flow - alpha * power * 4.71947e-4).abs() < 1e-12 * flow.max(1.0),
                "{r:?}"
            );
            let rise = power / (rho_cp * flow);
            assert!((exhaust - intake - rise).abs() < 1e-9 * rise, "{r:?}");
            // Intakes draw room air: at or above the coldest setpoint of the snapshot.
            assert!((17.4..40.0).contains(&intake), "{r:?}");
            warm += usize::from(intake > limit_c);
        }
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("{label}: ")))
            .unwrap_or_else(|| panic!("no inlet line for {label} in {stdout}"));
        assert!(
            line.contains(&format!("{warm} of 20 server intakes above {limit_c:.1} C")),
            "{line}"
        );
        warm_in_all += warm;
    }
    assert!(
        warm_in_all > 0,
        "the limit should catch some intakes: {stdout}"
    );
    // A limit that is not a number is refused by name.
    let o = run(on_dataset("simulate", "of-dev-clean")
        .args(["--inlet-limit-c=nan", "--out"])
        .arg(dir.join("pred.csv")));
    assert_input_error(&o, "--inlet-limit-c");
}

/// What if every setpoint rose by the headroom `simulate` reports? The hottest intake
/// then sits exactly at the limit: at fixed flows the temperatures move one for one with
/// the supply's. Changes outside the hall's limits are refused by name.
#[test]
fn simulate_says_which_racks_warm_each_sensor() {
    let dir = tmp("heat-sources");
    let params = dir.join("params.json");
    std::fs::write(
        &params,
        r#"{ "alpha/web": 0.13, "alpha/db": 0.17, "alpha/gpu": 0.12 }"#,
    )
    .unwrap();
    let table = dir.join("heat.csv");
    let o = run(on_dataset("simulate", "of-dev-clean")
        .arg("--params")
        .arg(&params)
        .arg("--out")
        .arg(dir.join("pred.csv"))
        .arg("--heat-sources")
        .arg(&table));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("heat.csv"));
    let csv = std::fs::read_to_string(&table).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("snapshot,sensor,rack,warming_k,share"));
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    // (snapshot, sensor) -> [(rack, warming, share)]
    type Racks = Vec<(String, f64, f64)>;
    let mut groups: std::collections::BTreeMap<(String, String), Racks> = Default::default();
    for r in &rows {
        let (warming, share): (f64, f64) = (r[3].parse().unwrap(), r[4].parse().unwrap());
        assert!((0.02 - 5e-5..=1.0 + 5e-5).contains(&share), "{r:?}");
        assert!(warming > 0.0, "{r:?}");
        groups
            .entry((r[0].clone(), r[1].clone()))
            .or_default()
            .push((r[2].clone(), warming, share));
    }
    for ((snapshot, sensor), racks) in &groups {
        let sum: f64 = racks.iter().map(|r| r.2).sum();
        assert!(
            sum <= 1.0 + 1e-3,
            "{snapshot} {sensor}: shares sum to {sum}"
        );
        assert!(racks.windows(2).all(|w| w[0].1 >= w[1].1), "{racks:?}");
    }
    // Each hot-aisle sensor sits at its rack's exhausts (`h-A3` behind rack A3): that rack
    // warms it most, in every snapshot.
    for snapshot in ["t0", "t1", "t2"] {
        for sensor in ["h-A1", "h-A3", "h-A5", "h-B2", "h-B4", "h-B5"] {
            let racks = &groups[&(snapshot.to_string(), sensor.to_string())];
            assert_eq!(racks[0].0, sensor[2..], "{snapshot} {sensor}: {racks:?}");
        }
    }
}

#[test]
fn simulate_answers_what_if_and_its_headroom_is_exact() {
    let dir = tmp("what-if");
    let simulate = |extra: &[&str]| {
        run(on_dataset("simulate", "of-dev-clean")
            .arg("--out")
            .arg(dir.join("pred.csv"))
            .args(extra))
    };
    let hottest_t1 = |extra: &[&str]| -> f64 {
        let table = dir.join("servers.csv");
        let o = simulate(&[&["--servers", table.to_str().unwrap()], extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read_to_string(&table)
            .unwrap()
            .lines()
            .filter(|l| l.starts_with("t1,"))
            .map(|l| l.split(',').nth(6).unwrap().parse::<f64>().unwrap())
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let limit_c = 27.0;
    // At the hall's initial alphas t1 is over the limit: the headroom is negative.
    let headroom = limit_c - hottest_t1(&[]);
    assert!(headroom < -0.5, "{headroom}");
    let raised = hottest_t1(&["--setpoint-offset-c", &format!("{headroom:.12}")]);
    assert!((raised - limit_c).abs() < 1e-6, "{raised}");
    // Slower fans give less supply against the same server draw: warmer intakes.
    assert!(hottest_t1(&["--fan-speed-scale", "0.9"]) > hottest_t1(&[]));
    let refused = |extra: &[&str], needle: &str| assert_input_error(&simulate(extra), needle);
    // On finer grids: each snapshot's least headroom over the grids, never above the
    // model's own.
    let o = simulate(&["--grid-check", "0.75,0.5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    for label in ["t0", "t1", "t2"] {
        let own = stdout
            .lines()
            .find(|l| l.starts_with(&format!("{label}: ")) && l.contains("server intakes"))
            .unwrap_or_else(|| panic!("{stdout}"));
        let fine = stdout
            .lines()
            .find(|l| l.starts_with(&format!("{label}: on finer grids")))
            .unwrap_or_else(|| panic!("{stdout}"));
        assert!(
            fine.contains("at 0.150 m") && fine.contains("at 0.100 m"),
            "{fine}"
        );
        let number = |text: &str, before: &str| -> f64 {
            let head = &text[..text.find(before).unwrap()];
            head.rsplit(' ').next().unwrap().parse().unwrap()
        };
        let least = number(fine, " C, allows for the grid");
        // The model's own: `headroom H C` or `O C over`.
        let model = if own.contains("headroom ") {
            number(own, " C: every setpoint could rise")
        } else {
            -number(own, " C over")
        };
        assert!(least <= model + 1e-9, "{least} > {model}: {fine}");
    }
    refused(
        &["--grid-check", "1.5"],
        "--grid-check: 1.5 is not a finer grid",
    );
    refused(
        &["--fan-speed-scale", "1.2"],
        "CRAC `crac-1` in snapshot `t0` would run at 1.080 of its rated flow",
    );
    refused(
        &["--power-scale=-1"],
        "--power-scale: expected a factor >= 0",
    );
    refused(
        &["--setpoint-offset-c", "inf"],
        "--setpoint-offset-c: expected a finite",
    );
    // OpenFOAM's options need --model openfoam, and the built-in simulator's fields are
    // not OpenFOAM's (refused before any case is meshed).
    refused(
        &["--np", "2"],
        "--np is an OpenFOAM option: add --model openfoam",
    );
    refused(
        &["--of-dir", dir.join("of").to_str().unwrap()],
        "--of-dir is an OpenFOAM option",
    );
    for flag in ["--vtk", "--heat-sources"] {
        refused(
            &["--model", "openfoam", flag, dir.join("x").to_str().unwrap()],
            &format!("{flag} needs the built-in simulator's fields"),
        );
    }
    refused(
        &["--model", "openfoam", "--grid-check", "0.5"],
        "--grid-check needs the built-in simulator's fields",
    );
    assert!(!dir.join("of").exists() && !dir.join("openfoam").exists());
}

/// A reader that closes early (`kalibre ... | head`) ends the process quietly, by the
/// signal other Unix tools die of, not with a panic.
#[cfg(unix)]
#[test]
fn a_closed_stdout_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tmp("pipe");
    let mut child = on_dataset("simulate", "of-dev-clean")
        .arg("--out")
        .arg(dir.join("pred.csv"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Close the reading end before the first line is printed (the solves come first).
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        o.status.signal(),
        Some(libc::SIGPIPE),
        "{:?}: {err}",
        o.status
    );
}

/// `simulate --params` with the report of a calibration that ran another model refuses
/// to answer with the built-in simulator unasked: it names the model that ran and the
/// flag that runs it; `--model builtin` asks for the built-in simulator and gets it.
#[test]
fn simulate_does_not_answer_for_another_model_unasked() {
    let dir = tmp("simulate-other-model");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(cli_support::QUICK_CALIBRATION)
        .arg("--out")
        .arg(dir.join("cal")));
    assert!(o.status.success(), "{}", stderr(&o));
    let mut report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cal/report.json")).unwrap())
            .unwrap();
    report["model"]["kind"] = serde_json::json!("openfoam");
    let edited = dir.join("openfoam-report.json");
    std::fs::write(&edited, serde_json::to_string(&report).unwrap()).unwrap();
    let simulate = |extra: &[&str]| {
        run(on_dataset("simulate", "of-dev-clean")
            .args(extra)
            .arg("--params")
            .arg(&edited)
            .arg("--out")
            .arg(dir.join("pred.csv")))
    };
    let o = simulate(&[]);
    assert_input_error(
        &o,
        "the calibration ran the openfoam model: --model openfoam runs it, and --model \
         builtin runs the built-in simulator at its parameters",
    );
    assert!(!dir.join("pred.csv").exists());
    let o = simulate(&["--model", "builtin"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("pred.csv").is_file());
}
