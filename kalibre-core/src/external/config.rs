//! `model.toml`: an external command model, its parameters and its scenarios from a file.
//!
//! The file is read key by key (not through serde) so that every error names its key as a
//! path (`params[2].lower`, `output.regex.t_in`), and unknown keys are errors: a typo must
//! not silently fall back to a default. Relative paths (program when given as a path,
//! template sources, runs root, fingerprint files) are relative to the file's directory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use toml::{Table, Value};

use super::command::{ExternalCommand, FailureKind, KeepRuns, RetryPolicy};
use super::parse::OutputParser;
use super::{ExternalError, NamedScenario};
use crate::diagnose::{group_candidates, CandidateEffect, CandidateParam};
use crate::{unprintable_name, Param, ParamSpace, Scale};

/// The most `retries` a `model.toml` may ask for: a run that fails that often will not
/// succeed on the next try.
pub const MAX_RETRIES: u32 = 100;

/// Everything `kalibre calibrate --model command --config model.toml` needs from the file.
#[derive(Debug)]
pub struct CommandModelConfig {
    /// The model.
    pub command: ExternalCommand<NamedScenario>,
    /// The parameters, in the order the model takes them; a candidate effect's are fixed
    /// at their `absent` values.
    pub space: ParamSpace,
    /// The candidate effects (`[[params]]` with `absent`), which `kalibre diagnose` tests.
    pub candidates: Vec<CandidateEffect>,
    /// The scenarios (operating conditions) listed in the file.
    pub scenarios: Vec<NamedScenario>,
}

struct Ctx<'a> {
    file: &'a str,
    base: &'a Path,
}

impl Ctx<'_> {
    fn err(&self, key: impl Into<String>, reason: impl Into<String>) -> ExternalError {
        ExternalError::Config {
            file: self.file.to_string(),
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// Builder and parser settings are named like the file's keys: add the file.
    fn lift(&self, e: ExternalError) -> ExternalError {
        match e {
            ExternalError::Setting { key, reason } => self.err(key, reason),
            e => e,
        }
    }

    /// Refuses a NUL byte in a text that becomes an argument, an environment value or a
    /// path: the operating system cannot take one, and every run would fail on it.
    fn no_nul(&self, key: impl Into<String>, s: &str) -> Result<(), ExternalError> {
        match s.find('\0') {
            Some(at) => Err(self.err(
                key,
                format!(
                    "holds a NUL byte (after {} characters); no program argument, \
                     environment value or path can carry one",
                    s[..at].chars().count()
                ),
            )),
            None => Ok(()),
        }
    }

    /// Checks a parameter or output name at `key`: non-empty, printable, and not one of
    /// `earlier` (the names before it, each with its key).
    fn name<'n>(
        &self,
        key: &str,
        name: &str,
        mut earlier: impl Iterator<Item = (String, &'n str)>,
    ) -> Result<(), ExternalError> {
        if name.is_empty() {
            return Err(self.err(key, "is empty; expected a name"));
        }
        if let Some(why) = unprintable_name(name) {
            return Err(self.err(key, format!("name {why}")));
        }
        match earlier.find(|(_, e)| *e == name) {
            Some((k, _)) => Err(self.err(key, format!("duplicate `{name}` (also `{k}`)"))),
            None => Ok(()),
        }
    }

    fn path(&self, p: &str) -> PathBuf {
        let p = Path::new(p);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    fn keys(&self, t: &Table, prefix: &str, allowed: &[&str]) -> Result<(), ExternalError> {
        match t.keys().find(|k| !allowed.contains(&k.as_str())) {
            Some(k) => Err(self.err(
                join(prefix, k),
                format!("unknown key (expected one of: {})", allowed.join(", ")),
            )),
            None => Ok(()),
        }
    }

    fn str(&self, t: &Table, prefix: &str, key: &str) -> Result<Option<String>, ExternalError> {
        match t.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.clone())),
            Some(v) => Err(self.err(
                join(prefix, key),
                format!("expected a string, got {}", v.type_str()),
            )),
        }
    }

    fn req_str(&self, t: &Table, prefix: &str, key: &str) -> Result<String, ExternalError> {
        self.str(t, prefix, key)?
            .ok_or_else(|| self.err(join(prefix, key), "required"))
    }

    fn num(&self, t: &Table, prefix: &str, key: &str) -> Result<Option<f64>, ExternalError> {
        let x = match t.get(key) {
            None => return Ok(None),
            Some(Value::Integer(i)) => *i as f64,
            Some(Value::Float(x)) => *x,
            Some(v) => {
                return Err(self.err(
                    join(prefix, key),
                    format!("expected a number, got {}", v.type_str()),
                ))
            }
        };
        if !x.is_finite() {
            return Err(self.err(join(prefix, key), format!("{x} is not finite")));
        }
        Ok(Some(x))
    }

    fn req_num(&self, t: &Table, prefix: &str, key: &str) -> Result<f64, ExternalError> {
        self.num(t, prefix, key)?
            .ok_or_else(|| self.err(join(prefix, key), "required"))
    }

    fn count(&self, t: &Table, key: &str) -> Result<Option<u32>, ExternalError> {
        match t.get(key) {
            None => Ok(None),
            Some(Value::Integer(i)) => u32::try_from(*i)
                .map(Some)
                .map_err(|_| self.err(key, format!("{i} is not a count in [0, {}]", u32::MAX))),
            Some(v) => Err(self.err(key, format!("expected an integer, got {}", v.type_str()))),
        }
    }

    fn strings(&self, t: &Table, prefix: &str, key: &str) -> Result<Vec<String>, ExternalError> {
        match t.get(key) {
            None => Ok(Vec::new()),
            Some(Value::Array(a)) => a
                .iter()
                .enumerate()
                .map(|(i, v)| match v {
                    Value::String(s) => Ok(s.clone()),
                    v => Err(self.err(
                        format!("{}[{i}]", join(prefix, key)),
                        format!("expected a string, got {}", v.type_str()),
                    )),
                })
                .collect(),
            Some(v) => Err(self.err(
                join(prefix, key),
                format!("expected an array of strings, got {}", v.type_str()),
            )),
        }
    }

    fn table<'t>(
        &self,
        t: &'t Table,
        prefix: &str,
        key: &str,
    ) -> Result<Option<&'t Table>, ExternalError> {
        match t.get(key) {
            None => Ok(None),
            Some(Value::Table(t)) => Ok(Some(t)),
            Some(v) => Err(self.err(
                join(prefix, key),
                format!("expected a table, got {}", v.type_str()),
            )),
        }
    }

    fn tables<'t>(&self, t: &'t Table, key: &str) -> Result<Vec<&'t Table>, ExternalError> {
        match t.get(key) {
            None => Ok(Vec::new()),
            Some(Value::Array(a)) => a
                .iter()
                .enumerate()
                .map(|(i, v)| match v {
                    Value::Table(t) => Ok(t),
                    v => Err(self.err(
                        format!("{key}[{i}]"),
                        format!("expected a table, got {}", v.type_str()),
                    )),
                })
                .collect(),
            Some(v) => Err(self.err(
                key,
                format!(
                    "expected an array of tables ([[{key}]]), got {}",
                    v.type_str()
                ),
            )),
        }
    }
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_string()
    } else {
        format!("{prefix}.{key}")
    }
}

/// Why a scenario label is refused, if it is: the rules of a hall's snapshot labels
/// (`snapshots.csv`): non-empty, printable, no space at either end, not too long. An
/// empty label would match a measurements row whose scenario is empty, and a padded one
/// (`winter `) another scenario than `winter`.
fn label_problem(label: &str) -> Option<String> {
    if label.is_empty() {
        return Some("expected a non-empty scenario label".into());
    }
    if let Some(why) = unprintable_name(label) {
        return Some(format!("scenario label {why}"));
    }
    (label.trim() != label).then(|| {
        format!(
            "scenario label `{label}` starts or ends with a space; labels are taken as \
             written, so it would be another scenario than `{}`",
            label.trim()
        )
    })
}

const TOP_KEYS: [&str; 16] = [
    "program",
    "args",
    "runs_root",
    "timeout_s",
    "kill_grace_s",
    "retries",
    "retry_on",
    "keep_runs",
    "fingerprint_files",
    "log_lines",
    "env",
    "templates",
    "output",
    "params",
    "scenarios",
    "description",
];

impl CommandModelConfig {
    /// Reads and checks a `model.toml`.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ExternalError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| ExternalError::io(path, e))?;
        Self::from_toml_str(&text, path)
    }

    /// Reads and checks a `model.toml` whose scenarios come from elsewhere (a hall's
    /// snapshots, say): a `[[scenarios]]` list is refused with `why`, before its entries
    /// are checked against the templates (where a variable they lack would be the error
    /// reported, not the list itself).
    pub fn load_without_scenarios(
        path: impl AsRef<Path>,
        why: &str,
    ) -> Result<Self, ExternalError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| ExternalError::io(path, e))?;
        let lists_scenarios = text
            .parse::<Table>()
            .is_ok_and(|top| top.contains_key("scenarios"));
        if lists_scenarios {
            return Err(ExternalError::Config {
                file: path.display().to_string(),
                key: "scenarios".into(),
                reason: why.into(),
            });
        }
        Self::from_toml_str(&text, path)
    }

    /// Parses the text of a `model.toml`; `file` names it in errors and its directory
    /// anchors relative paths.
    pub fn from_toml_str(text: &str, file: &Path) -> Result<Self, ExternalError> {
        let file_name = file.display().to_string();
        let base = match file.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        // Absolute, so that the paths made from it (the program, `runs_root`, hence
        // `{{run_dir}}` and `KALIBRE_RUN_DIR`) mean the same inside a run directory, where
        // the program runs, as here.
        let config_dir = std::path::absolute(base).map_err(|e| ExternalError::io(base, e))?;
        let cx = Ctx {
            file: &file_name,
            base: &config_dir,
        };
        let top: Table = text.parse().map_err(|e: toml::de::Error| {
            let key = match e.span() {
                Some(s) => {
                    let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                    format!("line {line}")
                }
                None => "(syntax)".into(),
            };
            cx.err(key, e.message().trim().to_string())
        })?;
        cx.keys(&top, "", &TOP_KEYS)?;
        cx.str(&top, "", "description")?;

        let program = cx.req_str(&top, "", "program")?;
        cx.no_nul("program", &program)?;
        let program = if Path::new(&program).components().count() > 1 {
            cx.path(&program)
        } else {
            PathBuf::from(program)
        };
        let runs_root = cx.str(&top, "", "runs_root")?;
        let runs_root = runs_root.as_deref().unwrap_or("runs");
        cx.no_nul("runs_root", runs_root)?;
        let runs_root = cx.path(runs_root);
        // Made by the first run if missing; a file there (or on the way to it) would fail
        // every run with `File exists` or `Not a directory`.
        if let Some(existing) = runs_root.ancestors().find(|a| a.exists()) {
            if !existing.is_dir() {
                return Err(cx.err(
                    "runs_root",
                    if existing == runs_root {
                        format!(
                            "{} exists and is not a directory; run directories go under it",
                            runs_root.display()
                        )
                    } else {
                        format!(
                            "{} is not a directory, so {} cannot be made under it",
                            existing.display(),
                            runs_root.display()
                        )
                    },
                ));
            }
        }
        let args = cx.strings(&top, "", "args")?;
        for (i, a) in args.iter().enumerate() {
            cx.no_nul(format!("args[{i}]"), a)?;
        }
        let mut b = ExternalCommand::<NamedScenario>::builder(program, runs_root)
            .with_args(args)
            .with_config_dir(config_dir.clone());

        let timeout = cx.req_num(&top, "", "timeout_s")?;
        if timeout <= 0.0 || timeout > 1e9 {
            return Err(cx.err(
                "timeout_s",
                format!(
                    "{} is not a number of seconds in (0, 1e9]",
                    crate::number(timeout)
                ),
            ));
        }
        b = b.with_timeout(Duration::from_secs_f64(timeout));
        if let Some(g) = cx.num(&top, "", "kill_grace_s")? {
            if !(0.0..=1e6).contains(&g) {
                return Err(cx.err(
                    "kill_grace_s",
                    format!(
                        "{} is not a number of seconds in [0, 1e6]",
                        crate::number(g)
                    ),
                ));
            }
            b = b.with_kill_grace(Duration::from_secs_f64(g));
        }

        let mut retry = RetryPolicy::default();
        if let Some(r) = cx.count(&top, "retries")? {
            // A failure that repeats every time would otherwise run (and fill `runs_root`)
            // without end: one run is never retried more than this.
            if r > MAX_RETRIES {
                return Err(cx.err(
                    "retries",
                    format!("{r} is too many; expected at most {MAX_RETRIES}"),
                ));
            }
            retry.max_attempts = r.saturating_add(1);
        }
        if top.contains_key("retry_on") {
            retry.on = cx
                .strings(&top, "", "retry_on")?
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    FailureKind::RETRYABLE
                        .into_iter()
                        .find(|k| k.name() == s)
                        .ok_or_else(|| {
                            cx.err(
                                format!("retry_on[{i}]"),
                                format!("`{s}` is not one of timeout, exit, output, non_finite"),
                            )
                        })
                })
                .collect::<Result<_, _>>()?;
        }
        b = b.with_retry(retry);
        match cx.str(&top, "", "keep_runs")?.as_deref() {
            None | Some("failed") => {}
            Some("all") => b = b.with_keep(KeepRuns::All),
            Some(k) => return Err(cx.err("keep_runs", format!("`{k}` is not `failed` or `all`"))),
        }
        for (i, f) in cx
            .strings(&top, "", "fingerprint_files")?
            .into_iter()
            .enumerate()
        {
            cx.no_nul(format!("fingerprint_files[{i}]"), &f)?;
            b = b.with_fingerprint_file(cx.path(&f));
        }
        if let Some(n) = cx.count(&top, "log_lines")? {
            b = b.with_log_lines(n as usize);
        }
        if let Some(env) = cx.table(&top, "", "env")? {
            for k in env.keys() {
                if let Some(why) = unprintable_name(k) {
                    return Err(
                        cx.err("env", format!("variable name `{}` {why}", k.escape_debug()))
                    );
                }
                let v = cx.req_str(env, "env", k)?;
                cx.no_nul(join("env", k), &v)?;
                b = b.with_env(k.clone(), v);
            }
        }
        for (i, t) in cx.tables(&top, "templates")?.into_iter().enumerate() {
            let p = format!("templates[{i}]");
            cx.keys(t, &p, &["source", "destination"])?;
            let source = cx.req_str(t, &p, "source")?;
            let dest = cx.req_str(t, &p, "destination")?;
            cx.no_nul(format!("{p}.source"), &source)?;
            cx.no_nul(format!("{p}.destination"), &dest)?;
            let source = cx.path(&source);
            if !source.is_file() {
                return Err(cx.err(
                    format!("{p}.source"),
                    format!("{} is not a readable file", source.display()),
                ));
            }
            b = b.with_template_file(source, dest);
        }

        let output = cx
            .table(&top, "", "output")?
            .ok_or_else(|| cx.err("output", "required ([output] with file, parser, names)"))?;
        cx.keys(output, "output", &["file", "parser", "names", "regex"])?;
        let out_file = cx.req_str(output, "output", "file")?;
        cx.no_nul("output.file", &out_file)?;
        let names = cx.strings(output, "output", "names")?;
        if names.is_empty() {
            return Err(cx.err("output.names", "required: the output names in order"));
        }
        for (i, n) in names.iter().enumerate() {
            let earlier = names[..i]
                .iter()
                .enumerate()
                .map(|(j, e)| (format!("output.names[{j}]"), e.as_str()));
            cx.name(&format!("output.names[{i}]"), n, earlier)?;
        }
        let parser_name = cx.req_str(output, "output", "parser")?;
        let regex = cx.table(output, "output", "regex")?;
        let parser = match (parser_name.as_str(), regex) {
            ("csv", None) => OutputParser::CsvColumns,
            ("csv_long", None) => OutputParser::CsvLong,
            ("regex", Some(r)) => {
                let mut pats = Vec::new();
                for k in r.keys() {
                    pats.push((k.clone(), cx.req_str(r, "output.regex", k)?));
                }
                OutputParser::regex(pats).map_err(|e| cx.lift(e))?
            }
            ("regex", None) => {
                return Err(cx.err(
                    "output.regex",
                    "required by parser = \"regex\": one pattern per output",
                ))
            }
            ("csv" | "csv_long", Some(_)) => {
                return Err(cx.err(
                    "output.regex",
                    format!("only used with parser = \"regex\", not `{parser_name}`"),
                ))
            }
            (p, _) => {
                return Err(cx.err(
                    "output.parser",
                    format!("`{p}` is not csv, csv_long or regex"),
                ))
            }
        };
        b = b.with_output(out_file, parser, names);

        let mut space = ParamSpace::new();
        let params = cx.tables(&top, "params")?;
        if params.is_empty() {
            return Err(cx.err("params", "at least one [[params]] is needed"));
        }
        let mut candidates = Vec::new();
        for (i, t) in params.iter().enumerate() {
            let p = format!("params[{i}]");
            cx.keys(
                t,
                &p,
                &[
                    "name", "lower", "upper", "initial", "scale", "absent", "effect",
                ],
            )?;
            if let Some(c) = candidate_param(&cx, t, &p, &space)? {
                let name = c.1.name.clone();
                // Held where the effect is absent: a fixed parameter, on a linear scale
                // since an absent value of 0 has no logarithm.
                Param::new(name, c.1.absent, c.1.absent, c.1.absent, Scale::Linear)
                    .and_then(|param| space.push(param))
                    .map_err(|e| cx.err(p.clone(), e.to_string()))?;
                candidates.push(c);
                continue;
            }
            let name = cx.req_str(t, &p, "name")?;
            param_name(&cx, &p, &name, &space)?;
            let param = Param::new(
                name,
                cx.req_num(t, &p, "lower")?,
                cx.req_num(t, &p, "upper")?,
                cx.req_num(t, &p, "initial")?,
                param_scale(&cx, t, &p)?,
            )
            .and_then(|param| space.push(param))
            .map_err(|e| cx.err(p.clone(), e.to_string()));
            param?;
        }
        b = b.with_params(space.names());
        let command = b.build().map_err(|e| cx.lift(e))?;

        let mut scenarios = Vec::new();
        for (i, t) in cx.tables(&top, "scenarios")?.into_iter().enumerate() {
            let p = format!("scenarios[{i}]");
            cx.keys(t, &p, &["label", "variables"])?;
            let label = cx.req_str(t, &p, "label")?;
            if let Some(why) = label_problem(&label) {
                return Err(cx.err(format!("{p}.label"), why));
            }
            if scenarios.iter().any(|s: &NamedScenario| s.label == label) {
                return Err(cx.err(format!("{p}.label"), format!("duplicate label `{label}`")));
            }
            let mut values = BTreeMap::new();
            if let Some(vars) = cx.table(t, &p, "variables")? {
                let vp = format!("{p}.variables");
                for k in vars.keys() {
                    if let Some(why) = unprintable_name(k) {
                        return Err(cx.err(
                            vp.clone(),
                            format!("variable name `{}` {why}", k.escape_debug()),
                        ));
                    }
                    values.insert(k.clone(), cx.req_num(vars, &vp, k)?);
                }
            }
            let s = NamedScenario { label, values };
            command.check_scenario(&s).map_err(|e| match e {
                ExternalError::Setting { reason, .. } => cx.err(format!("{p}.variables"), reason),
                // A placeholder this scenario leaves unset: named with the scenario, since
                // the others may well set it.
                ExternalError::Template {
                    file,
                    line,
                    placeholder,
                    reason,
                } => ExternalError::Template {
                    file,
                    line,
                    placeholder,
                    reason: format!(
                        "{reason}, in scenario `{}` ({p}.variables of {})",
                        s.label, cx.file
                    ),
                },
                e => e,
            })?;
            scenarios.push(s);
        }
        Ok(CommandModelConfig {
            command,
            space,
            candidates: group_candidates(candidates),
            scenarios,
        })
    }
}

/// `params[i].name`: non-empty, printable, and not the name of an earlier entry (each
/// entry is one parameter of `space`, in order).
fn param_name(cx: &Ctx<'_>, p: &str, name: &str, space: &ParamSpace) -> Result<(), ExternalError> {
    let earlier = space
        .params()
        .iter()
        .enumerate()
        .map(|(j, e)| (format!("params[{j}].name"), e.name.as_str()));
    cx.name(&format!("{p}.name"), name, earlier)?;
    // A template writes it `{{name}}`, which stops at a brace, splits at `:` (a format)
    // and holds no white space: such a name could never be placed.
    if name.contains(super::template::breaks_placeholder) {
        let fitting = (name.trim()).replace(super::template::breaks_placeholder, "_");
        return Err(cx.err(
            format!("{p}.name"),
            format!(
                "`{name}` cannot be written as a template placeholder `{{{{name}}}}`: a \
                 parameter's name holds no spaces, braces or `:`; expected e.g. `{fitting}`"
            ),
        ));
    }
    Ok(())
}

/// `params[i].scale`: `linear` (the default) or `log`.
fn param_scale(cx: &Ctx<'_>, t: &Table, p: &str) -> Result<Scale, ExternalError> {
    match cx.str(t, p, "scale")?.as_deref() {
        None | Some("linear") => Ok(Scale::Linear),
        Some("log") => Ok(Scale::Log),
        Some(s) => Err(cx.err(
            format!("{p}.scale"),
            format!("`{s}` is not `linear` or `log`"),
        )),
    }
}

/// A `[[params]]` entry with `absent`: a candidate effect's parameter (its effect's name
/// with it), checked; `None` for a calibrated parameter. `index` is its place in the space.
fn candidate_param(
    cx: &Ctx<'_>,
    t: &Table,
    p: &str,
    space: &ParamSpace,
) -> Result<Option<(String, CandidateParam)>, ExternalError> {
    let index = space.dim();
    let effect = cx.str(t, p, "effect")?;
    let Some(absent) = cx.num(t, p, "absent")? else {
        return match effect {
            Some(_) => Err(cx.err(
                format!("{p}.effect"),
                "names the effect of a candidate parameter, but there is no `absent` (the \
                 value at which the effect is absent): to calibrate the parameter (an effect \
                 added), delete `effect` too",
            )),
            None => Ok(None),
        };
    };
    let name = cx.req_str(t, p, "name")?;
    param_name(cx, p, &name, space)?;
    let (lower, upper) = (cx.req_num(t, p, "lower")?, cx.req_num(t, p, "upper")?);
    if lower >= upper {
        return Err(cx.err(
            p,
            format!(
                "a candidate's range must be increasing, got lower {} and upper {}",
                crate::number(lower),
                crate::number(upper)
            ),
        ));
    }
    if !(lower..=upper).contains(&absent) {
        return Err(cx.err(
            format!("{p}.absent"),
            format!(
                "{} is outside [{}, {}]: the effect must be absent somewhere in its range",
                crate::number(absent),
                crate::number(lower),
                crate::number(upper)
            ),
        ));
    }
    // Checked now, so that the entry still holds once `absent` is deleted to add it.
    let scale = param_scale(cx, t, p)?;
    let initial = cx.num(t, p, "initial")?;
    Param::new(name.clone(), lower, upper, initial.unwrap_or(lower), scale)
        .map_err(|e| cx.err(p, e.to_string()))?;
    let effect = match effect {
        Some(e) if e.trim().is_empty() => {
            return Err(cx.err(format!("{p}.effect"), "is empty"));
        }
        Some(e) => {
            if let Some(why) = unprintable_name(&e) {
                return Err(cx.err(format!("{p}.effect"), format!("effect name {why}")));
            }
            e
        }
        None => name.clone(),
    };
    Ok(Some((
        effect,
        CandidateParam {
            name,
            index,
            absent,
            lower,
            upper,
        },
    )))
}
