//! The external command model against small script models in `tests/fixtures/`:
//! a working model, one that hangs, one that exits non-zero, one that prints NaN, one that
//! writes nothing, a flaky one, hostile labels, template and configuration errors.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use kalibre_core::external::{
    CommandModelConfig, ExternalCommand, ExternalError, FailureKind, KeepRuns, NamedScenario,
    OutputParser, RetryPolicy,
};
use kalibre_core::{Model, ModelError};
use rayon::prelude::*;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A fresh scratch directory for one test.
fn scratch(test: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("external")
        .join(test);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A builder for `sh <fixture>` writing `out.csv` in the long format.
fn sh_model(script: &str, runs: &Path, outputs: &[&str]) -> kalibre_core::external::CommandBuilder {
    ExternalCommand::<NamedScenario>::builder("sh", runs)
        .with_args([fixture(script).display().to_string()])
        .with_output("out.csv", OutputParser::CsvLong, outputs.iter().copied())
        .with_timeout(Duration::from_secs(10))
}

fn python_model(runs: &Path) -> kalibre_core::external::CommandBuilder {
    ExternalCommand::<NamedScenario>::builder("python3", runs)
        .with_args([
            fixture("model.py").display().to_string(),
            "params.in".into(),
            "out.csv".into(),
        ])
        .with_template_file(fixture("params.in.tmpl"), "params.in")
        .with_output("out.csv", OutputParser::CsvColumns, ["t_in", "t_out"])
        .with_params(["k", "h"])
        .with_timeout(Duration::from_secs(20))
}

fn log_tail(e: &ModelError) -> &str {
    match e {
        ModelError::Failed { log_tail, .. } | ModelError::Timeout { log_tail, .. } => {
            log_tail.as_deref().unwrap_or("")
        }
        _ => "",
    }
}

/// True when no live process has this pid (gone, or a zombie awaiting its reaper).
fn process_gone(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        // The state follows the parenthesised command name.
        Ok(stat) => stat
            .rsplit_once(')')
            .is_some_and(|(_, rest)| rest.trim_start().starts_with(['Z', 'X'])),
    }
}

/// Waits up to `limit` for the process to die: SIGKILL is certain, but on a loaded
/// machine the killed process may need a moment of CPU to exit.
fn dies_within(pid: u32, limit: Duration) -> bool {
    let t = Instant::now();
    while t.elapsed() < limit {
        if process_gone(pid) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    process_gone(pid)
}

fn dirs_in(root: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root)
        .map(|r| r.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn script_model_renders_runs_and_parses() {
    let root = scratch("script_model");
    let model: ExternalCommand = python_model(&root).build().unwrap();
    let scenario = NamedScenario::new("winter").with("ambient_c", 5.0);
    let (k, h) = (2.5, 8.0);
    let report = model.run(&scenario, &[k, h]);
    let out = report.outcome.expect("the script model runs");
    let t_in = 5.0 + 0.5 * k;
    let t_out = t_in + 1000.0 / (h * k);
    assert_eq!(out.values, vec![t_in, t_out]);
    // A successful run's directory is removed by default.
    assert_eq!(report.attempts.len(), 1);
    assert!(!report.attempts[0].kept);
    assert!(dirs_in(&root).is_empty());

    // Kept on request, with the rendered file and the run record.
    let model: ExternalCommand = python_model(&root)
        .with_keep(KeepRuns::All)
        .build()
        .unwrap();
    let report = model.run(&scenario, &[0.1234567, 8.0]);
    assert!(report.outcome.is_ok());
    let dir = report.attempts[0].run_dir.clone().unwrap();
    assert!(
        dir.starts_with(&root)
            && dir
                .file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .starts_with("winter-")
    );
    let rendered = std::fs::read_to_string(dir.join("params.in")).unwrap();
    assert!(
        rendered.contains("k = 0.123457\nh = 8\nambient_c = 5\n"),
        "{rendered}"
    );
    assert!(rendered.contains("scenario winter"));
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("kalibre-run.json")).unwrap())
            .unwrap();
    assert_eq!(record["variables"]["k"], 0.1234567);
    assert_eq!(record["attempt"], 1);
}

#[test]
fn fingerprint_covers_templates_and_parser_but_not_timeout() {
    let root = scratch("fingerprint");
    let fp = |b: kalibre_core::external::CommandBuilder| {
        Model::fingerprint(&b.build::<NamedScenario>().unwrap())
    };
    let base = fp(python_model(&root));
    assert_eq!(base, fp(python_model(&root)));
    assert_eq!(
        base,
        fp(python_model(&root).with_timeout(Duration::from_secs(99)))
    );
    let other_template = python_model(&root).with_template_text("extra", "x = {{k}}", "extra.in");
    assert_ne!(base, fp(other_template));
    let other_parser =
        python_model(&root).with_output("out.csv", OutputParser::CsvLong, ["t_in", "t_out"]);
    assert_ne!(base, fp(other_parser));
    assert_ne!(base, fp(python_model(&root).with_args(["model.py"])));
}

#[test]
fn regex_parser_reads_the_programs_stdout() {
    let root = scratch("regex_stdout");
    let parser =
        OutputParser::regex([("t_out", r"T_out = (\S+)"), ("t_in", r"T_in = (\S+)")]).unwrap();
    let model: ExternalCommand = python_model(&root)
        .with_output("stdout.log", parser, ["t_out", "t_in"])
        .build()
        .unwrap();
    let out = model
        .evaluate(
            &NamedScenario::new("s").with("ambient_c", 20.0),
            &[2.0, 5.0],
        )
        .unwrap();
    assert_eq!(out.values, vec![21.0 + 100.0, 21.0]);
}

#[test]
fn hanging_model_is_killed_with_its_children() {
    let root = scratch("hang");
    let model: ExternalCommand = sh_model("hang.sh", &root, &["a"])
        .with_timeout(Duration::from_millis(1000))
        .with_kill_grace(Duration::from_millis(500))
        .build()
        .unwrap();
    let t = Instant::now();
    let report = model.run(&NamedScenario::new("hang"), &[]);
    let elapsed = t.elapsed();
    let err = report.outcome.unwrap_err();
    assert!(
        matches!(err, ModelError::Timeout { seconds, .. } if seconds == 1.0),
        "{err:?}"
    );
    assert!(elapsed < Duration::from_secs(4), "took {elapsed:?}");
    assert!(
        log_tail(&err).contains("started child"),
        "{}",
        log_tail(&err)
    );
    assert_eq!(report.attempts[0].failure, Some(FailureKind::Timeout));
    let dir = report.attempts[0].run_dir.clone().unwrap();
    assert!(
        report.attempts[0].kept && dir.is_dir(),
        "a failed run's directory is kept"
    );
    let pid: u32 = std::fs::read_to_string(dir.join("child.pid"))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert!(
        dies_within(pid, Duration::from_secs(3)),
        "the child `sleep 60` (pid {pid}) survived the timeout"
    );
}

#[test]
fn program_ignoring_sigterm_is_sigkilled() {
    let root = scratch("ignore_term");
    let model: ExternalCommand = sh_model("ignore_term.sh", &root, &["a"])
        .with_timeout(Duration::from_millis(500))
        .with_kill_grace(Duration::from_millis(300))
        .build()
        .unwrap();
    let t = Instant::now();
    let err = model
        .evaluate(&NamedScenario::new("stubborn"), &[])
        .unwrap_err();
    assert!(matches!(err, ModelError::Timeout { .. }), "{err:?}");
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "took {:?}",
        t.elapsed()
    );
}

#[test]
fn nonzero_exit_is_failed_with_code_and_log_tail() {
    let root = scratch("fail");
    let model: ExternalCommand = sh_model("fail.sh", &root, &["a"]).build().unwrap();
    let err = model.evaluate(&NamedScenario::new("f"), &[]).unwrap_err();
    let ModelError::Failed { reason, .. } = &err else {
        panic!("expected Failed, got {err:?}")
    };
    assert!(reason.contains("exited with code 3"), "{reason}");
    let tail = log_tail(&err);
    assert!(tail.contains("boom: solver diverged"), "{tail}");
    assert!(
        tail.contains("line 50\n") && !tail.contains("line 5\n"),
        "{tail}"
    );
    assert!(tail.lines().count() <= 40 + 3, "{tail}");
    assert!(tail.starts_with("run dir: "), "{tail}");
}

#[test]
fn nan_output_is_non_finite() {
    let root = scratch("nan");
    let model: ExternalCommand = sh_model("nan.sh", &root, &["a", "b"]).build().unwrap();
    let report = model.run(&NamedScenario::new("n"), &[]);
    match report.outcome.unwrap_err() {
        ModelError::NonFinite { index, name, .. } => assert_eq!((index, name.as_str()), (1, "b")),
        e => panic!("expected NonFinite, got {e:?}"),
    }
    assert_eq!(report.attempts[0].failure, Some(FailureKind::NonFinite));
}

#[test]
fn missing_output_file_is_failed() {
    let root = scratch("no_output");
    let model: ExternalCommand = sh_model("no_output.sh", &root, &["a"]).build().unwrap();
    let err = model.evaluate(&NamedScenario::new("m"), &[]).unwrap_err();
    let ModelError::Failed { reason, .. } = &err else {
        panic!("expected Failed, got {err:?}")
    };
    assert!(
        reason.contains("did not write the output file out.csv"),
        "{reason}"
    );
    assert!(log_tail(&err).contains("forgot the output"));
}

#[test]
fn shell_metacharacters_are_data_not_commands() {
    let root = scratch("injection");
    let model: ExternalCommand = sh_model("echo_args.sh", &root, &["n_args"])
        .with_args([
            fixture("echo_args.sh").display().to_string(),
            "{{scenario}}".into(),
            "--x={{x}}".into(),
        ])
        .with_template_text("inline", "label = {{scenario}}\n", "in.txt")
        .with_params(["x"])
        .with_keep(KeepRuns::All)
        .build()
        .unwrap();
    for label in [
        "x; touch pwned1",
        "$(touch pwned2)",
        "`touch pwned3` && touch pwned4 | cat",
    ] {
        let report = model.run(&NamedScenario::new(label), &[1.5]);
        assert_eq!(
            report.outcome.unwrap().values,
            vec![2.0],
            "two arguments for `{label}`"
        );
        let dir = report.attempts[0].run_dir.clone().unwrap();
        let args = std::fs::read_to_string(dir.join("args.txt")).unwrap();
        assert_eq!(args, format!("{label}\n--x=1.5\n"));
        let name = dir.file_name().unwrap().to_str().unwrap();
        assert!(
            name.chars()
                .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c)),
            "{name}"
        );
        assert_eq!(dir.parent().unwrap(), root);
        for d in [dir.as_path(), root.as_path(), Path::new(".")] {
            for n in 1..=4 {
                assert!(
                    !d.join(format!("pwned{n}")).exists(),
                    "a label ran a command in {}",
                    d.display()
                );
            }
        }
    }
}

#[test]
fn a_flaky_model_succeeds_on_retry() {
    let root = scratch("flaky");
    let state = root.join("state");
    let build = |retry: RetryPolicy| -> ExternalCommand {
        sh_model("flaky.sh", &root.join("runs"), &["a"])
            .with_args([fixture("flaky.sh").display().to_string(), "{{x}}".into()])
            .with_params(["x"])
            .with_env("FLAKY_STATE", state.display().to_string())
            .with_retry(retry)
            .build()
            .unwrap()
    };
    let retrying = build(RetryPolicy {
        max_attempts: 2,
        on: vec![FailureKind::Exit],
    });
    let report = retrying.run(&NamedScenario::new("r"), &[4.0]);
    assert_eq!(report.outcome.unwrap().values, vec![4.0]);
    assert_eq!(report.attempts.len(), 2);
    assert_eq!(report.attempts[0].failure, Some(FailureKind::Exit));
    assert!(report.attempts[0].kept && !report.attempts[1].kept);
    assert_ne!(report.attempts[0].run_dir, report.attempts[1].run_dir);

    // A failure kind the policy does not name is not retried.
    std::fs::remove_file(&state).unwrap();
    let timeouts_only = build(RetryPolicy {
        max_attempts: 3,
        on: vec![FailureKind::Timeout],
    });
    let report = timeouts_only.run(&NamedScenario::new("r"), &[4.0]);
    assert!(matches!(report.outcome, Err(ModelError::Failed { .. })));
    assert_eq!(report.attempts.len(), 1);
}

#[test]
fn parallel_runs_get_their_own_directories() {
    let root = scratch("parallel");
    let model: ExternalCommand = python_model(&root)
        .with_keep(KeepRuns::All)
        .build()
        .unwrap();
    let s = NamedScenario::new("same").with("ambient_c", 1.0);
    let reports: Vec<_> = (0..4)
        .into_par_iter()
        .map(|_| model.run(&s, &[1.0, 10.0]))
        .collect();
    let mut dirs: Vec<_> = reports
        .iter()
        .map(|r| {
            assert_eq!(r.outcome.as_ref().unwrap().values, vec![1.5, 101.5]);
            r.attempts[0].run_dir.clone().unwrap()
        })
        .collect();
    dirs.sort();
    dirs.dedup();
    assert_eq!(dirs.len(), 4, "identical runs share no directory");
}

#[test]
fn template_errors_name_file_and_placeholder() {
    let root = scratch("template_errors");
    let tmpl = root.join("bad.tmpl");
    std::fs::write(&tmpl, "k = {{k}}\nq = {{qq:.3}}\n").unwrap();
    let model: ExternalCommand = sh_model("nan.sh", &root.join("runs"), &["a"])
        .with_template_file(&tmpl, "bad.in")
        .with_params(["k"])
        .with_retry(RetryPolicy {
            max_attempts: 3,
            on: FailureKind::RETRYABLE.to_vec(),
        })
        .build()
        .unwrap();
    let report = model.run(&NamedScenario::new("t"), &[1.0]);
    let ModelError::Failed { reason, .. } = report.outcome.unwrap_err() else {
        panic!("expected Failed")
    };
    assert!(
        reason.contains(&tmpl.display().to_string())
            && reason.contains("`qq:.3`")
            && reason.contains("line 2"),
        "{reason}"
    );
    assert_eq!(report.attempts.len(), 1, "setup failures are not retried");

    // Checked up front for a known scenario.
    match model.check_scenario(&NamedScenario::new("t")).unwrap_err() {
        ExternalError::Template {
            file,
            placeholder,
            line,
            ..
        } => {
            assert_eq!(
                (file, placeholder.as_str(), line),
                (tmpl.display().to_string(), "qq:.3", 2)
            );
        }
        e => panic!("{e}"),
    }
    assert!(model
        .check_scenario(&NamedScenario::new("t").with("qq", 1.0))
        .is_ok());
    let clash = model.check_scenario(&NamedScenario::new("t").with("qq", 1.0).with("k", 2.0));
    assert!(clash.unwrap_err().to_string().contains("`k`"));
}

/// Copies the example configuration and its files into a scratch directory.
fn example_config(test: &str) -> (PathBuf, String) {
    let dir = scratch(test);
    for f in ["model.toml", "model.py", "params.in.tmpl"] {
        std::fs::copy(fixture(f), dir.join(f)).unwrap();
    }
    let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    (dir, text)
}

#[test]
fn example_config_loads_and_runs() {
    let (dir, _) = example_config("config_example");
    let cfg = CommandModelConfig::load(dir.join("model.toml")).unwrap();
    assert_eq!(cfg.space.names(), ["k", "h"]);
    assert_eq!(cfg.command.output_names(), ["t_in", "t_out"]);
    assert_eq!(cfg.command.retry().max_attempts, 2);
    assert_eq!(cfg.command.runs_root(), dir.join("runs"));
    let labels: Vec<_> = cfg.scenarios.iter().map(|s| s.label.as_str()).collect();
    assert_eq!(labels, ["winter", "summer"]);
    let x = cfg.space.initial();
    for (s, ambient) in cfg.scenarios.iter().zip([5.0, 30.0]) {
        let out = cfg.command.evaluate(s, &x).unwrap();
        let t_in = ambient + 0.5 * 2.5;
        assert_eq!(out.values, vec![t_in, t_in + 1000.0 / 25.0]);
    }
    // Editing the script changes the fingerprint (fingerprint_files).
    let before = cfg.command.fingerprint();
    std::fs::write(dir.join("model.py"), "# edited\n").unwrap();
    let after = CommandModelConfig::load(dir.join("model.toml")).unwrap();
    assert_ne!(before, after.command.fingerprint());
}

#[test]
fn config_errors_name_the_key() {
    let (dir, text) = example_config("config_errors");
    let file = dir.join("model.toml");
    let key_of = |edited: String| match CommandModelConfig::from_toml_str(&edited, &file) {
        Err(ExternalError::Config { key, file: f, .. }) => {
            assert_eq!(f, file.display().to_string());
            key
        }
        Err(e) => panic!("not a config error: {e}"),
        Ok(_) => panic!("accepted a bad config"),
    };
    assert_eq!(
        key_of(text.replace("timeout_s = 30", "timout_s = 30")),
        "timout_s"
    );
    assert_eq!(key_of(text.replace("timeout_s = 30\n", "")), "timeout_s");
    assert_eq!(
        key_of(text.replace("timeout_s = 30", "timeout_s = -1")),
        "timeout_s"
    );
    assert_eq!(
        key_of(text.replace("upper = 100.0", "upper = \"high\"")),
        "params[1].upper"
    );
    assert_eq!(
        key_of(text.replace("initial = 10.0", "initial = 1000.0")),
        "params[1]"
    );
    assert_eq!(
        key_of(text.replace("scale = \"log\"", "scale = \"ln\"")),
        "params[0].scale"
    );
    assert_eq!(
        key_of(text.replace("parser = \"csv\" ", "parser = \"json\"")),
        "output.parser"
    );
    assert_eq!(
        key_of(text.replace(
            "retry_on = [\"timeout\", \"exit\"]",
            "retry_on = [\"timeout\", \"segfault\"]"
        )),
        "retry_on[1]"
    );
    assert_eq!(
        key_of(text.replace(
            "destination = \"params.in\"",
            "destination = \"../escape.in\""
        )),
        "templates[0].destination"
    );
    assert_eq!(
        key_of(text.replace("source = \"params.in.tmpl\"", "source = \"missing.tmpl\"")),
        "templates[0].source"
    );
    assert_eq!(
        key_of(text.replace(
            "parser = \"csv\" ",
            "parser = \"regex\"\nregex = { t_in = 'a(b)(c)', t_out = 'x(y)' }\n"
        )),
        "output.regex.t_in"
    );
    assert_eq!(
        key_of(text.replace(
            "variables = { ambient_c = 5.0 }",
            "variables = { ambient_c = 5.0, k = 1.0 }"
        )),
        "scenarios[0].variables"
    );
    assert_eq!(
        key_of(text.replace("label = \"summer\"", "label = \"winter\"")),
        "scenarios[1].label"
    );
    assert_eq!(
        key_of(text.replace("timeout_s = 30", "timeout_s = 30 30")),
        "line 6"
    );
    // A failure that repeats every time would be retried without end.
    assert_eq!(
        key_of(text.replace("retries = 1 ", "retries = 1000000000 ")),
        "retries"
    );
    // A placeholder no scenario provides names its template.
    std::fs::write(dir.join("params.in.tmpl"), "k = {{k}}\nx = {{ambient}}\n").unwrap();
    match CommandModelConfig::load(&file).unwrap_err() {
        ExternalError::Template {
            file, placeholder, ..
        } => {
            assert!(
                file.ends_with("params.in.tmpl") && placeholder == "ambient",
                "{file} {placeholder}"
            );
        }
        e => panic!("{e}"),
    }
    // So does a number's format on a text value, before any run.
    std::fs::write(dir.join("params.in.tmpl"), "k = {{k}}\n# {{scenario:.3}}\n").unwrap();
    match CommandModelConfig::load(&file).unwrap_err() {
        ExternalError::Template {
            line, placeholder, ..
        } => assert_eq!((line, placeholder.as_str()), (2, "scenario:.3")),
        e => panic!("{e}"),
    }
}

/// Where the scenarios come from elsewhere, a `[[scenarios]]` list is refused as such
/// (not for a variable its entries lack), and a file without one loads as with `load`.
#[test]
fn a_file_whose_scenarios_come_from_elsewhere_refuses_a_scenarios_list() {
    let (dir, text) = example_config("config_no_scenarios");
    let file = dir.join("model.toml");
    match CommandModelConfig::load_without_scenarios(&file, "the snapshots are the scenarios")
        .unwrap_err()
    {
        ExternalError::Config { key, reason, .. } => {
            assert_eq!(key, "scenarios");
            assert_eq!(reason, "the snapshots are the scenarios");
        }
        e => panic!("{e}"),
    }
    let without = &text[..text
        .find("[[scenarios]]")
        .expect("the example lists scenarios")];
    std::fs::write(&file, without).unwrap();
    let cfg = CommandModelConfig::load_without_scenarios(&file, "unused").unwrap();
    assert!(cfg.scenarios.is_empty());
    assert_eq!(
        cfg.space.names(),
        CommandModelConfig::load(&file).unwrap().space.names()
    );
}
