//! The external command model against small script models in `tests/fixtures/`:
//! a working model, one that hangs, one that exits non-zero, one that prints NaN, one that
//! writes nothing, a flaky one, hostile labels, template errors. The configuration file
//! is `external_config.rs`'s.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use kalibre_core::external::{
    ExternalCommand, ExternalError, FailureKind, KeepRuns, NamedScenario, OutputParser, RetryPolicy,
};
use kalibre_core::{Model, ModelError};
use rayon::prelude::*;

mod external_support;
use external_support::{fixture, scratch};

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

/// The command names its parameters and outputs to the loop, which checks them against
/// the parameter space and the observations.
#[test]
fn the_command_names_its_parameters_and_outputs_to_the_loop() {
    let root = scratch("names");
    let cmd = python_model(&root).build::<NamedScenario>().unwrap();
    assert_eq!(
        Model::param_names(&cmd),
        Some(vec!["k".to_string(), "h".to_string()])
    );
    assert_eq!(
        Model::output_names(&cmd),
        Some(vec!["t_in".to_string(), "t_out".to_string()])
    );
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
    let e = report.outcome.unwrap_err();
    match &e {
        ModelError::NonFinite { index, name, .. } => assert_eq!((*index, name.as_str()), (1, "b")),
        e => panic!("expected NonFinite, got {e:?}"),
    }
    assert_eq!(report.attempts[0].failure, Some(FailureKind::NonFinite));
    // Where the value came from: the kept directory, named as for any failed run.
    let kept = report.attempts[0].run_dir.as_ref().unwrap();
    assert_eq!(
        e.run_dir(),
        Some(kept.display().to_string().as_str()),
        "{e:?}"
    );
    assert!(kept.is_dir());
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
