//! A calibration with fixed parameters (equal bounds: given, not calibrated) is diagnosed
//! like any other. Its finite-difference step is zero, and the diagnosis used to stop on
//! a NaN Jacobian (0 / 0) for input `calibrate` had accepted.

mod cli_support;

use cli_support::{data, diagnose_cmd, on_files, run, stderr, tmp};

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
