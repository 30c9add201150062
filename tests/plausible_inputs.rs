//! Inputs that parse but describe no hall: a CRAC air flow or server powers in the wrong
//! unit. `simulate`, `calibrate` and `diagnose` warn, naming the files, the snapshot and
//! the figure that gives it away, and go on (the user may mean it); a rise no model run
//! could give is refused before any run.

mod cli_support;

use std::path::Path;

use cli_support::{assert_input_error, data, kalibre, on_files, run, stderr, tmp};

/// `kalibre simulate` of `hall` and `snapshots` into `dir`: its stderr, after checking it
/// succeeded.
fn simulate(hall: &Path, snapshots: &Path, dir: &Path) -> String {
    let o = run(kalibre()
        .args(["simulate", "--hall"])
        .arg(hall)
        .arg("--snapshots")
        .arg(snapshots)
        .arg("--out")
        .arg(dir.join("predicted.csv")));
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    err
}

#[test]
fn unit_slips_in_flow_or_power_are_named_and_real_halls_are_not() {
    let dir = tmp("plausible");
    let hall = data("of-dev-clean/hall.json");
    let snaps = data("of-dev-clean/snapshots.csv");
    // The development hall: 58-67 kW on 3.5 m3/s at fan speed 0.9, about 15 K.
    let err = simulate(&hall, &snaps, &dir);
    assert!(!err.contains("warning"), "{err}");

    // The CRAC's flow a hundredth of what it is.
    let text = std::fs::read_to_string(&hall).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    for c in doc["cracs"].as_array_mut().unwrap() {
        let flow = c["rated_flow_m3_s"].as_f64().unwrap();
        c["rated_flow_m3_s"] = serde_json::json!(flow / 100.0);
    }
    let thin = dir.join("thin.json");
    std::fs::write(&thin, doc.to_string()).unwrap();
    let err = simulate(&thin, &snaps, &dir);
    let line = err
        .lines()
        .find(|l| l.contains("warning"))
        .unwrap_or_else(|| panic!("no warning: {err}"));
    for needle in [
        "thin.json",
        "snapshots.csv",
        "snapshot `t0`",
        "rated_flow_m3_s",
        "(2 more such snapshots)",
    ] {
        assert!(line.contains(needle), "`{needle}` not in {line}");
    }
    let rise: f64 = line
        .split(" K warmer")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no rise in {line}"));
    // A hundredth of the air carries the same heat at a hundred times the rise.
    assert!((500.0..5_000.0).contains(&rise), "{line}");

    // Powers in kW where W are meant: the servers hardly warm the air.
    let text = std::fs::read_to_string(&snaps).unwrap();
    let kw: String = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            if f.len() == 4 && f[1] == "power_w" {
                let w: f64 = f[3].parse().unwrap();
                format!("{},{},{},{}\n", f[0], f[1], f[2], w / 1000.0)
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let kw_path = dir.join("kw.csv");
    std::fs::write(&kw_path, kw).unwrap();
    let err = simulate(&hall, &kw_path, &dir);
    assert!(
        err.contains("kw.csv") && err.contains("powers in kW"),
        "{err}"
    );

    // A what-if far beyond any hall is said to be so; a modest one is not.
    let what_if = |scale: &str| {
        let o = run(kalibre()
            .args(["simulate", "--hall"])
            .arg(&hall)
            .arg("--snapshots")
            .arg(&snaps)
            .args(["--power-scale", scale, "--out"])
            .arg(dir.join("what-if.csv")));
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let err = what_if("100");
    assert!(
        err.contains("what if server powers x100: snapshot `t0`") && err.contains("no hall runs"),
        "{err}"
    );
    let err = what_if("1.2");
    assert!(!err.contains("warning"), "{err}");

    // calibrate warns the same before it runs anything; here a directory where its report
    // goes stops it right after.
    let out = dir.join("cal");
    std::fs::create_dir_all(out.join("report.json")).unwrap();
    let o = run(kalibre()
        .args(["calibrate", "--hall"])
        .arg(&thin)
        .arg("--snapshots")
        .arg(&snaps)
        .arg("--out")
        .arg(&out));
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("rated_flow_m3_s"), "{err}");
    assert!(err.contains("report.json is a directory"), "{err}");
}

#[test]
fn a_rise_no_model_can_give_is_refused_naming_the_inputs() {
    let dir = tmp("plausible-impossible");
    let hall = data("of-dev-clean/hall.json");
    let snaps = data("of-dev-clean/snapshots.csv");
    // Every fan of t0 a billionth of full speed: a valid ratio, but 60 kW on 3.5e-9 m3/s
    // of air is a rise of about 1e10 K, and every run would fail as implausible.
    let text = std::fs::read_to_string(&snaps).unwrap();
    let still: String = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            if f.len() == 4 && f[0] == "t0" && f[1] == "fan_speed" {
                format!("{},{},{},1e-9\n", f[0], f[1], f[2])
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let still_path = dir.join("still.csv");
    std::fs::write(&still_path, still).unwrap();
    let o = run(on_files("simulate", &hall, &still_path)
        .arg("--out")
        .arg(dir.join("predicted.csv")));
    assert_input_error(&o, "still.csv: snapshot `t0`");
    let err = stderr(&o);
    for needle in ["hall.json", "fan_speed", "10000 C"] {
        assert!(err.contains(needle), "`{needle}` not in {err}");
    }
    assert!(!dir.join("predicted.csv").exists());
    let o = run(on_files("calibrate", &hall, &still_path)
        .arg("--out")
        .arg(dir.join("cal")));
    assert_input_error(&o, "still.csv: snapshot `t0`");
    assert!(!dir.join("cal").join("runs.jsonl").exists());

    // A what-if that takes the hall there is refused by its flag; x1000 of 60 kW on
    // 3.5 m3/s is about 15,000 K.
    let o = run(on_files("simulate", &hall, &snaps)
        .args(["--power-scale", "1000", "--out"])
        .arg(dir.join("what-if.csv")));
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("what if server powers x1000: snapshot `t0`") && err.contains("10000 C"),
        "{err}"
    );
    assert!(!dir.join("what-if.csv").exists());
}
