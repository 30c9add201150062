//! A model of your own, a wall between two air streams whose outer temperature goes as
//! `q / h`, and what kalibre says of it.
//! - Calibrated briefly, the calibrated parameters' own linearised refit (`floor` in
//!   `--json`) promises a low MAE only by taking `h` through zero; the model run there
//!   (clamped into the box) reads far worse. The text blames the linearisation, not the
//!   calibration's iterations.
//! - Measurements too few for the parameters are bad input, said as such.
//! - Its calibration given to a hall's diagnosis is named as a model of your own's, not
//!   blamed on the snapshots; a hall's calibration given to it is named as a hall's.
//! - A `--params` object that leaves parameters out says which keep their initial values.
//! - A design that fails throughout names the run directory kept for its first failure.

mod cli_support;

use std::process::Command;

use cli_support::{
    assert_input_error, data, diagnose_cmd, kalibre, on_dataset, run, stderr, tmp,
    QUICK_CALIBRATION,
};

const MODEL_PY: &str = r#"import sys
v = {}
for line in open(sys.argv[1]):
    if "=" in line:
        k, x = line.split("=")
        v[k.strip()] = float(x)
t_out = v["ambient_c"] + v["q"] / v["h"] + v["loss"] * 0.05 * v["ambient_c"]
t_in = t_out + v["q"] / v["k"]
with open(sys.argv[2], "w") as f:
    f.write("t_in,t_out\n%r,%r\n" % (t_in, t_out))
"#;

const MODEL_TOML: &str = r#"description = "a wall between two air streams"
program = "python3"
args = ["{{config_dir}}/model.py", "params.in", "out.csv"]
timeout_s = 30
fingerprint_files = ["model.py"]

[[templates]]
source = "params.in.tmpl"
destination = "params.in"

[output]
file = "out.csv"
parser = "csv"
names = ["t_in", "t_out"]

[[params]]
name = "k"
lower = 0.5
upper = 20.0
initial = 2.5
scale = "log"

[[params]]
name = "h"
lower = 1.0
upper = 100.0
initial = 10.0

[[params]]
name = "loss"
lower = 0.0
upper = 5.0
absent = 0.0

[[scenarios]]
label = "winter"
variables = { ambient_c = 5.0, q = 100.0 }

[[scenarios]]
label = "summer"
variables = { ambient_c = 30.0, q = 50.0 }

[[scenarios]]
label = "spring"
variables = { ambient_c = 15.0, q = 200.0 }
"#;

const TEMPLATE: &str =
    "k = {{k}}\nh = {{h}}\nloss = {{loss}}\nambient_c = {{ambient_c}}\nq = {{q}}\n";

/// The truth: k = 4, h = 20, loss = 2.
const MEASUREMENTS: &str = "scenario,output,value\nwinter,t_in,35.5\nwinter,t_out,10.5\n\
summer,t_in,48.0\nsummer,t_out,35.5\nspring,t_in,76.5\nspring,t_out,26.5\n";

/// The wall's project in a fresh directory, measured by `measurements`; and a command of
/// it (`kalibre COMMAND --model command --config model.toml --measurements ...`).
fn project(name: &str, measurements: &str) -> (std::path::PathBuf, impl Fn(&str) -> Command) {
    let dir = tmp(name);
    for (name, text) in [
        ("model.py", MODEL_PY),
        ("model.toml", MODEL_TOML),
        ("params.in.tmpl", TEMPLATE),
        ("measurements.csv", measurements),
    ] {
        std::fs::write(dir.join(name), text).unwrap();
    }
    let at = dir.clone();
    let own = move |command: &str| {
        let mut c = kalibre();
        c.current_dir(&at)
            .args([command, "--model", "command", "--config", "model.toml"])
            .args(["--measurements", "measurements.csv", "--threads", "1"]);
        c
    };
    (dir, own)
}

#[test]
fn a_refit_the_model_run_refutes_is_blamed_on_the_linearisation() {
    let (dir, own) = project("own-floor", MEASUREMENTS);
    let o = run(own("calibrate").args([
        "--iterations",
        "3",
        "--polish",
        "2",
        "--quiet",
        "--out",
        "cal",
    ]));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(own("diagnose").args(["--calibration", "cal", "--json"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let d = &doc["diagnosis"];
    let (now, refit) = (d["mae"].as_f64().unwrap(), d["refit_mae"].as_f64().unwrap());
    let floor_run = doc["floor"]["mae"].as_f64().expect("the floor's model run");
    // The premise: the refit promises much, the run there gives nothing.
    assert!(refit < 0.5 * now && floor_run >= now, "{doc}");
    assert_eq!(
        doc["floor"]["beyond_bounds"],
        serde_json::json!([]),
        "{doc}"
    );
    let o = run(own("diagnose").args(["--calibration", "cal"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    let line = said
        .lines()
        .find(|l| l.contains("refitting the calibrated parameters alone"))
        .unwrap_or_else(|| panic!("no refit line in {said}"));
    assert!(line.contains("the linearisation misleads there"), "{line}");
    assert!(!line.contains("has not converged"), "{line}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two measured values for two calibrated parameters: nothing is left to estimate the
/// noise from, which the user must hear as a fault of the data (exit 2), not a failure.
#[test]
fn measurements_too_few_for_the_parameters_are_bad_input() {
    let two = "scenario,output,value\nwinter,t_in,35.5\nwinter,t_out,10.5\n";
    let (dir, own) = project("own-too-few", two);
    calibrate_in_one_iteration(&own);
    let o = run(own("diagnose").args(["--calibration", "cal"]));
    // Notes come first (the scenarios not measured, the runs planned); the error last.
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.contains("2 measured values for 2 calibrated parameters leave no degree")
            && last.contains("measure more values")
            && last.contains("kalibre diagnose --noise"),
        "{err}"
    );
    // The noise given, as the message offers: the diagnosis runs.
    let o = run(own("diagnose").args(["--calibration", "cal", "--noise", "0"]));
    assert_input_error(&o, "--noise: expected the measurements' noise");
    let o = run(own("diagnose").args(["--calibration", "cal", "--noise", "0.2"]));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_hall_diagnosis_of_this_calibration_names_the_model_of_your_own() {
    let (dir, own) = project("own-as-hall", MEASUREMENTS);
    calibrate_in_one_iteration(&own);
    let hall = data("of-dev-clean");
    let o = run(&mut diagnose_cmd(
        &hall.join("hall.json"),
        &hall.join("snapshots.csv"),
        &dir.join("cal"),
    ));
    assert_input_error(&o, "/model: the calibration of a model of your own");
    assert!(
        stderr(&o).contains("kalibre diagnose --model command"),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn simulate_says_which_parameters_a_short_params_object_leaves_and_refuses_a_halls() {
    let (dir, _) = project("own-params", MEASUREMENTS);
    std::fs::write(dir.join("k.json"), r#"{ "k": 4.0 }"#).unwrap();
    let simulate = || {
        let mut c = kalibre();
        c.current_dir(&dir)
            .args(["simulate", "--model", "command", "--config", "model.toml"]);
        c
    };
    let o = run(simulate().args(["--params", "k.json", "--out", "p.csv"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains(
            "gives no value of 2 of the 3 parameters (h, loss): they keep their initial values"
        ),
        "{said}"
    );
    assert!(said.contains("(3 scenarios x 2 outputs,"), "{said}");
    // A hall's calibration, whose `alpha/...` names this model does not have.
    let hall_cal = dir.join("hall-cal");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(QUICK_CALIBRATION)
        .arg("--out")
        .arg(&hall_cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(simulate()
        .arg("--params")
        .arg(hall_cal.join("report.json"))
        .args(["--out", "q.csv"]));
    assert_input_error(
        &o,
        "/model/kind: the calibration of a hall (the `builtin` model)",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `kalibre calibrate` of the project into `cal`: one iteration, no polish; it must succeed.
fn calibrate_in_one_iteration(own: &impl Fn(&str) -> Command) {
    let o = run(own("calibrate")
        .args(["--iterations", "1", "--polish", "0", "--quiet"])
        .args(["--out", "cal"]));
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A model that fails at every run of the initial design: calibrate ends with the first
/// failure's reason, its log and the directory kept for it, where the user looks first.
#[test]
fn a_design_that_fails_throughout_names_the_kept_run_directory() {
    let (dir, own) = project("own-all-fail", MEASUREMENTS);
    std::fs::write(
        dir.join("model.py"),
        "import sys\nprint('licence server down', file=sys.stderr)\nsys.exit(3)\n",
    )
    .unwrap();
    let o = run(own("calibrate")
        .args(["--iterations", "1", "--polish", "0", "--quiet"])
        .args(["--out", "cal"]));
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("runs of the initial design failed")
            && err.contains("its log: `licence server down`"),
        "{err}"
    );
    let kept = err
        .split("its directory is kept: ")
        .nth(1)
        .and_then(|rest| rest.split(')').next())
        .unwrap_or_else(|| panic!("no kept directory in {err}"));
    assert!(
        std::path::Path::new(kept).join("stderr.log").is_file(),
        "{kept}: {err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
