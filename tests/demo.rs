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
        // The folders count calibrations; the printed steps count diagnoses too.
        "each calibration's report.json in step-1/ (step 1), step-2/ (step 3)",
    ] {
        assert!(stdout.contains(needle), "`{needle}` not in:\n{stdout}");
    }

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
    // The hall to continue from carries the entry.
    let hall: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("hall-with-effect.json")).unwrap())
            .unwrap();
    assert_eq!(hall["effects"][0]["kind"], "rack_recirculation");
    assert!(out.join("diagnosis-1.json").is_file());
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
