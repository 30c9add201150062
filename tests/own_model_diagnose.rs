//! `kalibre diagnose --model command`: a model of your own with candidate effects
//! (`[[params]]` with `absent`) calibrated without them, the missing one named from the
//! model's own runs, added by deleting its `absent` line, and the error falling when it is
//! calibrated; the decoy is not named. Refusals name what is wrong.

mod cli_support;
mod heat_exchanger;

use std::path::Path;

use cli_support::{assert_input_error, kalibre, run, stderr};
use heat_exchanger::{calibrate, report, setup_with, MODEL_PY, MODEL_TOML, TEMPLATE};

/// The heat exchanger with a second candidate, a bias of the cold outlet's sensor: absent
/// in the truth, so a decoy.
fn with_decoy() -> (String, String, String) {
    let script = MODEL_PY.replace(
        "v[\"t_cold_in\"] + q / cc, q / 1000",
        "v[\"t_cold_in\"] + q / cc + v[\"bias\"], q / 1000",
    );
    assert_ne!(script, MODEL_PY, "the script's output line moved");
    let template = format!("{TEMPLATE}bias = {{{{bias}}}}\n");
    let loss = "name = \"loss\"\nlower = 0.0\nupper = 500.0\ninitial = 100.0\n";
    assert!(MODEL_TOML.contains(loss));
    let toml = MODEL_TOML.replace(
        loss,
        "name = \"loss\"\nlower = 0.0\nupper = 500.0\nabsent = 0.0\n\n[[params]]\n\
         name = \"bias\"\neffect = \"cold_sensor_bias\"\nlower = -2.0\nupper = 2.0\nabsent = 0.0\n",
    );
    (script, template, toml)
}

/// The truth: a heat loss of 150 W/K, no sensor bias.
const TRUTH: [(&str, f64); 4] = [("UA0", 5000.0), ("n", 0.6), ("loss", 150.0), ("bias", 0.0)];

fn diagnose(config: &Path, measurements: &Path, cal: &Path) -> std::process::Command {
    let mut c = kalibre();
    c.args(["diagnose", "--model", "command", "--config"])
        .arg(config)
        .arg("--measurements")
        .arg(measurements)
        .arg("--calibration")
        .arg(cal)
        .args(["--threads", "2"]);
    c
}

fn diagnosis_json(c: &mut std::process::Command) -> serde_json::Value {
    let o = run(c.arg("--json"));
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

fn hypothesis<'a>(doc: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    (doc["diagnosis"]["hypotheses"].as_array().unwrap().iter())
        .find(|h| h["name"] == name)
        .unwrap_or_else(|| panic!("no hypothesis `{name}` in {doc}"))
}

#[test]
fn the_missing_effect_is_named_added_and_the_error_falls() {
    let (script, template, toml) = with_decoy();
    let (dir, config, measurements) = setup_with("own-diagnose", &script, &template, &toml, &TRUTH);
    let cal = dir.join("cal");
    let o = run(&mut calibrate(&config, &measurements, &cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("candidate effects loss, cold_sensor_bias are held absent"),
        "{said}"
    );
    let without = report(&cal)["best"]["mae_c"].as_f64().unwrap();
    // The loss is what makes the model miss: the two parameters cannot absorb it.
    assert!(without > 0.5, "MAE without the loss {without}");

    let doc = diagnosis_json(&mut diagnose(&config, &measurements, &cal));
    let loss = hypothesis(&doc, "loss");
    assert_eq!(loss["significant"], true, "{loss}");
    let fitted = loss["fitted"]["loss"].as_f64().unwrap();
    assert!((fitted - 150.0).abs() < 7.5, "fitted loss {fitted}");
    assert_eq!(doc["diagnosis"]["hypotheses"][0]["name"], "loss");
    let decoy = hypothesis(&doc, "cold_sensor_bias");
    assert_eq!(decoy["significant"], false, "{decoy}");
    // 4 scenarios x (2 calibrated steps + 2 candidates' steps) new; the calibrated point
    // is the calibration's own run.
    assert_eq!(
        doc["runs"],
        serde_json::json!({ "new": 16, "from_journal": 4 })
    );
    // Again: every run is the journal's.
    let again = diagnosis_json(&mut diagnose(&config, &measurements, &cal));
    assert_eq!(
        again["runs"],
        serde_json::json!({ "new": 0, "from_journal": 20 })
    );
    assert_eq!(again["diagnosis"], doc["diagnosis"]);

    let o = run(&mut diagnose(&config, &measurements, &cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("delete `absent` from [[params]] `loss`"),
        "{said}"
    );

    // Added as the diagnosis says: the same names in the same order, so the calibration
    // resumes in its own directory, and the error falls.
    let added = toml.replace(
        "upper = 500.0\nabsent = 0.0\n",
        &format!("upper = 500.0\ninitial = {fitted}\n"),
    );
    std::fs::write(&config, added).unwrap();
    let o = run(&mut calibrate(&config, &measurements, &cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&cal);
    let with = r["best"]["mae_c"].as_f64().unwrap();
    assert!(
        with < 0.05 * without,
        "MAE {without} -> {with} with the loss"
    );
    assert!(r["runs"]["cached"].as_u64().unwrap() > 0, "{}", r["runs"]);
    let loss = r["best"]["params"]["loss"].as_f64().unwrap();
    assert!((loss - 150.0).abs() < 7.5, "calibrated loss {loss}");
    // Nothing is missing now: the decoy stays unnamed.
    let after = diagnosis_json(&mut diagnose(&config, &measurements, &cal));
    let named: Vec<&serde_json::Value> = (after["diagnosis"]["hypotheses"].as_array().unwrap())
        .iter()
        .filter(|h| h["significant"] == true)
        .collect();
    assert!(named.is_empty(), "{named:?}");
}

#[test]
fn a_diagnosis_of_a_model_of_your_own_refuses_what_does_not_fit() {
    let (script, template, toml) = with_decoy();
    let (dir, config, measurements) =
        setup_with("own-diagnose-refusals", &script, &template, &toml, &TRUTH);
    let cal = dir.join("cal");
    let o = run(calibrate(&config, &measurements, &cal).args(["--iterations", "2"]));
    assert!(o.status.success(), "{}", stderr(&o));

    // Hall flags are refused by name.
    let o = run(diagnose(&config, &measurements, &cal).args(["--write-hall", "h.json"]));
    assert_input_error(&o, "--write-hall is about a hall");
    // Other measurements than the calibration's.
    let text = std::fs::read_to_string(&measurements).unwrap();
    let first = text.lines().nth(1).unwrap();
    assert!(first.starts_with("low,t_hot_out,"), "{first}");
    let edited = text.replacen(first, "low,t_hot_out,30.0", 1);
    let other = dir.join("other.csv");
    std::fs::write(&other, edited).unwrap();
    let o = run(&mut diagnose(&config, &other, &cal));
    assert_input_error(&o, "not the measurements");
    // A model.toml with no candidate says how to give one.
    let plain = dir.join("plain.toml");
    let no_candidates = toml
        .replace(
            "absent = 0.0\n\n[[params]]",
            "initial = 100.0\n\n[[params]]",
        )
        .replace("effect = \"cold_sensor_bias\"\n", "")
        .replace("upper = 2.0\nabsent = 0.0", "upper = 2.0\ninitial = 0.0");
    std::fs::write(&plain, no_candidates).unwrap();
    let o = run(&mut diagnose(&plain, &measurements, &cal));
    assert_input_error(&o, "no candidate effect to test");
    // An edited model is another model: the calibration's point is not its.
    std::fs::write(dir.join("hx.py"), format!("{script}# edited\n")).unwrap();
    let o = run(&mut diagnose(&config, &measurements, &cal));
    assert_input_error(&o, "the calibration ran another model");
    // In model.toml: an absent value outside the range, and `effect` without `absent`.
    let outside = toml.replace("upper = 2.0\nabsent = 0.0", "upper = 2.0\nabsent = 3.0");
    std::fs::write(&config, outside).unwrap();
    let o = run(&mut diagnose(&config, &measurements, &cal));
    assert_input_error(&o, "`params[3].absent`: 3 is outside [-2, 2]");
    let stray = toml.replace("upper = 2.0\nabsent = 0.0", "upper = 2.0\ninitial = 0.0");
    std::fs::write(&config, stray).unwrap();
    let o = run(&mut diagnose(&config, &measurements, &cal));
    assert_input_error(
        &o,
        "`params[3].effect`: names the effect of a candidate parameter",
    );
}
