//! Calibrations `calibrate` accepts are diagnosed, two kinds of which `diagnose` used to
//! refuse: one with fixed parameters (equal bounds: given, not calibrated), whose
//! finite-difference step is zero (a NaN Jacobian, 0 / 0), and one of a hall that already
//! has a `containment_leakage` entry, whose all-defaults candidate was named as the
//! calibrated entry's parameter (the loop diagnose, add, recalibrate, diagnose again broke
//! there).

mod cli_support;

use std::path::Path;

use cli_support::{data, diagnose_cmd, kalibre, on_files, run, stderr, tmp, QUICK_CALIBRATION};

/// `hall` (a `hall.json` document) written to `dir`, calibrated quickly on `snaps` (with
/// `extra` flags) and diagnosed: the diagnosis's JSON.
fn calibrate_and_diagnose(
    dir: &Path,
    hall: &serde_json::Value,
    snaps: &Path,
    extra: &[&str],
) -> serde_json::Value {
    let path = dir.join("hall.json");
    std::fs::write(&path, serde_json::to_string_pretty(hall).unwrap()).unwrap();
    let cal = dir.join("cal");
    let o = run(on_files("calibrate", &path, snaps)
        .args(QUICK_CALIBRATION)
        .args(extra)
        .arg("--out")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(diagnose_cmd(&path, snaps, &cal).arg("--json"));
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

/// A `hall.json` document.
fn hall_doc(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn fixed_alpha_and_fixed_effect_parameters_are_diagnosed() {
    let dir = tmp("diagnose-fixed");
    let mut doc = hall_doc(&data("of-dev-bypass/hall.json"));
    doc["server_types"][0]["alpha_cfm_per_w"] =
        serde_json::json!({ "initial": 0.13, "min": 0.13, "max": 0.13 });
    doc["effects"] = serde_json::json!([{
        "kind": "bypass", "behind_rack": "B3", "fraction": 0.05, "fraction_bounds": [0.05, 0.05]
    }]);
    let d = calibrate_and_diagnose(&dir, &doc, &data("of-dev-bypass/snapshots.csv"), &[]);
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
    let mut doc = hall_doc(&synth.join("hall.json"));
    doc["effects"] = serde_json::json!([{
        "kind": "containment_leakage", "containment": 0, "open_fraction": 0.05, "sides": ["+y"]
    }]);
    let snaps = synth.join("snapshots.csv");
    let d = calibrate_and_diagnose(&dir, &doc, &snaps, &["--grid-m", "0.4"]);
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
