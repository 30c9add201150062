//! A resumed calibration reuses a journaled run only under the operating conditions it
//! ran at: a `snapshots.csv` edited under the same snapshot labels (other setpoints,
//! powers or fan speeds) runs the model again, where it used to answer from the old
//! conditions without a word. Edited readings alone change no model run, so the runs
//! made are reused.

mod cli_support;
use cli_support::*;

use std::path::Path;

/// `report.json`'s run counts and best MAE after calibrating `snapshots` into `out`.
fn calibrate(snapshots: &Path, out: &Path) -> (serde_json::Value, f64) {
    let o = run(kalibre()
        .args(["calibrate", "--hall"])
        .arg(data("of-dev-clean/hall.json"))
        .arg("--snapshots")
        .arg(snapshots)
        .args(QUICK_CALIBRATION)
        .arg("--out")
        .arg(out));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    (
        report["runs"].clone(),
        report["best"]["mae_c"].as_f64().unwrap(),
    )
}

#[test]
fn a_journaled_run_is_reused_only_under_the_conditions_it_ran_at() {
    let dir = tmp("resume-inputs");
    let stored = data("of-dev-clean/snapshots.csv");
    let text = std::fs::read_to_string(&stored).unwrap();
    let (first, _) = calibrate(&stored, &dir.join("cal"));
    let total = first["total"].as_u64().unwrap();
    assert_eq!(first["new"].as_u64(), Some(total));

    // Every setpoint 2 C warmer, under the same labels.
    let warmer: String = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            if f.len() == 4 && f[1] == "setpoint_c" {
                let v: f64 = f[3].parse().unwrap();
                format!("{},{},{},{:.2}\n", f[0], f[1], f[2], v + 2.0)
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    assert_ne!(warmer, text);
    let edited = dir.join("warmer.csv");
    std::fs::write(&edited, &warmer).unwrap();
    let (resumed, resumed_mae) = calibrate(&edited, &dir.join("cal"));
    assert_eq!(resumed["cached"].as_u64(), Some(0), "{resumed}");
    // What a fresh calibration of the edited file gives, exactly.
    let (_, fresh_mae) = calibrate(&edited, &dir.join("fresh"));
    assert_eq!(resumed_mae, fresh_mae);

    // Readings moved, conditions kept: the model's answers stand, every run is reused.
    let readings: String = text.replacen(
        "t0,sensor_c,c-A1-hi,17.833",
        "t0,sensor_c,c-A1-hi,18.833",
        1,
    );
    assert_ne!(readings, text);
    let moved = dir.join("readings.csv");
    std::fs::write(&moved, readings).unwrap();
    let (again, _) = calibrate(&moved, &dir.join("cal"));
    // The initial design (4 points x 3 snapshots) is the same; the search then follows
    // the new readings.
    assert!(again["cached"].as_u64().unwrap() >= 12, "{again}");
}
