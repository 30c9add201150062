//! Calibrations `calibrate` accepts are diagnosed, two kinds of which `diagnose` used to
//! refuse: one with fixed parameters (equal bounds: given, not calibrated), whose
//! finite-difference step is zero (a NaN Jacobian, 0 / 0), and one of a hall that already
//! has a `containment_leakage` entry, whose all-defaults candidate was named as the
//! calibrated entry's parameter (the loop diagnose, add, recalibrate, diagnose again broke
//! there).

mod cli_support;

use cli_support::{data, diagnose_cmd, kalibre, on_files, run, stderr, tmp};

#[test]
fn fixed_alpha_and_fixed_effect_parameters_are_diagnosed() {
    let dir = tmp("diagnose-fixed");
    let text = std::fs::read_to_string(data("of-dev-bypass/hall.json")).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    doc["server_types"][0]["alpha_cfm_per_w"] =
        serde_json::json!({ "initial": 0.13, "min": 0.13, "max": 0.13 });
    doc["effects"] = serde_json::json!([{
        "kind": "bypass", "behind_rack": "B3", "fraction": 0.05, "fraction_bounds": [0.05, 0.05]
    }]);
    let hall = dir.join("hall.json");
    std::fs::write(&hall, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    let snaps = data("of-dev-bypass/snapshots.csv");
    let cal = dir.join("cal");
    let o = run(on_files("calibrate", &hall, &snaps)
        .args([
            "--iterations",
            "2",
            "--polish",
            "0",
            "--no-grid-check",
            "--quiet",
            "--out",
        ])
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(diagnose_cmd(&hall, &snaps, &cal).arg("--json"));
    assert!(o.status.success(), "{}", stderr(&o));
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    let hyps = d["hypotheses"].as_array().unwrap();
    assert!(!hyps.is_empty());
    for h in hyps {
        let fraction = h["explained_fraction"].as_f64().unwrap();
        assert!(fraction.is_finite(), "{h}");
    }
}

#[test]
fn a_hall_with_a_containment_leakage_entry_is_diagnosed() {
    let dir = tmp("diagnose-leakage");
    let synth = dir.join("synth");
    let o = run(kalibre()
        .args(["synth", "--preset", "demo", "--seed", "3", "--out"])
        .arg(&synth));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(synth.join("hall.json")).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    doc["effects"] = serde_json::json!([{
        "kind": "containment_leakage", "containment": 0, "open_fraction": 0.05, "sides": ["+y"]
    }]);
    let hall = dir.join("hall.json");
    std::fs::write(&hall, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    let snaps = synth.join("snapshots.csv");
    let cal = dir.join("cal");
    let o = run(on_files("calibrate", &hall, &snaps)
        .args([
            "--iterations",
            "1",
            "--polish",
            "0",
            "--no-grid-check",
            "--quiet",
        ])
        .args(["--grid-m", "0.4", "--out"])
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(diagnose_cmd(&hall, &snaps, &cal).arg("--json"));
    assert!(o.status.success(), "{}", stderr(&o));
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    // The all-sides candidate, named as a second entry of its kind is.
    let h = d["hypotheses"]
        .as_array()
        .unwrap()
        .iter()
        .find(|h| h["name"] == "containment_leakage#2")
        .unwrap_or_else(|| panic!("no containment_leakage#2 in {d}"));
    assert!(
        h["fitted"]
            .get("containment_leakage#2/open_fraction")
            .is_some(),
        "{h}"
    );
}
