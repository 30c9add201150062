//! A model of your own, not a hall: `kalibre calibrate --model command --config
//! model.toml --measurements measurements.csv` calibrates an external program against
//! measurements of its `[[scenarios]]`, with the Gaussian-process surrogate, journals its
//! runs and resumes from them; hall-only flags and bad measurements are refused by name.
//! The model here is a small Python heat exchanger (effectiveness-NTU) with a known truth.

mod cli_support;
mod heat_exchanger;

use std::path::Path;

use cli_support::{assert_input_error, kalibre, on_dataset, run, stderr, tmp, QUICK_CALIBRATION};
use heat_exchanger::{calibrate, report, setup, MODEL_TOML, TRUTH};

/// The Gaussian-process loop alone (no polish on the model) finds the heat exchanger's
/// parameters from its four scenarios, and a second run replays every run from the
/// journal.
#[test]
fn a_model_of_your_own_is_calibrated_and_resumed() {
    let (dir, config, measurements) = setup("own-model");
    let out = dir.join("out");
    let o = run(&mut calibrate(&config, &measurements, &out));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("in the outputs' units"), "{said}");
    assert!(!said.contains(" C\n") && !said.contains("aisle"), "{said}");
    let r = report(&out);
    let initial = r["initial"]["mae_c"].as_f64().unwrap();
    let best = r["best"]["mae_c"].as_f64().unwrap();
    assert!(best < 0.01 * initial, "MAE {initial} -> {best}");
    for (name, truth) in TRUTH {
        let got = r["best"]["params"][name].as_f64().unwrap();
        assert!(
            (got - truth).abs() <= 0.03 * truth,
            "{name}: {got} against the truth {truth}"
        );
    }
    assert_eq!(r["model"]["kind"], "command");
    let total = r["runs"]["total"].as_u64().unwrap();
    // Resumed: every run is the journal's.
    let o = run(&mut calibrate(&config, &measurements, &out));
    assert!(o.status.success(), "{}", stderr(&o));
    let again = report(&out);
    assert_eq!(again["runs"]["new"], 0, "{}", again["runs"]);
    assert_eq!(again["runs"]["cached"].as_u64().unwrap(), total);
    assert_eq!(again["best"]["params"], r["best"]["params"]);
    // An edited model script is another model: its runs are not replayed.
    let script = dir.join("hx.py");
    let text = std::fs::read_to_string(&script).unwrap();
    std::fs::write(&script, text + "# edited\n").unwrap();
    let o = run(&mut calibrate(&config, &measurements, &out));
    assert_input_error(&o, &format!("holds {total} runs of another model"));
    // ... and the refusal names what changed: the script (a fingerprint file), not the
    // template.
    let said = stderr(&o);
    assert!(
        said.contains("since they ran, these changed: ") && said.contains("hx.py"),
        "{said}"
    );
    assert!(!said.contains("template"), "{said}");
    let template = dir.join("params.in.tmpl");
    let text = std::fs::read_to_string(&template).unwrap();
    std::fs::write(&template, text + "# edited\n").unwrap();
    let o = run(&mut calibrate(&config, &measurements, &out));
    let said = stderr(&o);
    assert!(
        said.contains("hx.py") && said.contains("template "),
        "{said}"
    );
}

/// What does not fit a model of your own is refused before any run, by name.
#[test]
fn a_model_of_your_own_refuses_what_does_not_fit() {
    let (dir, config, measurements) = setup("own-model-refusals");
    let out = dir.join("out");
    let o = run(kalibre()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--measurements")
        .arg(&measurements)
        .arg("--out")
        .arg(&out));
    assert_input_error(
        &o,
        "--measurements calibrates a model of your own: add --model command",
    );
    let o = run(calibrate(&config, &measurements, &out).args(["--rise-weight", "0"]));
    assert_input_error(&o, "--rise-weight is about a hall");
    let o = run(calibrate(&config, &measurements, &out).args(["--alpha", "per-server"]));
    assert_input_error(&o, "--alpha is about a hall");
    // Given at its hall default, a hall flag is still a hall's.
    let o = run(calibrate(&config, &measurements, &out).args(["--rise-range", "5,20"]));
    assert_input_error(&o, "--rise-range is about a hall");
    let o = run(calibrate(&config, &measurements, &out).args(["--np", "2"]));
    assert_input_error(&o, "--np is an OpenFOAM option: OpenFOAM solves a hall");
    let o = run(calibrate(&config, &measurements, &out).args(["--focus", "1"]));
    assert_input_error(&o, "--focus weighs a hall surrogate's runs");
    let typo = dir.join("typo.csv");
    let text = std::fs::read_to_string(&measurements).unwrap();
    std::fs::write(&typo, text.replace("\nmid,", "\nmdi,")).unwrap();
    let o = run(&mut calibrate(&config, &typo, &out));
    assert_input_error(&o, "line 5, column scenario: unknown scenario `mdi`");
    assert!(stderr(&o).contains("did you mean `mid`?"), "{}", stderr(&o));
    // A program that is not there is named before any run, not once per run.
    let missing = dir.join("missing.toml");
    std::fs::write(&missing, MODEL_TOML.replace("\"python3\"", "\"python33\"")).unwrap();
    let o = run(&mut calibrate(&missing, &measurements, &out));
    assert_input_error(&o, "`python33` is not an executable in PATH");
    // A runs root no one may write in (root included, so the test holds as root), found
    // before any run rather than journaled as every design run's failure.
    if cfg!(target_os = "linux") {
        let unwritable = dir.join("unwritable-root.toml");
        let toml = MODEL_TOML.replace("runs_root = \"runs\"", "runs_root = \"/proc/kalibre-runs\"");
        std::fs::write(&unwritable, toml).unwrap();
        let o = run(&mut calibrate(&unwritable, &measurements, &out));
        assert_input_error(&o, "`runs_root`: /proc/kalibre-runs takes no run directory");
    }
    // A hall and a model of your own at once: clap says they conflict.
    let o = run(calibrate(&config, &measurements, &out)
        .arg("--hall")
        .arg(dir.join("hall.json")));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
    // Nothing ran.
    assert!(!out.join("runs.jsonl").exists());
}

/// A scenario the model fails at every design point gives the surrogate nothing to learn
/// there: the calibration ends saying so, with the model's own reason, not blaming the
/// surrogate; every run is journaled as it ran.
#[test]
fn a_scenario_that_always_fails_is_named_with_its_reason() {
    let (dir, _, measurements) = setup("own-model-dead-scenario");
    let config = dir.join("broken.toml");
    let broken = "\n[[scenarios]]\nlabel = \"broken\"\nvariables = { m_hot = 0.0, m_cold = 0.6, \
                  t_hot_in = 70.0, t_cold_in = 12.0 }\n";
    std::fs::write(&config, MODEL_TOML.to_string() + broken).unwrap();
    let with_broken = dir.join("with-broken.csv");
    let text = std::fs::read_to_string(&measurements).unwrap();
    std::fs::write(&with_broken, text + "broken,t_hot_out,30\n").unwrap();
    let out = dir.join("out");
    let o = run(&mut calibrate(&config, &with_broken, &out));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("scenario `broken` failed at every design point")
            && err.contains("leave that scenario out of the observations")
            && err.contains("m_hot must be positive"),
        "{err}"
    );
    assert!(!err.contains("surrogate, fitted"), "{err}");
    // In the words of model.toml: its operating conditions are scenarios.
    assert!(!err.contains("snapshot"), "{err}");
    // Where to look: a kept run directory of that scenario, with the program's own log,
    // and the journal.
    let kept = err
        .split("its directory is kept: ")
        .nth(1)
        .and_then(|rest| rest.split(')').next())
        .unwrap_or_else(|| panic!("no kept directory named: {err}"));
    let log = std::fs::read_to_string(Path::new(kept).join("stderr.log")).unwrap();
    assert!(log.contains("m_hot must be positive"), "{kept}: {log}");
    assert!(
        err.contains(&format!(
            "in the run journal, {}",
            out.join("runs.jsonl").display()
        )),
        "{err}"
    );
    let journal = std::fs::read_to_string(out.join("runs.jsonl")).unwrap();
    assert!(
        journal.lines().any(|l| l.contains("\"failed\"")),
        "{journal}"
    );
}

/// Each parameter's relative error against the truth in a report.
fn relative_errors(r: &serde_json::Value) -> Vec<f64> {
    let params = r["best"]["params"].as_object().expect("named parameters");
    TRUTH
        .iter()
        .map(|(name, truth)| (params[*name].as_f64().unwrap() - truth).abs() / truth)
        .collect()
}

/// Measurements of different precision (the temperatures to 0.01 K, the heat flow to
/// 5 kW, and off by that much): with their `sd` column the loop weighs each residual by
/// it (weighted least squares) and finds the parameters closer than the same values
/// unweighted, whose misfit the heat flow's error pulls. The journal keeps the model's
/// outputs as they ran, so the weighted calibration repeats no run of the unweighted one.
#[test]
fn measurements_are_weighed_by_their_sd() {
    let (dir, config, measurements) = setup("own-model-sd");
    let text = std::fs::read_to_string(&measurements).unwrap();
    let (mut plain, mut weighted) = (String::new(), String::new());
    let mut sign = 1.0;
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            plain += "scenario,output,value\n";
            weighted += "scenario,output,value,sd\n";
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let (value, sd) = if f[1] == "q_kw" {
            sign = -sign;
            (f[2].parse::<f64>().unwrap() + 5.0 * sign, 5.0)
        } else {
            (f[2].parse::<f64>().unwrap(), 0.01)
        };
        plain += &format!("{},{},{value}\n", f[0], f[1]);
        weighted += &format!("{},{},{value},{sd}\n", f[0], f[1]);
    }
    let (plain_csv, weighted_csv) = (dir.join("plain.csv"), dir.join("weighted.csv"));
    std::fs::write(&plain_csv, plain).unwrap();
    std::fs::write(&weighted_csv, weighted).unwrap();
    let out = dir.join("out");
    let o = run(&mut calibrate(&config, &plain_csv, &out));
    assert!(o.status.success(), "{}", stderr(&o));
    let unweighted = relative_errors(&report(&out));
    let o = run(&mut calibrate(&config, &weighted_csv, &out));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("divided by its measurement's sd"), "{said}");
    assert!(
        said.contains("each output in its own units") && said.contains("q_kw"),
        "{said}"
    );
    let r = report(&out);
    assert_eq!(r["model"]["errors_in"], "sd");
    // The residual rows are values in the outputs' units, as the file gave them.
    let given = std::fs::read_to_string(&weighted_csv).unwrap();
    for row in r["residuals"].as_array().unwrap() {
        let line = format!(
            "{},{},{}",
            row["snapshot"].as_str().unwrap(),
            row["sensor"].as_str().unwrap(),
            row["measured_c"]
        );
        assert!(
            given.lines().any(|l| l.starts_with(&line)),
            "{line} in {given}"
        );
    }
    // The design points are the same, so at least the design is replayed.
    assert!(r["runs"]["cached"].as_u64().unwrap() >= 16, "{}", r["runs"]);
    let weighted = relative_errors(&r);
    let worst = |e: &[f64]| e.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst(&weighted) < 0.5 * worst(&unweighted),
        "relative parameter errors, weighted {weighted:?}, unweighted {unweighted:?}"
    );
    // Weighed right, the temperatures are fitted within a few of their sds.
    let best = r["best"]["mae_c"].as_f64().unwrap();
    assert!(best < 5.0, "MAE {best} sd");
}

/// A model of your own's report is not a hall's: `simulate --params` with a hall says so
/// by name instead of failing to parse its record, and without a hall runs the model of
/// your own at it.
#[test]
fn a_model_of_your_own_report_is_not_taken_for_a_halls() {
    let (dir, config, measurements) = setup("own-model-report");
    let out = dir.join("out");
    let o = run(calibrate(&config, &measurements, &out).args(["--iterations", "1"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(on_dataset("simulate", "of-dev-clean")
        .arg("--params")
        .arg(out.join("report.json"))
        .arg("--out")
        .arg(dir.join("pred.csv")));
    assert_input_error(&o, "the calibration of a model of your own");
    assert!(stderr(&o).contains("kalibre simulate --model command --config"));

    // Without a hall, simulate runs the model of your own at each scenario: at the
    // report's best parameters it gives the best run's outputs, so their error against
    // the measurements is the report's best MAE.
    let pred = dir.join("pred.csv");
    let simulate = |extra: &[&str]| {
        let mut c = kalibre();
        c.args(["simulate", "--model", "command", "--config"])
            .arg(&config)
            .arg("--params")
            .arg(out.join("report.json"))
            .arg("--out")
            .arg(&pred)
            .args(extra);
        run(&mut c)
    };
    let o = simulate(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let read = |path: &Path| -> Vec<(String, f64)> {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("scenario,output,value"));
        lines
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (format!("{},{}", f[0], f[1]), f[2].parse().unwrap())
            })
            .collect()
    };
    let (predicted, measured) = (read(&pred), read(&measurements));
    assert_eq!(predicted.len(), 12, "4 scenarios x 3 outputs");
    let mae = measured
        .iter()
        .map(|(key, m)| {
            let p = predicted.iter().find(|(k, _)| k == key).expect(key).1;
            (p - m).abs()
        })
        .sum::<f64>()
        / measured.len() as f64;
    let best = report(&out)["best"]["mae_c"].as_f64().unwrap();
    assert!(
        (mae - best).abs() <= 1e-6 * best.max(1e-9),
        "{mae} against the report's {best}"
    );
    // A hall's flags are refused by name, and half a hall is not taken for a model.
    let o = simulate(&["--vtk", dir.join("vtk").to_str().unwrap()]);
    assert_input_error(&o, "--vtk is about a hall");
    let o = simulate(&["--hall", "hall.json"]);
    assert_input_error(
        &o,
        "a hall's simulation needs --hall hall.json and --snapshots",
    );
}

/// The temperature-rise prior turned off (`--rise-weight 0`) binds nothing, so no
/// prior-data conflict is reported; with its weight on, the same narrow range binds.
#[test]
fn a_prior_turned_off_binds_nothing() {
    let dir = tmp("prior-off");
    let summary = |weight: &str, out: &str| {
        let o = run(on_dataset("calibrate", "of-dev-clean")
            .args(QUICK_CALIBRATION)
            .args(["--rise-range", "5,6", "--rise-weight", weight, "--out"])
            .arg(dir.join(out)));
        assert!(o.status.success(), "{}", stderr(&o));
        let html = std::fs::read_to_string(dir.join(out).join("report.html")).unwrap();
        (String::from_utf8_lossy(&o.stdout).into_owned(), html)
    };
    let (on, on_html) = summary("1", "on");
    assert!(on.contains("the temperature-rise prior binds"), "{on}");
    assert!(on_html.contains("The temperature-rise prior binds"));
    let (off, off_html) = summary("0", "off");
    assert!(!off.contains("prior binds"), "{off}");
    assert!(!off_html.contains("prior binds"));
}

/// A parameter that no template, argument or `env` value writes is one the program
/// cannot see (unless it reads `kalibre-run.json`): calibrating it would end wherever the
/// search left it, so it is warned of by name. A fixed one moves nothing and is not.
#[test]
fn a_parameter_the_program_cannot_see_is_warned_of() {
    let (dir, _, measurements) = setup("own-model-unwritten");
    let config = dir.join("unwritten.toml");
    let extra = "\n[[params]]\nname = \"fouling\"\nlower = 0.0\nupper = 1.0\ninitial = 0.5\n\
                 \n[[params]]\nname = \"spare\"\nlower = 1.0\nupper = 1.0\ninitial = 1.0\n";
    let toml = MODEL_TOML.replacen("\n[[scenarios]]", &format!("{extra}\n[[scenarios]]"), 1);
    std::fs::write(&config, toml).unwrap();
    let o = run(calibrate(&config, &measurements, &dir.join("out")).args([
        "--iterations",
        "1",
        "--polish",
        "0",
    ]));
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    let warned: Vec<&str> = err.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(warned.len(), 1, "{err}");
    assert!(
        warned[0].contains("params[3] `fouling` is written by no template")
            && warned[0].contains("unwritten.toml"),
        "{err}"
    );
    // The file the tests share writes every parameter: no warning.
    let (_, config, measurements) = setup("own-model-written");
    let o = run(calibrate(&config, &measurements, &dir.join("out2")).args([
        "--iterations",
        "1",
        "--polish",
        "0",
    ]));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
}
