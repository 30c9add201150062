//! End-to-end tests of the `kalibre` command-line tool on the small OpenFOAM development
//! hall shipped in `data/openfoam` (24 sensors, 3 snapshots, about 11k cells at 0.2 m).

mod cli_support;

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use cli_support::{
    assert_each_run_once, assert_input_error, data, kalibre, on_dataset, on_files, run, stderr, tmp,
};

/// `kalibre simulate` on a hall and snapshots, with optional parameters.
fn simulate(hall: &Path, snaps: &Path, params: Option<&Path>, out: &Path) -> Output {
    let mut c = on_files("simulate", hall, snaps);
    c.arg("--out").arg(out);
    if let Some(p) = params {
        c.arg("--params").arg(p);
    }
    run(&mut c)
}

#[test]
fn bad_inputs_give_one_line_and_exit_code_2() {
    let dir = tmp("bad");
    let hall = data("of-dev-clean/hall.json");
    let snaps = data("of-dev-clean/snapshots.csv");
    let out = dir.join("pred.csv");
    // A missing hall file.
    let o = simulate(Path::new("/nonexistent/hall.json"), &snaps, None, &out);
    assert_input_error(&o, "/nonexistent/hall.json");
    // A malformed hall: a negative rated flow.
    let bad_hall = dir.join("bad-hall.json");
    let text = std::fs::read_to_string(&hall).unwrap().replacen(
        "\"rated_flow_m3_s\": 3.95",
        "\"rated_flow_m3_s\": -1",
        1,
    );
    std::fs::write(&bad_hall, text).unwrap();
    let o = simulate(&bad_hall, &snaps, None, &out);
    assert_input_error(&o, "/cracs/0/rated_flow_m3_s");
    // An unknown parameter in --params.
    let params = dir.join("params.json");
    std::fs::write(&params, r#"{ "alpha/nosuchtype": 0.1 }"#).unwrap();
    let o = simulate(&hall, &snaps, Some(&params), &out);
    assert_input_error(&o, "alpha/nosuchtype");
    // A parameter outside its bounds.
    std::fs::write(&params, r#"{ "alpha/web": 7.5 }"#).unwrap();
    let o = simulate(&hall, &snaps, Some(&params), &out);
    assert_input_error(&o, "alpha/web");
    for (flags, needle) in [
        // A negative grid size.
        (&["--grid-m=-0.2"][..], "--grid-m"),
        // A Student-t likelihood with no degrees of freedom.
        (
            &["--likelihood", "student-t", "--nu", "0"][..],
            "--nu: expected a finite number >= 1 (1 is the Cauchy",
        ),
        // Degrees of freedom without the Student-t likelihood (calibrate's default is
        // least squares) would be ignored: refused.
        (
            &["--nu", "2"][..],
            "--nu is the Student-t likelihood's degrees of freedom",
        ),
        // Edges from the built-in simulator's flow asked of another model.
        (
            &["--model", "openfoam", "--influence-edges"][..],
            "--influence-edges",
        ),
    ] {
        let o = run(on_files("calibrate", &hall, &snaps)
            .args(flags)
            .arg("--out")
            .arg(dir.join("cal")));
        assert_input_error(&o, needle);
    }
    // Only given parameters (alpha fixed, an effect of equal bounds): nothing to calibrate.
    let text = std::fs::read_to_string(&hall).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    doc["effects"] = serde_json::json!([
        { "kind": "crac_supply_offset", "offset_c": 0.5, "offset_c_bounds": [0.5, 0.5] }
    ]);
    let given = dir.join("given.json");
    std::fs::write(&given, doc.to_string()).unwrap();
    let o = run(on_files("calibrate", &given, &snaps)
        .args(["--alpha", "fixed", "--out"])
        .arg(dir.join("cal")));
    assert_input_error(
        &o,
        "has nothing to calibrate: every parameter has equal bounds (crac_supply_offset/offset_c)",
    );
    assert!(!dir.join("cal").join("runs.jsonl").exists());
    // Snapshots of another hall: an unknown id.
    let bad_snaps = dir.join("snaps.csv");
    std::fs::write(
        &bad_snaps,
        "snapshot,kind,id,value\nt0,setpoint_c,crac-9,18\n",
    )
    .unwrap();
    let o = run(kalibre()
        .args(["calibrate", "--hall"])
        .arg(&hall)
        .arg("--snapshots")
        .arg(&bad_snaps)
        .arg("--out")
        .arg(dir.join("cal")));
    assert_input_error(&o, "crac-9");
    // An unknown preset.
    let o = run(kalibre()
        .args(["synth", "--preset", "hall-z", "--out"])
        .arg(dir.join("synth")));
    assert_input_error(&o, "hall-z");
}

fn journal_lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .map(str::to_owned)
        .collect()
}

fn calibrate_cmd(out: &Path) -> Command {
    let mut c = kalibre();
    c.args([
        "calibrate",
        "--iterations",
        "3",
        "--seed",
        "7",
        "--threads",
        "1",
        "--hall",
    ])
    .arg(data("of-dev-clean/hall.json"))
    .arg("--snapshots")
    .arg(data("of-dev-clean/snapshots.csv"))
    .arg("--out")
    .arg(out);
    c
}

/// Killing `kalibre calibrate` mid-run and starting it again repeats no finished model run,
/// and the resumed calibration ends where an uninterrupted one does.
#[test]
fn calibrate_resumes_after_kill_without_repeating_runs() {
    let whole = tmp("whole");
    let o = run(&mut calibrate_cmd(&whole));
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["schema"], "kalibre.report/1");
    let total = report["runs"]["total"].as_u64().unwrap() as usize;
    assert!(
        total >= 12,
        "initial design of 4 points x 3 snapshots at least"
    );
    assert!(whole.join("report.html").exists());
    let html = std::fs::read_to_string(whole.join("report.html")).unwrap();
    assert!(html.contains("<svg") && html.contains("Where the model fails"));
    // The calibrated model's server intakes, and a headroom the misfit at the row-end
    // inlets (which the built-in model reads colder than OpenFOAM) takes down.
    assert!(html.contains("<h2>Server intakes</h2>"));
    assert_eq!(
        html.matches(" of 20 above 27.0 C").count(),
        3,
        "one row per snapshot"
    );
    assert!(
        html.contains("headroom less the misfit at c-"),
        "row-end under-read"
    );
    // Which racks warm each sensor in the calibrated model's flow: a hot-aisle sensor's
    // own rack first; no exhaust at a row-end low inlet, which OpenFOAM's recirculation
    // round the row end warms.
    assert!(html.contains("<th>warmed by, in the model</th>"));
    let row = |sensor: &str| {
        let start = html.find(&format!("<tr><td>{sensor}</td>")).unwrap();
        let end = start + html[start..].find("</tr>").unwrap();
        html[start..end].to_string()
    };
    assert!(row("h-B4").contains(" K: B4 "), "{}", row("h-B4"));
    assert!(
        row("c-A1-lo").ends_with("<td>no exhaust</td>"),
        "{}",
        row("c-A1-lo")
    );
    // The default likelihood is the paper's, and the report says so.
    assert!(report["settings"].get("robust_nu").is_none());
    assert!(html.contains("<td>likelihood</td><td>least squares"));
    // The report says how well the measurements pin down each parameter, and so does the
    // summary and the HTML.
    let params = report["best"]["params"].as_object().unwrap();
    let uncertainty = report["uncertainty"].as_array().unwrap();
    assert_eq!(uncertainty.len(), params.len());
    for u in uncertainty {
        assert!(params.contains_key(u["name"].as_str().unwrap()));
        assert!(u["identified"].is_boolean());
        // Where the measurements point from the best run; identified implies settled.
        let shift = u["shift"].as_f64().expect("a finite shift");
        if u["identified"] == true {
            assert!(shift.abs() <= 2.0 * u["std"].as_f64().unwrap(), "{u}");
        }
    }
    assert!(String::from_utf8_lossy(&o.stdout).contains("parameters identified"));
    assert!(html.contains("one standard deviation (linearised)"));
    // The built-in model's polish measured the model's own slopes at the best run, and the
    // spreads say so.
    assert_eq!(report["uncertainty_slopes"], "model_finite_differences");
    assert!(String::from_utf8_lossy(&o.stdout).contains("slopes of the spreads"));
    assert!(html.contains("Spreads linearised with the model's finite differences"));
    // The built-in model ran once per snapshot on two finer grids at the best run; how far
    // that moves each parameter is reported beside its spread.
    let checks = report["numerical_checks"].as_array().expect("grid checks");
    assert_eq!(checks.len(), 2, "{checks:?}");
    for c in checks {
        assert!(c["variant"].as_str().unwrap().starts_with("grid "), "{c}");
        assert!(c["mean_abs_change"].as_f64().unwrap() > 0.0, "{c}");
    }
    assert!(uncertainty
        .iter()
        .all(|u| u["numerical"].as_f64().is_some()));
    assert!(String::from_utf8_lossy(&o.stdout).contains("numerics (at the best run)"));
    assert!(html.contains("move from the model's numerics"));
    // The polish weighed each reading by how far the grids move it: every residual
    // carries its weight, in (0, 1], and the summary says how many counted less.
    assert_eq!(report["settings"]["numerical_weighting"], true);
    let residuals = report["residuals"].as_array().unwrap();
    assert!(residuals
        .iter()
        .all(|r| r["weight"].as_f64().is_some_and(|w| w > 0.0 && w <= 1.0)));
    assert!(String::from_utf8_lossy(&o.stdout).contains("grid weighting (polish)"));
    // The least setpoint headroom over the snapshots, with the misfit taken off.
    let stdout = String::from_utf8_lossy(&o.stdout);
    let line = stdout
        .lines()
        .find(|l| l.contains("server intakes (model)"))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(
        line.contains("setpoint headroom") && line.contains("the model under-reads c-"),
        "{line}"
    );
    assert!(html.contains("weighed by how far the finer grids move it"));

    // Start again, kill once a few runs are journaled, then resume.
    let cut = tmp("cut");
    let journal = cut.join("runs.jsonl");
    let mut child = calibrate_cmd(&cut).spawn().unwrap();
    let start = Instant::now();
    while journal_lines(&journal).len() < 5 && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let done_before = journal_lines(&journal)
        .iter()
        .filter(|l| serde_json::from_str::<serde_json::Value>(l).is_ok())
        .count();
    assert!(
        done_before >= 5 && done_before < total,
        "killed mid-run ({done_before} of {total})"
    );
    let o = run(&mut calibrate_cmd(&cut));
    assert!(o.status.success(), "{}", stderr(&o));
    let resumed: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cut.join("report.json")).unwrap()).unwrap();
    // A calibration may itself meet a point it already ran (the polish stage's
    // finite-difference step can land on a geometry step of the loop): the journal
    // replays those in the uninterrupted run too.
    let replayed_in_whole = report["runs"]["cached"].as_u64().unwrap() as usize;
    assert_eq!(
        resumed["runs"]["cached"].as_u64().unwrap() as usize,
        done_before + replayed_in_whole
    );
    assert_eq!(
        resumed["runs"]["new"].as_u64().unwrap() as usize,
        total - done_before - replayed_in_whole,
        "no finished run is repeated"
    );
    assert_eq!(
        resumed["best"], report["best"],
        "same result as the uninterrupted run"
    );
    assert_eq!(resumed["uncertainty"], report["uncertainty"]);
    // Each (snapshot, parameters) appears once in the journal.
    let runs: Vec<serde_json::Value> = journal_lines(&journal)
        .iter()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    assert_eq!(assert_each_run_once(&runs), total - replayed_in_whole);
}

/// Ctrl-C in a calibration of the built-in model (no external run to end) ends it as
/// SIGINT does, and says where the finished runs are and that the same command resumes.
#[cfg(target_os = "linux")]
#[test]
fn ctrl_c_says_where_the_finished_runs_are() {
    use std::os::unix::process::ExitStatusExt;
    let out = tmp("ctrl-c");
    let journal = out.join("runs.jsonl");
    let child = calibrate_cmd(&out)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while journal_lines(&journal).len() < 3 && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(20));
    }
    // SAFETY: signalling a child this test started and has not reaped.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.signal(), Some(libc::SIGINT), "{o:?}");
    assert!(
        stderr(&o).contains(&format!(
            "kalibre: stopped; finished model runs are kept in {}: the same command resumes \
             from there, repeating no successful run",
            journal.display()
        )),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(out);
}

/// Without the polish, the spreads come from a local fit of the model's own runs (the
/// loop's runs near the best one spread enough in every direction on this hall), and a
/// model error that repeats at the same sensors is reported and warned about.
#[test]
fn without_the_polish_the_spreads_fit_the_models_runs_and_a_repeated_error_is_flagged() {
    let out = tmp("no-polish");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--polish", "0", "--seed", "1", "--threads", "1", "--out"])
        .arg(&out));
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["uncertainty_slopes"], "model_runs");
    // The built-in model against OpenFOAM data: its row-end errors recur in every snapshot.
    let icc = report["residual_icc"].as_f64().expect("three snapshots");
    assert!(icc > 0.5, "{icc}");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("a local linear fit of the model's runs"),
        "{stdout}"
    );
    assert!(stdout.contains("repeats at the same sensors"), "{stdout}");
    let _ = std::fs::remove_dir_all(out);
}

/// `kalibre diagnose --json` prints the `kalibre.diagnosis/1` schema, and a calibration
/// of another hall is refused with a clear message.
#[test]
fn diagnose_prints_json_and_refuses_another_halls_calibration() {
    let dir = tmp("diagnose");
    let cal = dir.join("cal");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--iterations", "1"])
        .arg("--out")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--json"])
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(d["schema"], "kalibre.diagnosis/1");
    assert!(d["mae_c"].as_f64().is_some_and(|m| m > 0.0));
    let hyps = d["hypotheses"].as_array().unwrap();
    assert!(!hyps.is_empty());
    assert!(d["unexplained_sensors"].is_array(), "{d}");
    for h in hyps {
        for key in [
            "effect",
            "explained_fraction",
            "predicted_mae_c",
            "significant",
            "refuted_by_model_runs",
            "inert",
            "identifiable",
            "in_range",
        ] {
            assert!(!h[key].is_null(), "{key} missing in {h}");
        }
        // An entry only where the fit is within its range: one outside it would do
        // nothing.
        if h["in_range"] == true {
            assert_eq!(h["suggestion"]["kind"], h["effect"], "{h}");
        } else {
            assert!(h["suggestion"].is_null(), "{h}");
        }
        // A fit outside its parameter's range is never significant.
        let fitted = h["fitted"].as_object().expect("fitted");
        assert!(!fitted.is_empty(), "{h}");
        if h["in_range"] == false {
            assert_eq!(h["significant"], false, "{h}");
        }
    }
    // The worst sensors, worst first, each with the racks that warm it in the built-in
    // model's flow; a rack's part of the warming is its share of the whole.
    let worst = d["worst_sensors"].as_array().expect("worst_sensors");
    assert_eq!(worst.len(), 5, "{d}");
    let residuals: Vec<f64> = worst
        .iter()
        .map(|w| w["mean_residual_c"].as_f64().unwrap().abs())
        .collect();
    assert!(residuals.windows(2).all(|p| p[0] >= p[1]), "{residuals:?}");
    for w in worst {
        assert!(w["sensor"].as_str().is_some_and(|s| !s.is_empty()), "{w}");
        assert_eq!(w["position_m"].as_array().map(Vec::len), Some(3), "{w}");
        let Some(warming) = w.get("warming") else {
            panic!("no `warming` with the built-in model: {w}");
        };
        if warming.is_null() {
            continue;
        }
        let total_k = warming["warming_k"].as_f64().unwrap();
        assert!(total_k > 0.0, "{w}");
        let mut parts_k = 0.0;
        for r in warming["racks"].as_array().unwrap() {
            let (part_k, share) = (
                r["warming_k"].as_f64().unwrap(),
                r["share"].as_f64().unwrap(),
            );
            assert!((0.1..=1.0).contains(&share), "{w}");
            assert!(
                (part_k - share * total_k).abs() < 1e-9 * total_k.max(1.0),
                "{w}"
            );
            parts_k += part_k;
        }
        assert!(parts_k <= total_k * (1.0 + 1e-9), "{w}");
    }
    // `--refit 1` runs the leading hypothesis with the model and says what it ran.
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--json", "--refit", "1", "--refit-iterations", "2"])
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    let refits = d["refits"].as_array().expect("refits");
    assert_eq!(refits.len(), 1, "{d}");
    let steps = refits[0]["steps"].as_array().unwrap();
    assert!((1..=2).contains(&steps.len()), "{d}");
    for s in steps {
        assert!(s["model_mae_c"].as_f64().is_some_and(|m| m > 0.0), "{s}");
        assert!(
            s["effect_value"].as_f64().is_some_and(f64::is_finite),
            "{s}"
        );
    }
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--refit", "1", "--refit-iterations", "0"])
        .arg("--calibration")
        .arg(&cal));
    assert_input_error(&o, "--refit-iterations: must be at least 1 with --refit");
    // The same hall under another name is the same model (the fingerprint leaves the
    // name out): it passes the model check and reaches the next one, here a bad --nu,
    // which comes after it.
    let o = run(kalibre()
        .args(["diagnose", "--nu", "0", "--hall"])
        .arg(data("of-dev-crac-offset/hall.json"))
        .arg("--snapshots")
        .arg(data("of-dev-clean/snapshots.csv"))
        .arg("--calibration")
        .arg(&cal));
    assert_input_error(&o, "--nu: expected a finite number >= 1");
    // And other measurements are not the calibration's.
    let o = run(on_dataset("diagnose", "of-dev-crac-offset")
        .arg("--calibration")
        .arg(&cal));
    assert_input_error(&o, "not the measurements");
    // A Student-t with no degrees of freedom is no likelihood, and with too few (0.05)
    // every hypothesis "explains" everything: both refused, as is --nu with the
    // Gaussian likelihood, which would ignore it.
    for (args, needle) in [
        (&["--nu", "0"][..], "--nu: expected a finite number >= 1"),
        (&["--nu", "0.05"][..], "got 0.05"),
        (
            &["--likelihood", "gaussian", "--nu", "2"][..],
            "--nu is the Student-t likelihood's",
        ),
    ] {
        let o = run(on_dataset("diagnose", "of-dev-clean")
            .args(args)
            .arg("--calibration")
            .arg(&cal));
        assert_input_error(&o, needle);
    }
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--sensor-bias-rival", "nan"])
        .arg("--calibration")
        .arg(&cal));
    assert_input_error(&o, "--sensor-bias-rival: must be finite and >= 0, got NaN");
    // OpenFOAM's options belong to --model openfoam.
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--np", "2"])
        .arg("--calibration")
        .arg(&cal));
    assert_input_error(&o, "--np is an OpenFOAM option: add --model openfoam");
}

/// `report.json` records the model the calibration ran (its grid and alpha mode), and
/// `diagnose` and `simulate --params report.json` run that model without being told again.
#[test]
fn diagnose_and_simulate_run_the_model_the_calibration_recorded() {
    let dir = tmp("recorded");
    let cal = dir.join("cal");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--iterations", "1", "--polish", "0", "--grid-m", "0.25"])
        .args(["--alpha", "per-server", "--out"])
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let report_path = cal.join("report.json");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    let mut model = report["model"].clone();
    let fingerprint = model["fingerprint"].take();
    // Each snapshot's conditions, so that diagnose can refuse edited ones.
    let keys = model
        .as_object_mut()
        .unwrap()
        .remove("scenario_keys")
        .unwrap();
    for label in ["t0", "t1", "t2"] {
        assert!(
            keys[label].as_str().is_some_and(|k| k.len() == 32),
            "{keys}"
        );
    }
    assert!(
        fingerprint
            .as_str()
            .is_some_and(|f| f.starts_with("kalibre-dc-sim/")),
        "{fingerprint}"
    );
    assert_eq!(
        model,
        serde_json::json!({ "kind": "builtin", "grid_m": 0.25, "alpha": "per_server",
            "fingerprint": null })
    );
    // Without --grid-m or --alpha: the calibration's grid and per-server parameters.
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--json")
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let pred = dir.join("pred.csv");
    let o = run(on_dataset("simulate", "of-dev-clean")
        .arg("--params")
        .arg(&report_path)
        .arg("--out")
        .arg(&pred));
    assert!(o.status.success(), "{}", stderr(&o));
    // The predictions are the calibration's best run: same model, same parameters.
    let csv = std::fs::read_to_string(&pred).unwrap();
    let residuals = report["residuals"].as_array().unwrap();
    assert_eq!(residuals.len(), 3 * 24);
    for r in residuals {
        let row = format!(
            "{},sensor_c,{},",
            r["snapshot"].as_str().unwrap(),
            r["sensor"].as_str().unwrap()
        );
        let line = csv.lines().find(|l| l.starts_with(&row)).unwrap();
        let v: f64 = line.rsplit(',').next().unwrap().parse().unwrap();
        let p = r["predicted_c"].as_f64().unwrap();
        assert!((v - p).abs() < 1e-9, "{row}: {v} against {p}");
    }
    // A grid given again wins, and then it is another model than the one calibrated.
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--grid-m", "0.2", "--calibration"])
        .arg(&cal));
    assert_input_error(&o, "/model/fingerprint: runs of another model");
    // A built-in calibration is not diagnosed with OpenFOAM, before anything runs.
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .args(["--model", "openfoam", "--calibration"])
        .arg(&cal));
    assert_input_error(
        &o,
        "the calibration ran the builtin model; diagnose it with --model builtin",
    );
    // A record that does not parse is named.
    let mut bad = report.clone();
    bad["model"]["kind"] = serde_json::json!(7);
    std::fs::write(&report_path, serde_json::to_string(&bad).unwrap()).unwrap();
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--calibration")
        .arg(&cal));
    assert_input_error(&o, "report.json: /model: not a kalibre model record");
}

/// `kalibre diagnose --write-hall` writes the hall with the top significant suggestion
/// added and warm-started at the calibrated values, which `kalibre calibrate` takes as it
/// is; with nothing significant it writes nothing and says so.
#[test]
fn diagnose_writes_the_next_hall() {
    let dir = tmp("next-hall");
    let cal = dir.join("cal");
    let o = run(on_dataset("calibrate", "of-dev-crac-offset")
        .arg("--out")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let next = dir.join("next").join("hall.json");
    let o = run(on_dataset("diagnose", "of-dev-crac-offset")
        .arg("--json")
        .arg("--calibration")
        .arg(&cal)
        .arg("--write-hall")
        .arg(&next));
    assert!(o.status.success(), "{}", stderr(&o));
    // stdout stays one JSON document; the file is announced on stderr.
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert!(
        stderr(&o).contains("crac_supply_offset added"),
        "{}",
        stderr(&o)
    );
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&next).unwrap()).unwrap();
    let effects = written["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1);
    assert_eq!(effects[0], d["hypotheses"][0]["suggestion"]);
    // Warm start at the diagnosis's fit: every type's initial alpha is the calibrated one
    // moved by the joint refit beside the effect, within its bounds.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cal.join("report.json")).unwrap()).unwrap();
    let change = &d["hypotheses"][0]["current_change"];
    let mut moved = 0;
    for t in written["server_types"].as_array().unwrap() {
        let name = format!("alpha/{}", t["id"].as_str().unwrap());
        let calibrated = report["best"]["params"][&name].as_f64().unwrap();
        let bounds = &t["alpha_cfm_per_w"];
        let (lo, hi) = (
            bounds["min"].as_f64().unwrap(),
            bounds["max"].as_f64().unwrap(),
        );
        let dp = change[&name].as_f64().unwrap_or(0.0);
        let initial = bounds["initial"].as_f64().unwrap();
        assert!(
            (initial - (calibrated + dp).clamp(lo, hi)).abs() < 1e-12,
            "{name}"
        );
        moved += usize::from((initial - calibrated).abs() > 1e-6);
    }
    assert!(moved > 0, "the refit moved no alpha: {change}");
    let o = run(kalibre()
        .args(["calibrate", "--iterations", "1", "--polish", "1"])
        .args(["--likelihood", "student-t", "--hall"])
        .arg(&next)
        .arg("--snapshots")
        .arg(data("of-dev-crac-offset/snapshots.csv"))
        .arg("--out")
        .arg(dir.join("cal-next")));
    assert!(o.status.success(), "{}", stderr(&o));
    // Started there, the hall with the effect already reads better than the calibrated
    // model without it, as the diagnosis predicted.
    let next_report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("cal-next").join("report.json")).unwrap(),
    )
    .unwrap();
    let start = next_report["initial"]["mae_c"].as_f64().unwrap();
    let calibrated = report["best"]["mae_c"].as_f64().unwrap();
    let predicted = d["hypotheses"][0]["predicted_mae_c"].as_f64().unwrap();
    assert!(
        start < calibrated,
        "next hall at {start:.3} C, calibrated {calibrated:.3} C, predicted {predicted:.3} C"
    );
    // The clean hall: nothing significant, nothing written.
    let cal = dir.join("cal-clean");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .arg("--out")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let none = dir.join("none.json");
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--calibration")
        .arg(&cal)
        .arg("--write-hall")
        .arg(&none));
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("nothing significant:"), "{out}");
    assert!(!none.exists());
    // Each worst sensor is followed by which racks warm it in the calibrated model's flow.
    // The worst here are the row-end low cold-aisle sensors, which OpenFOAM's
    // recirculation warms and no exhaust reaches in the built-in model.
    let lines: Vec<&str> = out.lines().collect();
    let worst: Vec<usize> = (0..lines.len())
        .filter(|&i| lines[i].contains(" aisle at (") && lines[i].contains("the model reads"))
        .collect();
    assert_eq!(worst.len(), 5, "{out}");
    for &i in &worst {
        let next = lines[i + 1];
        assert!(
            next.contains("in the model, exhausts warm it by")
                || next.contains("no exhaust reaches it in the model"),
            "{}\n{next}",
            lines[i]
        );
    }
    assert!(
        out.contains("the measured warmth takes a path the model lacks"),
        "{out}"
    );
}
