//! Any simulator as a [`Model`](crate::Model): an external program driven through files.
//!
//! Per run, [`ExternalCommand`] makes a fresh working directory under a runs root, renders
//! input files from templates with the parameters substituted (`{{name}}` or
//! `{{name:.6}}`, see [`Template`]), starts the program with an argument list (never a
//! shell string) in its own process group, kills the whole group on a wall-clock timeout,
//! and parses the outputs from a file ([`OutputParser`]). Failures become
//! [`ModelError`](crate::ModelError)s with the reason and the log tail; a [`RetryPolicy`]
//! repeats chosen failure kinds, each attempt in a fresh directory.
//!
//! The pieces are public so that adapters (OpenFOAM) can reuse them: [`run_process`]
//! (process group, timeout, logs), [`log_tail`], [`RunDirs`], [`Template`].
//!
//! Configuration from a TOML file: [`CommandModelConfig::load`]; the format is documented
//! in `docs/models.md`.

mod command;
mod config;
mod groups;
mod parse;
mod parts;
mod process;
mod program;
mod run;
mod rundir;
mod template;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use command::{
    AttemptReport, CommandBuilder, ExternalCommand, FailureKind, KeepRuns, RetryPolicy, RunReport,
    TemplateFile,
};
pub use config::CommandModelConfig;
pub use groups::{
    await_stop, end_runs_with_kalibre, set_stop_message, signal_runs, stopping, StopMessage,
};
pub use parse::OutputParser;
pub use parts::changed_parts;
pub use process::{log_tail, run_process, ProcessEnd, ProcessOutcome, ProcessSpec};
pub use rundir::{RunDir, RunDirs};
pub use template::{Format, Template, TemplateValue, Variables};

/// Errors of building or configuring an external model (not of running it: a run's
/// failure is a [`ModelError`](crate::ModelError)).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ExternalError {
    /// A key of a configuration file is missing, mistyped or out of range.
    #[error("{file}: `{key}`: {reason}")]
    Config {
        /// The configuration file.
        file: String,
        /// The key, as a path (`params[1].lower`, `output.names`).
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A setting given to the builder is invalid (the configuration loader turns this into
    /// [`ExternalError::Config`] naming the file).
    #[error("setting `{key}`: {reason}")]
    Setting {
        /// The setting, named as in the configuration file.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A template is malformed or names an unknown placeholder.
    #[error("template {file}, line {line}: placeholder `{placeholder}`: {reason}")]
    Template {
        /// The template (its source file, or `args[i]` / `env.NAME` for inline templates).
        file: String,
        /// 1-based line of the placeholder.
        line: usize,
        /// The placeholder's text between the braces.
        placeholder: String,
        /// What is wrong.
        reason: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory concerned.
        path: String,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
}

impl ExternalError {
    pub(crate) fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        ExternalError::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }

    pub(crate) fn setting(key: impl Into<String>, reason: impl Into<String>) -> Self {
        ExternalError::Setting {
            key: key.into(),
            reason: reason.into(),
        }
    }
}

/// A scenario that can render itself into template variables.
///
/// Its label names the run directory and is the `{{scenario}}` placeholder; its variables
/// are placeholders next to the parameters (a name used by both is an error).
pub trait TemplateScenario {
    /// A short human-readable name (e.g. `2024-07-01T12:00`).
    fn label(&self) -> &str;
    /// Named values for the templates, e.g. `("power_w/A01-01", Number(350.0))`.
    fn variables(&self) -> Vec<(String, TemplateValue)>;
}

/// A generic scenario: a label and named numbers, as written in a configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedScenario {
    /// Label (run directory name and `{{scenario}}`).
    pub label: String,
    /// Named values (placeholders in templates and arguments).
    pub values: BTreeMap<String, f64>,
}

impl NamedScenario {
    /// A scenario without variables.
    pub fn new(label: impl Into<String>) -> Self {
        NamedScenario {
            label: label.into(),
            values: BTreeMap::new(),
        }
    }

    /// Adds a variable (builder style).
    pub fn with(mut self, name: impl Into<String>, value: f64) -> Self {
        self.values.insert(name.into(), value);
        self
    }
}

impl TemplateScenario for NamedScenario {
    fn label(&self) -> &str {
        &self.label
    }

    fn variables(&self) -> Vec<(String, TemplateValue)> {
        self.values
            .iter()
            .map(|(k, &v)| (k.clone(), TemplateValue::Number(v)))
            .collect()
    }
}

/// A hash that is stable across Rust versions and platforms (FNV-1a, 128 bit), for
/// fingerprints and run directory names. Fields are length-prefixed so that
/// `("ab", "c")` and `("a", "bc")` differ.
#[derive(Debug, Clone)]
pub(crate) struct StableHasher(u128);

impl StableHasher {
    const OFFSET: u128 = 0x6c62272e07bb014262b821756295c58d;
    const PRIME: u128 = 0x0000000001000000000000000000013B;

    pub(crate) fn new() -> Self {
        StableHasher(Self::OFFSET)
    }

    fn bytes(&mut self, data: &[u8]) {
        for &b in data {
            self.0 ^= u128::from(b);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
    }

    /// Adds one field.
    pub(crate) fn field(&mut self, data: impl AsRef<[u8]>) -> &mut Self {
        let data = data.as_ref();
        self.bytes(&(data.len() as u64).to_le_bytes());
        self.bytes(data);
        self
    }

    pub(crate) fn finish(&self) -> u128 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stable_hash_is_fixed_and_field_separated() {
        let h = |parts: &[&str]| {
            let mut s = StableHasher::new();
            for p in parts {
                s.field(p);
            }
            s.finish()
        };
        assert_ne!(h(&["ab", "c"]), h(&["a", "bc"]));
        assert_eq!(h(&["x"]), h(&["x"]));
        // The published FNV-1a 128 test vector: the journal keys runs by this hash, so it
        // must not change between builds.
        let mut s = StableHasher::new();
        s.bytes(b"a");
        assert_eq!(
            format!("{:032x}", s.finish()),
            "d228cb696f1a8caf78912b704e4a8964"
        );
    }
}
