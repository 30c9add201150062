//! Inputs the command-line tool refuses before any model runs: outputs that would
//! replace an input file, thread and run counts that would only thrash, what-if changes
//! beyond the air's range. Each is one line naming the flag, and exit code 2.

mod cli_support;

use std::path::Path;

use cli_support::{assert_input_error, data, kalibre, run, tmp};

#[test]
fn an_output_over_an_input_file_is_refused_and_the_input_kept() {
    let dir = tmp("overwrite");
    let hall = data("of-dev-clean/hall.json");
    let snaps = dir.join("snapshots.csv");
    std::fs::copy(data("of-dev-clean/snapshots.csv"), &snaps).unwrap();
    let before = std::fs::read(&snaps).unwrap();
    let simulate = |out: &Path, servers: Option<&Path>| {
        let mut c = kalibre();
        c.args(["simulate", "--hall"])
            .arg(&hall)
            .arg("--snapshots")
            .arg(&snaps)
            .arg("--out")
            .arg(out);
        if let Some(s) = servers {
            c.arg("--servers").arg(s);
        }
        run(&mut c)
    };
    // The same file by another spelling of its path.
    let same = dir.join(".").join("snapshots.csv");
    assert_input_error(&simulate(&same, None), "is the --snapshots file");
    assert_eq!(
        std::fs::read(&snaps).unwrap(),
        before,
        "the measurements changed"
    );
    let o = simulate(&dir.join("pred.csv"), Some(&hall));
    assert_input_error(&o, "--servers");
}

#[test]
fn thread_and_run_counts_that_would_thrash_are_refused() {
    let dir = tmp("counts");
    let hall = data("of-dev-clean/hall.json");
    let snaps = data("of-dev-clean/snapshots.csv");
    let calibrate = |flag: &str, n: &str| {
        run(kalibre()
            .args(["calibrate", flag, n, "--hall"])
            .arg(&hall)
            .arg("--snapshots")
            .arg(&snaps)
            .arg("--out")
            .arg(dir.join("cal")))
    };
    assert_input_error(
        &calibrate("--threads", "10000"),
        "--threads 10000: expected at most 1024",
    );
    assert_input_error(
        &calibrate("--parallel-runs", "10000"),
        "must be at most 1024, got 10000",
    );
    assert!(
        !dir.join("cal").join("runs.jsonl").exists(),
        "a refused calibration started a journal"
    );
}

#[test]
fn what_if_changes_beyond_the_air_are_refused() {
    let dir = tmp("what-if");
    let what_if = |flag: &str, value: &str| {
        run(kalibre()
            .args(["simulate", flag, value, "--hall"])
            .arg(data("of-dev-clean/hall.json"))
            .arg("--snapshots")
            .arg(data("of-dev-clean/snapshots.csv"))
            .arg("--out")
            .arg(dir.join("pred.csv")))
    };
    assert_input_error(
        &what_if("--setpoint-offset-c", "1e308"),
        "would supply 1e308 C",
    );
    assert_input_error(&what_if("--power-scale", "1e300"), "expected at most 1e7 W");
    assert!(!dir.join("pred.csv").exists());
}

#[test]
fn a_report_of_another_schema_is_refused() {
    let dir = tmp("schema");
    let report = dir.join("report.json");
    std::fs::write(
        &report,
        r#"{ "schema": "kalibre.report/9", "best": { "params": { "alpha/web": 0.13 } } }"#,
    )
    .unwrap();
    let o = run(kalibre()
        .args(["simulate", "--hall"])
        .arg(data("of-dev-clean/hall.json"))
        .arg("--snapshots")
        .arg(data("of-dev-clean/snapshots.csv"))
        .arg("--params")
        .arg(&report)
        .arg("--out")
        .arg(dir.join("pred.csv")));
    assert_input_error(
        &o,
        "/schema: expected \"kalibre.report/1\", found \"kalibre.report/9\"",
    );
}
