//! Inputs the command-line tool refuses before any model runs: outputs that would
//! replace an input file or a user's hall, thread and run counts that would only thrash, what-if changes
//! beyond the air's range, a parameter named twice, a journal line no model could have
//! written, flags that cannot apply, a diagnosis of another hall or other measurements
//! than the calibration's. Each is one line naming the flag, file or line, and exit
//! code 2.

mod cli_support;

use std::path::Path;

use cli_support::{
    assert_input_error, data, diagnose_cmd, kalibre, on_dataset, run, stderr, tmp,
    QUICK_CALIBRATION,
};

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
    // A user's own hall is not a synthetic one to replace, nor a calibration a demo's.
    let mine = dir.join("mine");
    std::fs::create_dir_all(&mine).unwrap();
    std::fs::copy(&hall, mine.join("hall.json")).unwrap();
    let o = run(kalibre().args(["synth", "--out"]).arg(&mine));
    assert_input_error(&o, "holds hall.json with no truth.json beside it");
    // Nor another tool's dataset with a truth of its own: the OpenFOAM development
    // hall's files.
    let theirs = dir.join("theirs");
    std::fs::create_dir_all(&theirs).unwrap();
    for name in ["hall.json", "snapshots.csv", "truth.json"] {
        std::fs::copy(data(&format!("of-dev-clean/{name}")), theirs.join(name)).unwrap();
    }
    let o = run(kalibre().args(["synth", "--out"]).arg(&theirs));
    assert_input_error(
        &o,
        "holds hall.json with a truth.json that is not kalibre's (no `schema` kalibre.truth/1) beside it",
    );
    assert_eq!(
        std::fs::read(theirs.join("truth.json")).unwrap(),
        std::fs::read(data("of-dev-clean/truth.json")).unwrap()
    );
    let cal = dir.join("cal");
    std::fs::create_dir_all(&cal).unwrap();
    std::fs::write(cal.join("runs.jsonl"), "").unwrap();
    let o = run(kalibre().args(["demo", "--out"]).arg(&cal));
    assert_input_error(&o, "holds runs.jsonl with no truth.json beside it");
    assert_eq!(
        std::fs::read(mine.join("hall.json")).unwrap(),
        std::fs::read(&hall).unwrap()
    );
    // A synthetic hall is replaced when asked again.
    let synthetic = dir.join("synthetic");
    for _ in 0..2 {
        let o = run(kalibre().args(["synth", "--out"]).arg(&synthetic));
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    }
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
    // Search and training sizes that would run for hours (or fill the memory: 1e8 members
    // took 8 GB) inside one step, where --max-wall-s is not looked at.
    for (flag, n, why) in [
        (
            "--population",
            "100000000",
            "--population: must be at most 10000",
        ),
        (
            "--de-iterations",
            "4000000000",
            "--de-iterations: must be in 1..=100000",
        ),
        (
            "--adam-steps",
            "4000000000",
            "--adam-steps: must be in 1..=1000000",
        ),
        ("--epochs", "4000000000", "--epochs: must be in 1..=100000"),
    ] {
        assert_input_error(&calibrate(flag, n), why);
    }
    assert!(
        !dir.join("cal").join("runs.jsonl").exists(),
        "a refused calibration started a journal"
    );
}

/// Search settings that leave the search unable to move, or mean nothing, are refused
/// by flag: `--trust-region 1e-300` used to pin every iteration to the initial design.
#[test]
fn search_settings_out_of_their_ranges_are_refused_by_flag() {
    let dir = tmp("ranges");
    for (flag, value, why) in [
        (
            "--trust-region",
            "1e-300",
            "--trust-region: must be in [0.001, 1]",
        ),
        ("--focus", "1e-300", "--focus: must be finite and >= 0.01"),
        (
            "--explore",
            "2",
            "--explore: must be in [0, 1] (0 stops at a repeated point)",
        ),
        (
            "--rise-weight",
            "1e308",
            "`weight`: must be in [0, 1e6], got 1e308",
        ),
        (
            "--rise-weight=-1",
            "",
            "`weight`: must be in [0, 1e6], got -1",
        ),
        (
            "--crossover",
            "1e308",
            "--crossover: must be in [0, 1], got 1e308",
        ),
        (
            "--rise-range",
            "0,1e308",
            "`upper_c`: must be at most 100 K, got 1e308",
        ),
        (
            "--max-runs",
            "5",
            "--max-runs: 5 is smaller than the initial design's 12 runs",
        ),
    ] {
        // An empty value: the flag carries it (`--flag=-1`).
        let o = run(kalibre()
            .args(["calibrate", flag])
            .args((!value.is_empty()).then_some(value))
            .arg("--hall")
            .arg(data("of-dev-clean/hall.json"))
            .arg("--snapshots")
            .arg(data("of-dev-clean/snapshots.csv"))
            .arg("--out")
            .arg(dir.join("cal")));
        assert_input_error(&o, why);
    }
}

/// An `--out` that cannot take a calibration's files is refused before any run: a
/// `report.html` that is a directory used to fail after the whole calibration, and a FIFO
/// named `runs.jsonl` (or the lock file) blocked it for good.
#[test]
fn an_out_that_cannot_take_the_files_is_refused_first() {
    let dir = tmp("out-kinds");
    std::fs::create_dir_all(dir.join("html").join("report.html")).unwrap();
    std::fs::write(dir.join("plain"), "not a directory").unwrap();
    for (sub, name) in [("fifo", "runs.jsonl"), ("lock", ".kalibre.lock")] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        let made = std::process::Command::new("mkfifo")
            .arg(dir.join(sub).join(name))
            .status()
            .unwrap();
        assert!(made.success());
    }
    for (out, why) in [
        ("html", "report.html is a directory"),
        ("plain", "is a file, not a directory"),
        ("fifo", "runs.jsonl is not a regular file"),
        ("lock", ".kalibre.lock is not a regular file"),
    ] {
        let o = run(kalibre()
            .args(["calibrate", "--hall"])
            .arg(data("of-dev-clean/hall.json"))
            .arg("--snapshots")
            .arg(data("of-dev-clean/snapshots.csv"))
            .arg("--out")
            .arg(dir.join(out)));
        assert_input_error(&o, why);
    }
    let o = run(kalibre().args(["synth", "--out"]).arg(dir.join("plain")));
    assert_input_error(&o, "is a file, not a directory");
    // Nor one that would have to be made under a file.
    let o = run(kalibre()
        .args(["synth", "--out"])
        .arg(dir.join("plain").join("sub")));
    assert_input_error(&o, "plain is a file, not a directory");
    // Nor does `diagnose` wait on a FIFO where the calibration's journal should be.
    let o = run(&mut diagnose_cmd(
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
        &dir.join("fifo"),
    ));
    assert_input_error(&o, "runs.jsonl: not a regular file");
    // A calibration with runs but no report yet (stopped, or still running) is named as
    // such, not as a missing file.
    let stopped = dir.join("stopped");
    std::fs::create_dir_all(&stopped).unwrap();
    std::fs::write(stopped.join("runs.jsonl"), "").unwrap();
    let o = run(&mut diagnose_cmd(
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
        &stopped,
    ));
    assert_input_error(&o, "has runs but no report");
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
fn a_hall_with_nothing_to_calibrate_is_refused_naming_the_field() {
    let dir = tmp("nothing-to-calibrate");
    // The development hall has no effects: with alpha fixed nothing is left.
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--alpha", "fixed", "--out"])
        .arg(dir.join("cal")));
    assert_input_error(
        &o,
        "of-dev-clean/hall.json: /calibrate/alpha: alpha is `fixed`",
    );
    assert!(stderr(&o).contains("per_type"), "{}", stderr(&o));
    assert!(!dir.join("cal").join("runs.jsonl").exists());
}

/// `kalibre simulate` on the development hall with `text` as the `--params` file
/// `params`, predictions to `dir/pred.csv`.
fn simulate_with_params(dir: &Path, params: &Path, text: &str) -> std::process::Output {
    std::fs::write(params, text).unwrap();
    run(kalibre()
        .args(["simulate", "--hall"])
        .arg(data("of-dev-clean/hall.json"))
        .arg("--snapshots")
        .arg(data("of-dev-clean/snapshots.csv"))
        .arg("--params")
        .arg(params)
        .arg("--out")
        .arg(dir.join("pred.csv")))
}

#[test]
fn a_report_of_another_schema_is_refused() {
    let dir = tmp("schema");
    let report = dir.join("report.json");
    let simulate_with = |text: &str| simulate_with_params(&dir, &report, text);
    let o = simulate_with(
        r#"{ "schema": "kalibre.report/9", "best": { "params": { "alpha/web": 0.13 } } }"#,
    );
    assert_input_error(
        &o,
        "/schema: expected \"kalibre.report/1\", found \"kalibre.report/9\"",
    );
    // An edited model record is blamed, not a --grid-m that was never given.
    let o = simulate_with(
        r#"{ "schema": "kalibre.report/1", "best": { "params": { "alpha/web": 0.13 } },
             "model": { "kind": "builtin", "grid_m": -0.2, "alpha": "per_type" } }"#,
    );
    assert_input_error(
        &o,
        "report.json: /model/grid_m: -0.2 is not a cell size in m",
    );
}

#[test]
fn a_parameter_named_twice_is_refused() {
    let dir = tmp("twice");
    // serde_json alone would keep 0.2 without a word.
    let o = simulate_with_params(
        &dir,
        &dir.join("params.json"),
        r#"{ "alpha/web": 0.1, "alpha/web": 0.2 }"#,
    );
    assert_input_error(&o, "params.json: /: key `alpha/web` appears twice");
    assert!(!dir.join("pred.csv").exists());
}

#[test]
fn a_journal_line_no_hall_model_could_give_is_named_on_resume() {
    let dir = tmp("journal-edit");
    let out = dir.join("cal");
    let calibrate = || {
        run(kalibre()
            .args([
                "calibrate",
                "--iterations",
                "1",
                "--no-grid-check",
                "--hall",
            ])
            .arg(data("of-dev-clean/hall.json"))
            .arg("--snapshots")
            .arg(data("of-dev-clean/snapshots.csv"))
            .arg("--out")
            .arg(&out))
    };
    assert_eq!(calibrate().status.code(), Some(0));
    let journal = out.join("runs.jsonl");
    let text = std::fs::read_to_string(&journal).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let k = lines
        .iter()
        .position(|l| l.contains(r#""status":"ok""#))
        .expect("an ok run");
    let mut run: serde_json::Value = serde_json::from_str(&lines[k]).unwrap();
    let n = run["outputs"].as_array().unwrap().len();
    // Finite, so the record parses; a sensor at 1e308 C would reach the surrogate as NaN.
    run["outputs"] = serde_json::json!(vec![1e308; n]);
    lines[k] = run.to_string();
    std::fs::write(&journal, lines.join("\n") + "\n").unwrap();
    let o = calibrate();
    assert_input_error(&o, &format!("runs.jsonl: line {}", k + 1));
    assert_input_error(&o, "is implausible: 1e308 (beyond +/-1e150");
    // A line that is not a record at all is skipped and its run done again, with a word.
    lines[k] = "{not json".into();
    std::fs::write(&journal, lines.join("\n") + "\n").unwrap();
    let o = calibrate();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    let warning = format!("1 unreadable line(s) skipped (line {}:", k + 1);
    assert!(
        err.contains("kalibre: warning: ") && err.contains(&warning),
        "{err}"
    );
}

#[test]
fn flags_that_cannot_apply_are_refused_before_any_output() {
    let dir = tmp("early");
    let hall = data("of-dev-clean/hall.json");
    let snaps = data("of-dev-clean/snapshots.csv");
    // A bad --grid-check factor used to be found after pred.csv was written.
    let o = run(kalibre()
        .args(["simulate", "--grid-check", "2", "--hall"])
        .arg(&hall)
        .arg("--snapshots")
        .arg(&snaps)
        .arg("--out")
        .arg(dir.join("pred.csv")));
    assert_input_error(&o, "--grid-check: 2 is not a finer grid");
    assert!(!dir.join("pred.csv").exists());
    // In (0, 1) but no check: the model's own grid, or one too fine to build.
    for (factor, why) in [
        ("0.999999", "the model's own cells in this room"),
        ("1e-9", "above the built-in simulator's 30000000"),
    ] {
        let o = run(kalibre()
            .args(["calibrate", "--grid-check", factor, "--hall"])
            .arg(&hall)
            .arg("--snapshots")
            .arg(&snaps)
            .arg("--out")
            .arg(dir.join("cal")));
        assert_input_error(&o, why);
    }
    assert!(!dir.join("cal").join("runs.jsonl").exists());
    // An unwritable --write-hall used to be found after the diagnosis's solves.
    let o = run(diagnose_cmd(&hall, &snaps, &dir.join("no-calibration"))
        .arg("--write-hall")
        .arg(&dir));
    assert_input_error(&o, "--write-hall");
    assert_input_error(&o, "is a directory");
    // A command model meshes for itself: --grid-m would be ignored.
    let o = run(kalibre()
        .args([
            "calibrate",
            "--model",
            "command",
            "--grid-m",
            "0.1",
            "--config",
        ])
        .arg(dir.join("model.toml"))
        .arg("--hall")
        .arg(&hall)
        .arg("--snapshots")
        .arg(&snaps)
        .arg("--out")
        .arg(dir.join("cal")));
    assert_input_error(
        &o,
        "--grid-m sets the grid of the built-in simulator or OpenFOAM",
    );
    // Air at billions of degrees (fans all but stopped) is no prediction: refused before
    // any solve, by the what-if that asks for it.
    let o = run(kalibre()
        .args(["simulate", "--fan-speed-scale", "1e-9", "--hall"])
        .arg(&hall)
        .arg("--snapshots")
        .arg(&snaps)
        .arg("--out")
        .arg(dir.join("pred.csv")));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("what if fan speeds x1e-9: snapshot `t0`")
            && err.contains("past any temperature a model of the hall can give"),
        "{err}"
    );
    assert!(!dir.join("pred.csv").exists());
}

#[test]
fn a_diagnosis_of_other_inputs_than_the_calibrations_is_refused() {
    let dir = tmp("other-inputs");
    let cal = dir.join("cal");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(QUICK_CALIBRATION)
        .arg("--out")
        .arg(&cal));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let report_path = cal.join("report.json");
    let read_report = || -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap()
    };
    // One server's power edited under the same label, the readings as they were: the
    // model would run at conditions it was never fitted at (this diagnosed a 4.97 C MAE
    // and a significant effect, exit 0). The report's keys tell, and without them the
    // journal's.
    let snaps = data("of-dev-clean/snapshots.csv");
    let text = std::fs::read_to_string(&snaps).unwrap();
    let powered = text.replacen("t0,power_w,A1-01,2540", "t0,power_w,A1-01,5080", 1);
    assert_ne!(powered, text);
    let edited_snaps = dir.join("powered.csv");
    std::fs::write(&edited_snaps, powered).unwrap();
    // `diagnose` of this calibration, with these inputs and flags.
    let diagnose = |hall: &Path, snapshots: &Path, flags: &[&str]| {
        run(kalibre()
            .args(["diagnose", "--hall"])
            .arg(hall)
            .arg("--snapshots")
            .arg(snapshots)
            .arg("--calibration")
            .arg(&cal)
            .args(flags))
    };
    let hall = data("of-dev-clean/hall.json");
    let diagnose_at = |snapshots: &Path| diagnose(&hall, snapshots, &[]);
    let conditions = "powered.csv: snapshot `t0`: its setpoints, fan speeds or powers are not \
                      those the calibration ran at";
    let o = diagnose_at(&edited_snaps);
    assert_input_error(&o, conditions);
    assert!(stderr(&o).contains("report.json"), "{}", stderr(&o));
    let mut report = read_report();
    assert!(
        report["model"]["scenario_keys"]["t0"].is_string(),
        "{report}"
    );
    report["model"]
        .as_object_mut()
        .unwrap()
        .remove("scenario_keys");
    std::fs::write(&report_path, report.to_string()).unwrap();
    let o = diagnose_at(&edited_snaps);
    assert_input_error(&o, conditions);
    assert!(stderr(&o).contains("runs.jsonl"), "{}", stderr(&o));
    // A line of the journal that is not JSON is named, not passed over.
    let journal = cal.join("runs.jsonl");
    let runs = std::fs::read_to_string(&journal).unwrap();
    std::fs::write(&journal, format!("{runs}not a record\n")).unwrap();
    let o = diagnose_at(&edited_snaps);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let line = runs.lines().count() + 1;
    assert!(
        err.contains(&format!("1 line(s) are not JSON (first: line {line})")),
        "{err}"
    );
    std::fs::write(&journal, runs).unwrap();
    // The report's values are read by name (a tool that rewrites it may reorder them);
    // one deleted is named, by diagnose and by simulate --params alike, never taken from
    // the hall's initial values.
    let kept = std::fs::read_to_string(&report_path).unwrap();
    let mut report = read_report();
    report["best"]["params"]
        .as_object_mut()
        .unwrap()
        .remove("alpha/db");
    std::fs::write(&report_path, report.to_string()).unwrap();
    let missing = "report.json: /best/params: no value of `alpha/db`";
    assert_input_error(&diagnose_at(&snaps), missing);
    let o = run(kalibre()
        .args(["simulate", "--hall"])
        .arg(&hall)
        .arg("--snapshots")
        .arg(&snaps)
        .arg("--params")
        .arg(&report_path)
        .arg("--out")
        .arg(dir.join("pred.csv")));
    assert_input_error(&o, missing);
    assert!(!dir.join("pred.csv").exists());
    // A residual row of a sensor the hall lacks is the report's, not the snapshots'.
    let mut report = read_report();
    report["residuals"][0]["sensor"] = "zz".into();
    std::fs::write(&report_path, report.to_string()).unwrap();
    assert_input_error(
        &diagnose_at(&snaps),
        "report.json: /residuals: sensor `zz` is not in hall",
    );
    std::fs::write(&report_path, kept).unwrap();
    // Without the journal, the report's record of the model still names the hall it ran.
    std::fs::remove_file(cal.join("runs.jsonl")).unwrap();
    let text = std::fs::read_to_string(&hall).unwrap();
    let mut edited_hall: serde_json::Value = serde_json::from_str(&text).unwrap();
    let flow = edited_hall["cracs"][0]["rated_flow_m3_s"].as_f64().unwrap();
    edited_hall["cracs"][0]["rated_flow_m3_s"] = (1.1 * flow).into();
    let edited = dir.join("hall.json");
    std::fs::write(&edited, edited_hall.to_string()).unwrap();
    let o = diagnose(&edited, &snaps, &[]);
    assert_input_error(&o, "report.json: /model/fingerprint: runs of another model");
    // One reading moved by half a degree.
    let text = std::fs::read_to_string(&snaps).unwrap();
    let moved = text.replacen(
        "t0,sensor_c,c-A1-hi,17.833",
        "t0,sensor_c,c-A1-hi,18.333",
        1,
    );
    assert_ne!(moved, text);
    let other = dir.join("snapshots.csv");
    std::fs::write(&other, moved).unwrap();
    let o = diagnose(&hall, &other, &[]);
    assert_input_error(
        &o,
        "snapshot `t0`, sensor `c-A1-hi` reads 18.333 C, the calibration's 17.833 C",
    );
    // A recorded grid too fine for the room is blamed on the record, not on a flag.
    let mut report = read_report();
    report["model"]["grid_m"] = 0.001.into();
    std::fs::write(&report_path, report.to_string()).unwrap();
    let o = diagnose(&hall, &snaps, &[]);
    assert_input_error(&o, "report.json: /model/grid_m: cells of 0.001 m need");
    // A --write-hall nothing can be written in, before any solve.
    let o = diagnose(&hall, &snaps, &["--write-hall", "/proc/kalibre/hall.json"]);
    assert_input_error(
        &o,
        "--write-hall /proc/kalibre/hall.json: cannot write in /proc",
    );
    // An existing file that opens for writing but cannot be replaced (the hall is written
    // beside it and renamed): refused before the solves too, not after them.
    let o = diagnose(&hall, &snaps, &["--write-hall", "/proc/version"]);
    assert_input_error(&o, "--write-hall /proc/version: cannot write in /proc");
}
