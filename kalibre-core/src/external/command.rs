//! [`ExternalCommand`]: the model, its builder and its settings.

use std::ffi::OsString;
use std::marker::PhantomData;
use std::path::{Component, Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::parse::OutputParser;
use super::parts::Parts;
use super::process::{STDERR_LOG, STDOUT_LOG};
use super::rundir::RunDirs;
use super::template::Template;
use super::{ExternalError, NamedScenario, StableHasher, TemplateScenario};
use crate::{Model, ModelError, Outputs};

/// Names every template can use besides parameters and scenario variables.
pub(crate) const BUILTINS: [&str; 4] = ["scenario", "run_dir", "attempt", "config_dir"];
/// The file in each run directory that records what was run.
pub(crate) const RUN_RECORD: &str = "kalibre-run.json";
/// Program files up to this size are hashed into the fingerprint; larger ones by size.
const MAX_HASHED_PROGRAM: u64 = 16 << 20;

/// The kind of a failed attempt, for the [`RetryPolicy`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureKind {
    /// The run could not be set up: directory, template, program not startable. Never
    /// retried (it would fail the same way).
    Setup,
    /// The wall-clock limit was hit.
    Timeout,
    /// The program exited non-zero or was killed by a signal it did not get from us.
    Exit,
    /// The output file is missing or an output is missing or not a number.
    Output,
    /// An output is NaN or infinite.
    NonFinite,
}

impl FailureKind {
    /// The kind's name in configuration files.
    pub fn name(self) -> &'static str {
        match self {
            FailureKind::Setup => "setup",
            FailureKind::Timeout => "timeout",
            FailureKind::Exit => "exit",
            FailureKind::Output => "output",
            FailureKind::NonFinite => "non_finite",
        }
    }

    /// The kinds a retry policy may name (all but [`FailureKind::Setup`]).
    pub const RETRYABLE: [FailureKind; 4] = [
        FailureKind::Timeout,
        FailureKind::Exit,
        FailureKind::Output,
        FailureKind::NonFinite,
    ];
}

/// How often a run is attempted and after which failures it is attempted again. Each
/// attempt runs in a fresh directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RetryPolicy {
    /// Attempts in all (1 = no retry).
    pub max_attempts: u32,
    /// Failure kinds that earn another attempt.
    pub on: Vec<FailureKind>,
}

impl Default for RetryPolicy {
    /// One attempt; if attempts are raised, timeouts and crashes are retried (the
    /// transient failures of clusters: preempted jobs, lost nodes).
    fn default() -> Self {
        RetryPolicy {
            max_attempts: 1,
            on: vec![FailureKind::Timeout, FailureKind::Exit],
        }
    }
}

/// Which run directories stay on disk after the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KeepRuns {
    /// Failed attempts' directories (for inspection); successful ones are removed.
    #[default]
    Failed,
    /// Every directory.
    All,
}

/// An input file rendered into each run directory.
#[derive(Debug, Clone)]
pub struct TemplateFile {
    /// Where it goes, relative to the run directory.
    pub destination: PathBuf,
    /// Its template.
    pub template: Template,
}

/// What happened in one attempt of a run.
#[derive(Debug, Clone)]
pub struct AttemptReport {
    /// The attempt's directory (`None` if it could not be created).
    pub run_dir: Option<PathBuf>,
    /// Whether the directory is still on disk.
    pub kept: bool,
    /// Why the attempt failed, if it did.
    pub failure: Option<FailureKind>,
    /// Directory creation, template rendering, run record.
    pub setup: Duration,
    /// Spawn to reap, including the program's own run time.
    pub process: Duration,
    /// Reading and parsing the output file.
    pub parse: Duration,
    /// Removing the directory of a successful run.
    pub cleanup: Duration,
}

/// A run: its outcome and every attempt.
#[derive(Debug, Clone)]
pub struct RunReport {
    /// The outputs, or the last attempt's failure.
    pub outcome: Result<Outputs, ModelError>,
    /// The attempts in order.
    pub attempts: Vec<AttemptReport>,
}

/// A simulator run as an external program, one fresh directory per run (see the
/// [module documentation](super)). Build it with [`ExternalCommand::builder`] or load it
/// from a file with [`super::CommandModelConfig::load`].
///
/// It holds no mutable state: parallel calls to [`Model::evaluate`] are independent.
#[derive(Debug)]
pub struct ExternalCommand<S = NamedScenario> {
    pub(crate) program: OsString,
    pub(crate) args: Vec<Template>,
    pub(crate) env: Vec<(String, Template)>,
    pub(crate) templates: Vec<TemplateFile>,
    pub(crate) output_file: PathBuf,
    pub(crate) parser: OutputParser,
    pub(crate) output_names: Vec<String>,
    pub(crate) param_names: Vec<String>,
    pub(crate) timeout: Duration,
    pub(crate) kill_grace: Duration,
    pub(crate) retry: RetryPolicy,
    pub(crate) dirs: RunDirs,
    pub(crate) keep: KeepRuns,
    pub(crate) log_lines: usize,
    pub(crate) config_dir: Option<PathBuf>,
    pub(crate) fingerprint: String,
    /// Each part of the fingerprint with its own digest ([`ExternalCommand::fingerprint_parts`]).
    pub(crate) fingerprint_parts: Vec<(String, String)>,
    _scenario: PhantomData<fn(&S)>,
}

/// Builds an [`ExternalCommand`]; everything is checked once, in [`CommandBuilder::build`].
#[derive(Debug, Clone)]
pub struct CommandBuilder {
    program: PathBuf,
    runs_root: PathBuf,
    args: Vec<String>,
    env: Vec<(String, String)>,
    templates: Vec<(TemplateSource, PathBuf)>,
    output: Option<(PathBuf, OutputParser, Vec<String>)>,
    param_names: Vec<String>,
    timeout: Option<Duration>,
    kill_grace: Duration,
    retry: RetryPolicy,
    keep: KeepRuns,
    fingerprint_files: Vec<PathBuf>,
    log_lines: usize,
    config_dir: Option<PathBuf>,
}

#[derive(Debug, Clone)]
enum TemplateSource {
    File(PathBuf),
    Text(String, String),
}

impl ExternalCommand {
    /// A builder for `program` (a path, or a name looked up in `PATH`) with run
    /// directories under `runs_root`; the same as [`CommandBuilder::new`]. The scenario
    /// type is chosen by [`CommandBuilder::build`].
    pub fn builder(program: impl Into<PathBuf>, runs_root: impl Into<PathBuf>) -> CommandBuilder {
        CommandBuilder::new(program, runs_root)
    }
}

impl<S> ExternalCommand<S> {
    /// Parameter names, in the order of the values `evaluate` takes.
    pub fn param_names(&self) -> &[String] {
        &self.param_names
    }

    /// Output names, in the order of the returned values.
    pub fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// The fingerprint's parts, each with its own digest: `program` (its path and, named
    /// by path, its content), `args`, `env`, `template SOURCE`, `output`, `params`, and
    /// each fingerprint file by its path. Kept beside a journal, they name what changed
    /// when a later command's fingerprint differs ([`super::changed_parts`]).
    pub fn fingerprint_parts(&self) -> &[(String, String)] {
        &self.fingerprint_parts
    }

    /// Where run directories go.
    pub fn runs_root(&self) -> &Path {
        self.dirs.root()
    }

    /// Removes the run directories that runs killed mid-run (a calibration stopped with
    /// `kill -9`, a lost node) left under the runs root, and returns them; see
    /// [`RunDirs::remove_interrupted`]. Live runs and kept failed runs stay. Call it when
    /// a calibration starts; the CLI does.
    pub fn remove_interrupted_runs(&self) -> std::io::Result<Vec<PathBuf>> {
        self.dirs.remove_interrupted()
    }

    /// The wall-clock limit of one attempt.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// The retry policy.
    pub fn retry(&self) -> &RetryPolicy {
        &self.retry
    }
}

fn relative_inside(path: &Path) -> bool {
    !path.as_os_str().is_empty()
        && path
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
}

impl CommandBuilder {
    /// A builder for `program` (a path, or a name looked up in `PATH`) with run
    /// directories under `runs_root`.
    pub fn new(program: impl Into<PathBuf>, runs_root: impl Into<PathBuf>) -> Self {
        CommandBuilder {
            program: program.into(),
            runs_root: runs_root.into(),
            args: Vec::new(),
            env: Vec::new(),
            templates: Vec::new(),
            output: None,
            param_names: Vec::new(),
            timeout: None,
            kill_grace: Duration::from_secs(5),
            retry: RetryPolicy::default(),
            keep: KeepRuns::default(),
            fingerprint_files: Vec::new(),
            log_lines: 40,
            config_dir: None,
        }
    }

    /// Program arguments; each may hold placeholders and stays one argument after substitution.
    pub fn with_args<A: Into<String>>(mut self, args: impl IntoIterator<Item = A>) -> Self {
        self.args = args.into_iter().map(Into::into).collect();
        self
    }

    /// Adds an environment variable (the value may hold placeholders).
    pub fn with_env(mut self, name: impl Into<String>, value: impl Into<String>) -> Self {
        self.env.push((name.into(), value.into()));
        self
    }

    /// Adds a template file, read at build time, rendered to `destination` (relative to
    /// the run directory).
    pub fn with_template_file(
        mut self,
        source: impl Into<PathBuf>,
        destination: impl Into<PathBuf>,
    ) -> Self {
        self.templates
            .push((TemplateSource::File(source.into()), destination.into()));
        self
    }

    /// Adds a template given as text; `name` identifies it in errors.
    pub fn with_template_text(
        mut self,
        name: impl Into<String>,
        text: impl Into<String>,
        destination: impl Into<PathBuf>,
    ) -> Self {
        self.templates.push((
            TemplateSource::Text(name.into(), text.into()),
            destination.into(),
        ));
        self
    }

    /// The output file (relative to the run directory), its parser and the output names.
    pub fn with_output<N: Into<String>>(
        mut self,
        file: impl Into<PathBuf>,
        parser: OutputParser,
        names: impl IntoIterator<Item = N>,
    ) -> Self {
        self.output = Some((
            file.into(),
            parser,
            names.into_iter().map(Into::into).collect(),
        ));
        self
    }

    /// Parameter names, in the order of the values passed to `evaluate`.
    pub fn with_params<N: Into<String>>(mut self, names: impl IntoIterator<Item = N>) -> Self {
        self.param_names = names.into_iter().map(Into::into).collect();
        self
    }

    /// Wall-clock limit of one attempt (required).
    pub fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = Some(timeout);
        self
    }

    /// Time between SIGTERM and SIGKILL on timeout (default 5 s).
    pub fn with_kill_grace(mut self, grace: Duration) -> Self {
        self.kill_grace = grace;
        self
    }

    /// Retry policy (default: one attempt).
    pub fn with_retry(mut self, retry: RetryPolicy) -> Self {
        self.retry = retry;
        self
    }

    /// Which run directories stay on disk (default: failed ones).
    pub fn with_keep(mut self, keep: KeepRuns) -> Self {
        self.keep = keep;
        self
    }

    /// A file whose contents go into the fingerprint (e.g. the script `python3` runs).
    pub fn with_fingerprint_file(mut self, path: impl Into<PathBuf>) -> Self {
        self.fingerprint_files.push(path.into());
        self
    }

    /// The directory `{{config_dir}}` stands for (the configuration file's, so arguments
    /// can name scripts next to it). A location, not content: not in the fingerprint.
    pub fn with_config_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.config_dir = Some(dir.into());
        self
    }

    /// Lines of log kept with a failure (default 40).
    pub fn with_log_lines(mut self, lines: usize) -> Self {
        self.log_lines = lines;
        self
    }

    /// Checks everything and reads the template files.
    pub fn build<S>(self) -> Result<ExternalCommand<S>, ExternalError> {
        fn set(key: impl Into<String>, reason: impl Into<String>) -> ExternalError {
            ExternalError::setting(key, reason)
        }
        if self.program.as_os_str().is_empty() {
            return Err(set("program", "empty"));
        }
        let mut h = StableHasher::new();
        let mut parts = Parts::default();
        h.field("kalibre.command/1")
            .field(self.program.as_os_str().as_encoded_bytes());
        parts.field("program", self.program.as_os_str().as_encoded_bytes());
        // A program named by path is hashed, so editing the script invalidates old runs.
        if self.program.components().count() > 1 {
            let meta = std::fs::metadata(&self.program)
                .map_err(|e| set("program", format!("{}: {e}", self.program.display())))?;
            if !meta.is_file() {
                return Err(set(
                    "program",
                    format!("{} is not a file", self.program.display()),
                ));
            }
            if meta.len() <= MAX_HASHED_PROGRAM {
                let bytes = std::fs::read(&self.program)
                    .map_err(|e| ExternalError::io(&self.program, e))?;
                parts.field("program", &bytes);
                h.field(bytes);
            } else {
                h.field(meta.len().to_le_bytes());
                parts.field("program", meta.len().to_le_bytes());
            }
        }
        let timeout = self.timeout.ok_or_else(|| set("timeout_s", "required"))?;
        if timeout.is_zero() {
            return Err(set("timeout_s", "must be positive"));
        }
        if self.retry.max_attempts == 0 {
            return Err(set("retries", "at least one attempt is needed"));
        }
        if self.retry.on.contains(&FailureKind::Setup) {
            return Err(set("retry_on", "setup failures are never retried"));
        }

        for (i, p) in self.param_names.iter().enumerate() {
            if p.is_empty() || BUILTINS.contains(&p.as_str()) {
                return Err(set(
                    format!("params[{i}].name"),
                    format!("`{p}` is empty or reserved"),
                ));
            }
            if self.param_names[..i].contains(p) {
                return Err(set(format!("params[{i}].name"), format!("duplicate `{p}`")));
            }
        }

        let mut args = Vec::with_capacity(self.args.len());
        for (i, a) in self.args.iter().enumerate() {
            let t = Template::parse(format!("args[{i}]"), a.clone())?;
            h.field(a);
            parts.field("args", a);
            args.push(t);
        }
        let mut env = Vec::with_capacity(self.env.len());
        let mut env_sorted = self.env.clone();
        env_sorted.sort();
        for (k, v) in &env_sorted {
            if k.is_empty() || k.contains(['=', '\0']) {
                return Err(set(format!("env.{k}"), "invalid variable name"));
            }
            if env.iter().any(|(e, _)| e == k) {
                return Err(set(format!("env.{k}"), "given twice"));
            }
            env.push((k.clone(), Template::parse(format!("env.{k}"), v.clone())?));
            h.field(k).field(v);
            parts.field("env", k);
            parts.field("env", v);
        }

        let reserved = [STDOUT_LOG, STDERR_LOG, RUN_RECORD];
        let mut templates = Vec::with_capacity(self.templates.len());
        for (i, (src, dest)) in self.templates.iter().enumerate() {
            let key = format!("templates[{i}].destination");
            if !relative_inside(dest) {
                return Err(set(
                    key,
                    format!(
                        "{} must be a relative path inside the run directory",
                        dest.display()
                    ),
                ));
            }
            if reserved.iter().any(|r| dest == Path::new(r)) {
                return Err(set(
                    key,
                    format!("{} is reserved for kalibre's own files", dest.display()),
                ));
            }
            if templates
                .iter()
                .any(|t: &TemplateFile| t.destination == *dest)
            {
                return Err(set(
                    key,
                    format!("{} is written by two templates", dest.display()),
                ));
            }
            let template = match src {
                TemplateSource::File(p) => Template::from_file(p)?,
                TemplateSource::Text(name, text) => Template::parse(name.clone(), text.clone())?,
            };
            h.field(dest.as_os_str().as_encoded_bytes())
                .field(template.text());
            let part = match src {
                TemplateSource::File(p) => format!("template {}", p.display()),
                TemplateSource::Text(name, _) => format!("template {name}"),
            };
            parts.field(&part, dest.as_os_str().as_encoded_bytes());
            parts.field(&part, template.text());
            templates.push(TemplateFile {
                destination: dest.clone(),
                template,
            });
        }

        let (output_file, parser, output_names) = self
            .output
            .ok_or_else(|| set("output", "required (file, parser and names)"))?;
        if !relative_inside(&output_file) {
            return Err(set(
                "output.file",
                format!(
                    "{} must be a relative path inside the run directory",
                    output_file.display()
                ),
            ));
        }
        if output_names.is_empty() {
            return Err(set("output.names", "at least one output is needed"));
        }
        for (i, n) in output_names.iter().enumerate() {
            if n.is_empty() || output_names[..i].contains(n) {
                return Err(set(
                    format!("output.names[{i}]"),
                    format!("`{n}` is empty or a duplicate"),
                ));
            }
        }
        parser.check(&output_names)?;
        h.field(output_file.as_os_str().as_encoded_bytes())
            .field(parser.describe());
        parts.field("output", output_file.as_os_str().as_encoded_bytes());
        parts.field("output", parser.describe());
        for n in output_names.iter().chain(&self.param_names) {
            h.field(n);
        }
        for n in &output_names {
            parts.field("output", n);
        }
        for n in &self.param_names {
            parts.field("params", n);
        }
        for (i, f) in self.fingerprint_files.iter().enumerate() {
            let bytes = std::fs::read(f).map_err(|e| {
                set(
                    format!("fingerprint_files[{i}]"),
                    format!("{}: {e}", f.display()),
                )
            })?;
            parts.field(&f.display().to_string(), &bytes);
            h.field(bytes);
        }

        Ok(ExternalCommand {
            program: self.program.into_os_string(),
            args,
            env,
            templates,
            output_file,
            parser,
            output_names,
            param_names: self.param_names,
            timeout,
            kill_grace: self.kill_grace,
            retry: self.retry,
            dirs: RunDirs::new(self.runs_root),
            keep: self.keep,
            log_lines: self.log_lines,
            config_dir: self.config_dir,
            fingerprint: format!("command/{:032x}", h.finish()),
            fingerprint_parts: parts.finish(),
            _scenario: PhantomData,
        })
    }
}

impl<S: TemplateScenario + Sync> Model for ExternalCommand<S> {
    type Scenario = S;

    fn param_names(&self) -> Option<Vec<String>> {
        Some(self.param_names.clone())
    }

    fn output_names(&self) -> Option<Vec<String>> {
        Some(self.output_names.clone())
    }

    /// Hash of program (and its contents when named by path), arguments, environment,
    /// template contents and destinations, output file, parser, output and parameter
    /// names, and the fingerprint files. Not of timeout, retries or runs root.
    fn fingerprint(&self) -> String {
        self.fingerprint.clone()
    }

    fn evaluate(&self, scenario: &S, params: &[f64]) -> Result<Outputs, ModelError> {
        self.run(scenario, params).outcome
    }

    /// The scenario's variables: a scenario edited under its label is run again.
    fn scenario_key(&self, scenario: &S) -> String {
        crate::scenario_digest(&format!("{:?}", scenario.variables()))
    }
}
