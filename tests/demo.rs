//! End-to-end: `kalibre demo` tells the whole story on the embedded `demo` hall with a
//! hidden effect (the built binary, as a user runs it).

use std::path::PathBuf;
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kalibre-demo-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn demo_names_the_hidden_effect_and_the_error_falls() {
    let out = tmp("default");
    // An earlier, longer story's files: none of them may sit beside the new story. A
    // file of the user's stays.
    std::fs::create_dir_all(out.join("step-7")).unwrap();
    for stale in ["step-7/report.json", "diagnosis-5.json", "notes.txt"] {
        std::fs::write(out.join(stale), "{}").unwrap();
    }
    let o = Command::new(env!("CARGO_BIN_EXE_kalibre"))
        .args(["demo", "--out"])
        .arg(&out)
        .output()
        .expect("the kalibre binary runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "stdout:\n{stdout}\nstderr:\n{stderr}");

    // The steps and the summary are printed, with the report's path.
    for needle in [
        "step 1: calibrate alpha",
        "diagnose where the calibrated model fails",
        "suggested entry for hall.json \"effects\"",
        "summary",
        "report.html",
        // Steps count calibrations, as the step-K/ folders and report.html do; each
        // diagnosis is named after the step it diagnoses.
        "step 2: add rack_recirculation(rack=A05), recalibrate",
        "diagnosis after step 1: diagnose where the calibrated model fails",
        "diagnosis after step 2: diagnose where the calibrated model fails",
        "each step's report.json in step-1/, step-2/",
        // The order is the BIC's, and the header says so.
        "missing effects, best first: the significant ones, then the others, each in order of `BIC`",
    ] {
        assert!(stdout.contains(needle), "`{needle}` not in:\n{stdout}");
    }
    assert!(!stdout.contains("step 3"), "{stdout}");
    // The summary numbers the calibrations as report.html does (`1. calibrate alpha`).
    assert!(
        stdout
            .lines()
            .any(|l| l.starts_with("  1    calibrate alpha"))
            && stdout
                .lines()
                .any(|l| l.starts_with("  2    add rack_recirculation(rack=A05)")),
        "{stdout}"
    );

    // Under each worst sensor of the first diagnosis, which racks warm it in the model's
    // flow. The worst is the inlet of the rack whose exhaust recirculates (hidden): the
    // model reads it degrees too cold, and no exhaust reaches it in the model's flow.
    let lines: Vec<&str> = stdout.lines().collect();
    let first_diagnosis = lines
        .iter()
        .position(|l| l.contains("diagnose where the calibrated model fails"))
        .unwrap();
    let worst = &lines[first_diagnosis + 2..first_diagnosis + 8];
    for pair in worst.chunks(2) {
        assert!(pair[0].contains("the model reads"), "{stdout}");
        assert!(
            pair[1].contains("in the model, exhausts warm it by")
                || pair[1].contains("no exhaust reaches it in the model"),
            "{stdout}"
        );
    }
    assert!(
        worst[0].contains("c-A05-") && worst[0].contains("too cold"),
        "{stdout}"
    );
    assert!(
        worst[1].contains("the measured warmth takes a path the model lacks"),
        "{stdout}"
    );

    // story.json: two calibrations, the second with the added effect, and a lower error.
    let story: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("story.json")).unwrap()).unwrap();
    assert_eq!(story["schema"], "kalibre.story/1");
    let steps = story["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 2, "{stdout}");
    assert!(steps[0]["effects"].as_array().unwrap().is_empty());
    let added = &steps[1]["effects"][0];
    assert_eq!(added["kind"], "rack_recirculation", "{stdout}");
    let first = steps[0]["mae_after_c"].as_f64().unwrap();
    let last = steps[1]["mae_after_c"].as_f64().unwrap();
    assert!(
        last < first,
        "the error did not fall: {first:.3} -> {last:.3} C"
    );
    assert_eq!(story["outcome"], "improved");
    // Where no sensor measures: the servers' intakes against the truth's. The alpha-only
    // model misses the recirculating rack's intakes by degrees; with the effect it does
    // not, and the intakes' error falls as the sensors' does.
    let intakes = |k: usize| &steps[k]["intakes"];
    let (before, after) = (
        intakes(0)["mae_c"].as_f64().unwrap(),
        intakes(1)["mae_c"].as_f64().unwrap(),
    );
    assert!(after < 0.5 * before, "intakes: {before:.3} -> {after:.3} C");
    let worst = intakes(0)["worst_server"].as_str().unwrap();
    assert!(worst.starts_with("A05-"), "worst intake before: {worst}");
    let (w0, w1) = (
        intakes(0)["worst_error_c"].as_f64().unwrap().abs(),
        intakes(1)["worst_error_c"].as_f64().unwrap().abs(),
    );
    assert!(w1 < 0.5 * w0, "worst intake error: {w0:.2} -> {w1:.2} C");
    assert!(stdout.contains("where no sensor measures"), "{stdout}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<th>intakes: MAE (C)</th>"), "intake table");
    assert!(html.contains(&format!("<td>{before:.2}</td>")), "{before}");
    assert!(html.contains("<td>1. calibrate alpha</td>"), "step table");
    assert!(html.contains("<td>2. add rack_recirculation(rack=A05), recalibrate</td>"));
    // Each hypothesis's BIC change is shown, as in the terminal; a fit outside its range
    // is not offered as an entry (clamped, it would do nothing), in story.json either.
    let mut outside = 0;
    for d in story["diagnoses"].as_array().unwrap() {
        for h in d["hypotheses"].as_array().unwrap() {
            let bic = h["delta_bic"].as_f64().unwrap();
            let line = stdout.lines().find(|l| {
                l.trim_start()
                    .starts_with(&format!("{} ", h["name"].as_str().unwrap()))
            });
            if let Some(line) = line {
                assert!(line.contains(&format!("BIC {bic:+.1}")), "{line}");
            }
            // Its row in report.html.
            let name = h["name"].as_str().unwrap().replace('"', "&quot;");
            let row = html
                .split("<tr>")
                .find(|r| r.starts_with(&format!("<td>{name}</td>")))
                .unwrap_or_else(|| panic!("{name} has no row"));
            let offered = !row.contains("none (fitted outside its range, which no entry gives)");
            if h["in_range"] == false {
                outside += 1;
                assert!(h["entry"].is_null(), "{h}");
                assert!(!offered, "{row}");
            } else {
                assert_eq!(
                    h["entry"]["kind"],
                    h["name"]
                        .as_str()
                        .unwrap()
                        .split(['(', '#'])
                        .next()
                        .unwrap()
                );
                assert!(offered && row.contains("<code>{&quot;kind&quot;"), "{row}");
            }
        }
    }
    assert!(
        outside > 0,
        "the demo has fits outside their range to leave out"
    );
    for zero in ["&quot;fraction&quot;:0.0,", "&quot;fraction&quot;:0.0}"] {
        assert!(
            !html.contains(zero),
            "an entry that does nothing is offered"
        );
    }

    // The hall to continue from carries the entry.
    let hall: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("hall-with-effect.json")).unwrap())
            .unwrap();
    assert_eq!(hall["effects"][0]["kind"], "rack_recirculation");
    // Each diagnosis-N.json is the document `diagnose --json` prints: the ranking, and
    // where step N's calibration fails, worst sensor first, with the racks warming each.
    let diagnosis: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("diagnosis-1.json")).unwrap())
            .unwrap();
    let step1: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("step-1/report.json")).unwrap())
            .unwrap();
    let mut by_sensor: std::collections::BTreeMap<&str, (f64, f64)> = Default::default();
    for r in step1["residuals"].as_array().unwrap() {
        let e = by_sensor.entry(r["sensor"].as_str().unwrap()).or_default();
        e.0 += r["predicted_c"].as_f64().unwrap() - r["measured_c"].as_f64().unwrap();
        e.1 += 1.0;
    }
    let worst_mean = by_sensor
        .iter()
        .map(|(s, (sum, n))| (*s, sum / n))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .unwrap();
    let listed = diagnosis["worst_sensors"]
        .as_array()
        .expect("worst_sensors");
    assert_eq!(listed.len(), 5, "{listed:?}");
    assert_eq!(listed[0]["sensor"], worst_mean.0, "{listed:?}");
    assert!((listed[0]["mean_residual_c"].as_f64().unwrap() - worst_mean.1).abs() < 1e-9);
    assert!(
        listed
            .iter()
            .all(|w| w["warming"].is_object() || w["warming"].is_null()),
        "{listed:?}"
    );
    assert!(
        stdout.contains(&format!("    {:<12}", worst_mean.0)),
        "{stdout}"
    );
    // The demo's snapshots are steady: none is off at every sensor.
    assert_eq!(
        diagnosis["odd_snapshots"],
        serde_json::json!([]),
        "{diagnosis}"
    );
    assert!(diagnosis["hypotheses"].is_array());
    assert!(out.join("step-2/report.json").is_file());
    assert!(!out.join("step-7").exists() && !out.join("diagnosis-5.json").exists());
    assert!(out.join("notes.txt").is_file());

    // report.html: the plan, two thermal planes with their racks outlined, the error
    // chart across calibrations; nothing fetched from outside.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<h2>Where the model fails</h2>"));
    assert!(html.contains("model minus measurement"), "plan legend");
    assert!(html.contains("Thermal plane at z = 1.30 m"));
    assert!(html.contains("before calibration, snapshot"));
    assert!(html.contains("after calibration 2, snapshot"));
    assert_eq!(
        html.matches(r#"class="rack""#).count(),
        2 * 24,
        "two planes x 24 racks"
    );
    assert!(html.contains("<h2>The error as effects are added</h2>"));
    assert!(html.contains("2: + rack_recirculation"));
    assert!(html.contains("<h2>Error per iteration</h2>"));
    assert!(html.contains("<h2>Measured against model</h2>"));
    for external in ["<script", "<link", " src=", "href=\"http", "url("] {
        assert!(
            !html.contains(external),
            "the report refers to `{external}`"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// A hidden bypass behind A03: the bypasses behind its neighbours (and across the aisle)
/// are significant too, each on its own evidence, but they read the same residual (their
/// shares add up to more than all of it): the listing says they are alternative
/// placements of one effect, and which the data cannot tell from the first.
#[test]
fn demo_says_significant_neighbours_are_alternatives_of_one_effect() {
    let out = tmp("bypass");
    let o = Command::new(env!("CARGO_BIN_EXE_kalibre"))
        .args(["demo", "--effect", "bypass", "--out"])
        .arg(&out)
        .output()
        .expect("the kalibre binary runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let lines: Vec<&str> = stdout.lines().collect();
    let listed: Vec<usize> = (0..lines.len())
        .filter(|&i| lines[i].contains("explains") && lines[i].contains("significant"))
        .collect();
    let first = lines[listed[0]].trim_start();
    assert!(first.starts_with("bypass(behind_rack="), "{stdout}");
    let best = first.split_whitespace().next().unwrap();
    // Every other significant one of the first diagnosis is called an alternative.
    let others: Vec<usize> = listed
        .iter()
        .copied()
        .skip(1)
        .take_while(|&i| !lines[..i].iter().any(|l| l.contains("suggested entry")))
        .collect();
    assert!(others.len() >= 2, "{stdout}");
    for i in others {
        assert!(
            lines[i + 1].contains(&format!("an alternative to {best}, not a second effect")),
            "{}\n{}",
            lines[i],
            lines[i + 1]
        );
    }
    assert!(
        stdout.contains("the data cannot tell the two apart (BIC +"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn demo_refuses_a_bad_unknown_or_empty_effect() {
    for (arg, needle) in [
        ("Bypass!", "--effect `Bypass!`"),
        ("no_such_kind", "no_such_kind"),
        // Size 0 hides nothing, as `synth` says too.
        (
            "crac_supply_offset:offset_c=0",
            "offset_c is 0, which hides nothing",
        ),
    ] {
        let out = tmp("bad");
        let o = Command::new(env!("CARGO_BIN_EXE_kalibre"))
            .args(["demo", "--effect", arg, "--out"])
            .arg(&out)
            .output()
            .expect("the kalibre binary runs");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(needle), "{stderr}");
        assert!(!out.exists(), "nothing written on bad input");
    }
}
