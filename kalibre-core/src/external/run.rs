//! One run of an [`ExternalCommand`]: attempts, each in a fresh directory.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::command::{
    AttemptReport, ExternalCommand, FailureKind, KeepRuns, RunReport, BUILTINS, RUN_RECORD,
};
use super::process::{log_tail, run_process, ProcessEnd, ProcessSpec};
use super::template::{Template, TemplateValue, Variables};
use super::{ExternalError, StableHasher, TemplateScenario};
use crate::{check_outputs, ModelError, Outputs};

type Failure = (FailureKind, ModelError);

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGSEGV => " (SIGSEGV)",
        libc::SIGKILL => " (SIGKILL: out of memory?)",
        libc::SIGABRT => " (SIGABRT)",
        libc::SIGFPE => " (SIGFPE)",
        libc::SIGBUS => " (SIGBUS)",
        libc::SIGTERM => " (SIGTERM)",
        libc::SIGINT => " (SIGINT)",
        _ => "",
    }
}

impl<S: TemplateScenario> ExternalCommand<S> {
    /// The variables of a scenario and parameters, without the per-attempt built-ins.
    fn base_variables(&self, scenario: &S, params: &[f64]) -> Result<Variables, String> {
        let mut vars = Variables::new();
        vars.insert(
            "scenario",
            TemplateValue::Text(scenario.label().to_string()),
        );
        if let Some(d) = &self.config_dir {
            vars.insert("config_dir", TemplateValue::Text(d.display().to_string()));
        }
        for (n, &x) in self.param_names.iter().zip(params) {
            vars.insert(n.clone(), TemplateValue::Number(x));
        }
        for (n, v) in scenario.variables() {
            if BUILTINS.contains(&n.as_str()) {
                return Err(format!("scenario variable `{n}` is a reserved name"));
            }
            if vars.insert(n.clone(), v).is_some() {
                return Err(format!(
                    "scenario variable `{n}` has the name of a parameter or another variable"
                ));
            }
        }
        Ok(vars)
    }

    /// Every text a run renders: the arguments, the environment values and the template
    /// files.
    fn every_template(&self) -> impl Iterator<Item = &Template> {
        self.args
            .iter()
            .chain(self.env.iter().map(|(_, t)| t))
            .chain(self.templates.iter().map(|t| &t.template))
    }

    /// Checks that every placeholder of the templates, arguments and environment resolves
    /// for `scenario` (a number's format only on a number) and that its variables clash
    /// with no parameter or built-in name.
    pub fn check_scenario(&self, scenario: &S) -> Result<(), ExternalError> {
        let zeros = vec![0.0; self.param_names.len()];
        let mut vars = self.base_variables(scenario, &zeros).map_err(|reason| {
            ExternalError::setting(format!("scenario `{}`", scenario.label()), reason)
        })?;
        vars.insert("run_dir", TemplateValue::Text(String::new()));
        vars.insert("attempt", TemplateValue::Number(1.0));
        // A trial rendering: an unknown name, or a number's format on a text value
        // (`{{scenario:.3}}`), is refused here rather than failing every run.
        for t in self.every_template() {
            t.render(&vars)?;
        }
        Ok(())
    }

    /// The parameters that no template, argument or environment value writes: the
    /// program can see them only by reading `kalibre-run.json`, so when it does not,
    /// calibrating them moves nothing.
    pub fn unwritten_params(&self) -> Vec<&str> {
        let written: std::collections::BTreeSet<&str> = self
            .every_template()
            .flat_map(|t| t.placeholders())
            .collect();
        self.param_names
            .iter()
            .map(String::as_str)
            .filter(|p| !written.contains(p))
            .collect()
    }

    /// Runs the model with every attempt the retry policy allows, and reports each.
    pub fn run(&self, scenario: &S, params: &[f64]) -> RunReport {
        let refuse = |reason: String| RunReport {
            outcome: Err(ModelError::InvalidParams(reason)),
            attempts: Vec::new(),
        };
        if params.len() != self.param_names.len() {
            return refuse(format!(
                "expected {} parameter values, got {}",
                self.param_names.len(),
                params.len()
            ));
        }
        if let Some((n, x)) = self
            .param_names
            .iter()
            .zip(params)
            .find(|(_, x)| !x.is_finite())
        {
            return refuse(format!("parameter `{n}` is {x}"));
        }
        let base = match self.base_variables(scenario, params) {
            Ok(v) => v,
            Err(reason) => {
                return RunReport {
                    outcome: Err(ModelError::failed(reason)),
                    attempts: Vec::new(),
                }
            }
        };
        let mut h = StableHasher::new();
        h.field(scenario.label());
        for (n, v) in scenario.variables() {
            h.field(n);
            match v {
                TemplateValue::Number(x) => h.field(x.to_bits().to_le_bytes()),
                TemplateValue::Text(t) => h.field(t),
            };
        }
        for x in params {
            h.field(x.to_bits().to_le_bytes());
        }
        let key = h.finish();

        let mut attempts = Vec::new();
        let max = self.retry.max_attempts.max(1);
        let mut n = 1;
        loop {
            let (result, report) = self.attempt(scenario.label(), &base, n, key);
            attempts.push(report);
            match result {
                Ok(outputs) => {
                    return RunReport {
                        outcome: Ok(outputs),
                        attempts,
                    }
                }
                Err((kind, _)) if n < max && self.retry.on.contains(&kind) => n += 1,
                Err((_, err)) => {
                    let err = match err {
                        ModelError::Failed { reason, log_tail } if n > 1 => ModelError::Failed {
                            reason: format!("{reason} (attempt {n} of {max})"),
                            log_tail,
                        },
                        e => e,
                    };
                    return RunReport {
                        outcome: Err(err),
                        attempts,
                    };
                }
            }
        }
    }

    fn attempt(
        &self,
        label: &str,
        base: &Variables,
        attempt: u32,
        key: u128,
    ) -> (Result<Outputs, Failure>, AttemptReport) {
        let t0 = Instant::now();
        let mut report = AttemptReport {
            run_dir: None,
            kept: false,
            failure: None,
            setup: Duration::ZERO,
            process: Duration::ZERO,
            parse: Duration::ZERO,
            cleanup: Duration::ZERO,
        };
        let dir = match self.dirs.create(label, key) {
            Ok(d) => d,
            Err(e) => {
                report.setup = t0.elapsed();
                report.failure = Some(FailureKind::Setup);
                let reason = format!(
                    "cannot create a run directory under {}: {e}",
                    self.dirs.root().display()
                );
                return (
                    Err((FailureKind::Setup, ModelError::failed(reason))),
                    report,
                );
            }
        };
        report.run_dir = Some(dir.to_path_buf());
        report.kept = true;
        let result = self.attempt_in(&dir, base, attempt, &mut report, t0);
        match &result {
            Ok(_) if self.keep == KeepRuns::Failed => {
                let t = Instant::now();
                // A directory that cannot be removed stays; it is never reused anyway.
                report.kept = std::fs::remove_dir_all(&dir).is_err();
                report.cleanup = t.elapsed();
            }
            Ok(_) => {}
            Err((kind, _)) => report.failure = Some(*kind),
        }
        (result, report)
    }

    fn attempt_in(
        &self,
        dir: &Path,
        base: &Variables,
        attempt: u32,
        report: &mut AttemptReport,
        t0: Instant,
    ) -> Result<Outputs, Failure> {
        let tail = || {
            let mut tail = format!("run dir: {}\n", dir.display());
            if let Some(t) = log_tail(dir, self.log_lines) {
                tail.push_str(&t);
            }
            tail
        };
        let with_tail = |reason: String| ModelError::Failed {
            reason,
            log_tail: Some(tail()),
        };
        let setup_err = |reason: String| (FailureKind::Setup, with_tail(reason));

        let mut vars = base.clone();
        vars.insert("run_dir", TemplateValue::Text(dir.display().to_string()));
        vars.insert("attempt", TemplateValue::Number(f64::from(attempt)));
        let render_err = |e: ExternalError| setup_err(e.to_string());
        for t in &self.templates {
            let text = t.template.render(&vars).map_err(render_err)?;
            let path = dir.join(&t.destination);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)
                    .map_err(|e| setup_err(format!("{}: {e}", parent.display())))?;
            }
            std::fs::write(&path, text)
                .map_err(|e| setup_err(format!("{}: {e}", path.display())))?;
        }
        let args = self
            .args
            .iter()
            .map(|t| t.render(&vars))
            .collect::<Result<Vec<_>, _>>()
            .map_err(render_err)?;
        let mut env = vec![
            ("KALIBRE_RUN_DIR".to_string(), dir.display().to_string()),
            ("KALIBRE_ATTEMPT".to_string(), attempt.to_string()),
        ];
        for (k, t) in &self.env {
            env.push((k.clone(), t.render(&vars).map_err(render_err)?));
        }
        self.write_record(dir, &vars, attempt, &args)
            .map_err(|e| setup_err(format!("{}: {e}", dir.join(RUN_RECORD).display())))?;
        report.setup = t0.elapsed();

        let spec = ProcessSpec {
            program: &self.program,
            args: &args,
            env: &env,
            dir,
            timeout: self.timeout,
            kill_grace: self.kill_grace,
        };
        let program = Path::new(&self.program).display();
        let outcome =
            run_process(&spec).map_err(|e| setup_err(format!("cannot run `{program}`: {e}")))?;
        report.process = outcome.elapsed;
        match outcome.end {
            ProcessEnd::Exited(0) => {}
            ProcessEnd::Exited(code) => {
                return Err((
                    FailureKind::Exit,
                    with_tail(format!("`{program}` exited with code {code}")),
                ))
            }
            ProcessEnd::Signalled(sig) => {
                return Err((
                    FailureKind::Exit,
                    with_tail(format!(
                        "`{program}` was killed by signal {sig}{}",
                        signal_name(sig)
                    )),
                ))
            }
            ProcessEnd::TimedOut { .. } => {
                return Err((
                    FailureKind::Timeout,
                    ModelError::Timeout {
                        seconds: self.timeout.as_secs_f64(),
                        log_tail: Some(tail()),
                    },
                ));
            }
        }

        let t = Instant::now();
        let path: PathBuf = dir.join(&self.output_file);
        let file = self.output_file.display().to_string();
        let text = std::fs::read_to_string(&path).map_err(|e| {
            let reason = if e.kind() == std::io::ErrorKind::NotFound {
                format!("`{program}` exited 0 but did not write the output file {file}")
            } else {
                format!("cannot read the output file {file}: {e}")
            };
            (FailureKind::Output, with_tail(reason))
        })?;
        let values = self
            .parser
            .parse(&text, &file, &self.output_names)
            .map_err(|reason| (FailureKind::Output, with_tail(reason)))?;
        let checked = check_outputs(values.into(), &self.output_names).map_err(|e| {
            let kind = match e {
                ModelError::NonFinite { .. } => FailureKind::NonFinite,
                _ => FailureKind::Output,
            };
            // The kept directory and the log say where the value came from.
            (kind, e.with_log_tail(|_| Some(tail())))
        });
        report.parse = t.elapsed();
        checked
    }

    /// Writes what this attempt runs, so a kept directory explains itself.
    fn write_record(
        &self,
        dir: &Path,
        vars: &Variables,
        attempt: u32,
        args: &[String],
    ) -> std::io::Result<()> {
        let json = |v: &TemplateValue| match v {
            TemplateValue::Number(x) => serde_json::json!(x),
            TemplateValue::Text(t) => serde_json::json!(t),
        };
        let variables: serde_json::Map<String, serde_json::Value> =
            vars.iter().map(|(n, v)| (n.to_string(), json(v))).collect();
        let record = serde_json::json!({
            "attempt": attempt,
            "variables": variables,
            "params": self.param_names,
            "program": Path::new(&self.program).display().to_string(),
            "args": args,
            "fingerprint": self.fingerprint,
        });
        std::fs::write(dir.join(RUN_RECORD), record.to_string())
    }
}
