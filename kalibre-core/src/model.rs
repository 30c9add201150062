//! The expensive model being calibrated.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a model run failed. A failed run is a value: it is journaled and the loop goes on.
#[derive(Debug, Clone, Error, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ModelError {
    /// The run failed (solver diverged, program exited non-zero, ...).
    #[error("model run failed: {reason}")]
    Failed {
        /// What went wrong, in words.
        reason: String,
        /// The end of the run's log, when there is one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        log_tail: Option<String>,
    },
    /// The run exceeded its wall-clock limit and was killed.
    #[error("model run timed out after {seconds} s")]
    Timeout {
        /// The limit that was exceeded. JSON has no NaN or infinity: a limit that is not
        /// a finite number (kalibre's runners always give one; a model of your own might
        /// not) is journaled as `null` and read back as NaN, so the run's line still
        /// loads.
        #[serde(deserialize_with = "crate::number::null_as_nan")]
        seconds: f64,
        /// The end of the run's log, when there is one.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        log_tail: Option<String>,
    },
    /// An output is NaN or infinite.
    #[error("model output {index} (`{name}`) is not finite: {value}")]
    NonFinite {
        /// Output index.
        index: usize,
        /// Output name.
        name: String,
        /// The value as text (`NaN`, `inf`).
        value: String,
        /// The end of the run's log, when there is one (a `run dir:` line first, where
        /// the run's directory was kept).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        log_tail: Option<String>,
    },
    /// The model returned the wrong number of outputs.
    #[error("model returned {got} outputs, expected {expected}")]
    WrongOutputCount {
        /// Outputs expected.
        expected: usize,
        /// Outputs returned.
        got: usize,
    },
    /// The model refused the parameters (e.g. out of its valid range). Journaled as
    /// `{"kind": "invalid_params", "reason": ...}`: a tagged string alone has no field
    /// to go in.
    #[error("model refused the parameters: {0}")]
    #[serde(with = "reason_field")]
    InvalidParams(String),
    /// An output is finite but physically impossible ([`Model::check_plausible`]): the
    /// run diverged, or the value did not come from the model.
    #[error("model output {index} (`{name}`) is implausible: {value} ({reason})")]
    Implausible {
        /// Output index.
        index: usize,
        /// Output name.
        name: String,
        /// The value as text.
        value: String,
        /// The limit it breaks, in words.
        reason: String,
    },
}

impl ModelError {
    /// A [`ModelError::Failed`] without a log.
    pub fn failed(reason: impl Into<String>) -> Self {
        ModelError::Failed {
            reason: reason.into(),
            log_tail: None,
        }
    }

    /// The directory a failed run was kept in, when its log tail names it (a line
    /// `run dir: PATH`, as [`crate::external::ExternalCommand`] and the OpenFOAM model
    /// write first).
    ///
    /// ```
    /// use kalibre_core::ModelError;
    /// let e = ModelError::Failed {
    ///     reason: "energy balance off".into(),
    ///     log_tail: Some("run dir: /runs/t0-1\n==> stdout.log <==\nEnd\n".into()),
    /// };
    /// assert_eq!(e.run_dir(), Some("/runs/t0-1"));
    /// assert_eq!(e.log_gist().as_deref(), Some("`End`"));
    /// ```
    pub fn run_dir(&self) -> Option<&str> {
        self.log_tail()?
            .lines()
            .find_map(|l| l.strip_prefix(RUN_DIR_LINE))
            .map(str::trim)
    }

    /// The error with `dir` named as the kept run directory (see [`Self::run_dir`]), when
    /// it names none yet.
    pub fn with_run_dir(self, dir: &std::path::Path) -> Self {
        if self.run_dir().is_some() {
            return self;
        }
        let named = |tail: Option<String>| {
            let line = format!("{RUN_DIR_LINE}{}", dir.display());
            Some(match tail {
                Some(t) => format!("{line}\n{t}"),
                None => line,
            })
        };
        self.with_log_tail(named)
    }

    /// The end of the run's log, when the error has one.
    pub fn log_tail(&self) -> Option<&str> {
        match self {
            ModelError::Failed { log_tail, .. }
            | ModelError::Timeout { log_tail, .. }
            | ModelError::NonFinite { log_tail, .. } => log_tail.as_deref(),
            ModelError::WrongOutputCount { .. }
            | ModelError::InvalidParams(_)
            | ModelError::Implausible { .. } => None,
        }
    }

    /// The error with its log tail made by `tail` from the one it has, where its kind
    /// keeps one.
    pub fn with_log_tail(mut self, tail: impl FnOnce(Option<String>) -> Option<String>) -> Self {
        match &mut self {
            ModelError::Failed { log_tail, .. }
            | ModelError::Timeout { log_tail, .. }
            | ModelError::NonFinite { log_tail, .. } => *log_tail = tail(log_tail.take()),
            ModelError::WrongOutputCount { .. }
            | ModelError::InvalidParams(_)
            | ModelError::Implausible { .. } => {}
        }
        self
    }

    /// The gist of the run's log for a one-line message: the first and last non-empty
    /// lines of its last section (stderr's, when the program wrote any), where a program
    /// usually says what went wrong and how it ended; `None` without a log.
    ///
    /// ```
    /// use kalibre_core::ModelError;
    /// let e = ModelError::Failed {
    ///     reason: "`solver` exited with code 2".into(),
    ///     log_tail: Some("==> stderr.log <==\nerror: no mesh\n\nexiting\n".into()),
    /// };
    /// assert_eq!(e.log_gist().as_deref(), Some("`error: no mesh` ... `exiting`"));
    /// ```
    pub fn log_gist(&self) -> Option<String> {
        let section = self.log_tail()?.rsplit("==> ").next()?;
        let mut lines = section
            .lines()
            .skip(usize::from(section.contains(" <==")))
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with(RUN_DIR_LINE));
        let first = lines.next()?;
        Some(match lines.last() {
            Some(last) => format!("`{first}` ... `{last}`"),
            None => format!("`{first}`"),
        })
    }
}

/// How a log tail names the kept run directory: its first line, `run dir: PATH`.
const RUN_DIR_LINE: &str = "run dir: ";

/// A stable digest (FNV-1a 128, hex) of a scenario's inputs written as text, for
/// [`Model::scenario_key`]; the same on every build and platform.
///
/// ```
/// let a = kalibre_core::scenario_digest("setpoints [18.0]");
/// assert_eq!(a, kalibre_core::scenario_digest("setpoints [18.0]"));
/// assert_ne!(a, kalibre_core::scenario_digest("setpoints [18.5]"));
/// ```
pub fn scenario_digest(inputs: &str) -> String {
    let mut h = crate::external::StableHasher::new();
    h.field(inputs);
    format!("{:032x}", h.finish())
}

/// What one successful model run returns: one value per output (sensor).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Outputs {
    /// One value per output, in the order of the observation's outputs.
    pub values: Vec<f64>,
    /// Optional per-output spread of the run itself (e.g. the oscillation of a CFD probe),
    /// kept as the run's noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spread: Option<Vec<f64>>,
    /// Whatever else the run computed that is not an observed output, by name (e.g. a
    /// CFD run's every server intake): journaled with the run, so that what an expensive
    /// run gave is never lost. The calibration does not use it. Every value must be
    /// finite (JSON has no NaN or infinity): the loop fails a run whose extras hold one,
    /// naming the key, as it fails a non-finite output.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub extras: BTreeMap<String, Vec<f64>>,
}

impl From<Vec<f64>> for Outputs {
    fn from(values: Vec<f64>) -> Self {
        Outputs {
            values,
            ..Default::default()
        }
    }
}

/// An expensive simulation model.
///
/// A *scenario* is one operating condition (for a data hall: setpoints, fan speeds and
/// server powers of one snapshot). Parameters are physical values in the order of the
/// calibration's [`crate::ParamSpace`].
pub trait Model: Sync {
    /// One operating condition. The trait asks only `Sync`, but a
    /// [`crate::Calibrator`] needs `Clone` too (and [`crate::GaussianProcess`]
    /// `PartialEq`): derive both where you can.
    type Scenario: Sync;

    /// A fingerprint of everything that determines the model's answers apart from the
    /// scenario and the parameters (geometry, grid, solver settings). Journaled runs with
    /// another fingerprint are never reused.
    fn fingerprint(&self) -> String;

    /// Fingerprints earlier versions of this code gave the same model (the same answers
    /// at the same scenario and parameters, hashed another way): a journal opened for the
    /// model reads their runs as its own ([`crate::RunStore::open_with_aliases`]), so
    /// that a change of what the fingerprint covers does not discard journaled runs. New
    /// runs are journaled under [`Self::fingerprint`]. The default has none.
    fn legacy_fingerprints(&self) -> Vec<String> {
        Vec::new()
    }

    /// Every fingerprint the model's runs may be journaled under: [`Self::fingerprint`]
    /// first, then [`Self::legacy_fingerprints`].
    fn run_fingerprints(&self) -> Vec<String> {
        [vec![self.fingerprint()], self.legacy_fingerprints()].concat()
    }

    /// Runs the model. Failure is a value: return a [`ModelError`] (the loop also catches
    /// a panic and journals it as a failed run, but a panic may leave the model's own
    /// state half-updated).
    fn evaluate(
        &self,
        scenario: &Self::Scenario,
        params: &[f64],
    ) -> std::result::Result<Outputs, ModelError>;

    /// The names of the parameters the model reads, in the order it reads them, when it
    /// knows them (an [`crate::external::ExternalCommand`] does): the loop then refuses a
    /// [`crate::ParamSpace`] that names them otherwise, whose values would reach the
    /// model swapped without a word. The default, `None`, trusts the order.
    fn param_names(&self) -> Option<Vec<String>> {
        None
    }

    /// The names of the outputs the model returns, in order, when it knows them: the
    /// loop refuses observations that name them otherwise. The default, `None`, trusts
    /// the order.
    fn output_names(&self) -> Option<Vec<String>> {
        None
    }

    /// Checks a successful run's outputs against what the model can physically give
    /// (for a data hall: air above absolute zero). The loop applies it to every run,
    /// fresh or read back from the journal, so an impossible value never reaches the
    /// surrogate. The default accepts every finite value.
    fn check_plausible(&self, outputs: &Outputs) -> std::result::Result<(), ModelError> {
        let _ = outputs;
        Ok(())
    }

    /// A digest of the scenario's inputs (e.g. [`scenario_digest`] of its setpoints and
    /// powers), journaled with each run: a run is reused only under the same label *and*
    /// the same inputs, so a snapshot edited under its old label is run again, never
    /// answered from the old conditions. The default, empty, trusts the label alone.
    fn scenario_key(&self, scenario: &Self::Scenario) -> String {
        let _ = scenario;
        String::new()
    }
}

/// Checks a model's answer: the output count and that every value is finite.
pub fn check_outputs(
    outputs: Outputs,
    names: &[String],
) -> std::result::Result<Outputs, ModelError> {
    if outputs.values.len() != names.len() {
        return Err(ModelError::WrongOutputCount {
            expected: names.len(),
            got: outputs.values.len(),
        });
    }
    if let Some((index, v)) = outputs
        .values
        .iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
    {
        return Err(ModelError::NonFinite {
            index,
            name: names[index].clone(),
            value: v.to_string(),
            log_tail: None,
        });
    }
    // Finite, but the fits square it: near f64::MAX that overflows into NaN, far from
    // the run that gave it.
    if let Some((index, v)) =
        (outputs.values.iter().enumerate()).find(|(_, v)| !crate::within_magnitude(**v))
    {
        return Err(ModelError::Implausible {
            index,
            name: names[index].clone(),
            value: crate::number(*v),
            reason: format!(
                "beyond +/-{}, more than the fit can square",
                crate::number(crate::MAX_MAGNITUDE)
            ),
        });
    }
    Ok(outputs)
}

/// Why a run's [`Outputs::extras`] cannot be journaled, if they cannot: the first value
/// that is NaN or infinite, named by its key and index.
pub(crate) fn non_finite_extra(extras: &BTreeMap<String, Vec<f64>>) -> Option<String> {
    extras.iter().find_map(|(key, values)| {
        let i = values.iter().position(|v| !v.is_finite())?;
        Some(format!(
            "extra `{key}` value {i} is not finite ({}); a run journal holds finite \
             numbers only (give the model's extras finite values, or leave that one out)",
            crate::number(values[i])
        ))
    })
}

/// A reason as the one field `reason` of its tagged object ([`ModelError::InvalidParams`]).
mod reason_field {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize)]
    struct Borrowed<'a> {
        reason: &'a str,
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Owned {
        reason: String,
    }

    pub fn serialize<S: Serializer>(reason: &str, s: S) -> Result<S::Ok, S::Error> {
        Borrowed { reason }.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<String, D::Error> {
        Ok(Owned::deserialize(d)?.reason)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kind of failure is journaled and read back as it was.
    #[test]
    fn every_failure_round_trips_through_json() {
        let failures = [
            ModelError::Failed {
                reason: "diverged".into(),
                log_tail: Some("step 12".into()),
            },
            ModelError::Timeout {
                seconds: 30.0,
                log_tail: None,
            },
            ModelError::NonFinite {
                index: 1,
                name: "t_out".into(),
                value: "NaN".into(),
                log_tail: Some("run dir: /runs/t0-1\n".into()),
            },
            ModelError::WrongOutputCount {
                expected: 3,
                got: 2,
            },
            ModelError::InvalidParams("alpha below 0".into()),
            ModelError::Implausible {
                index: 0,
                name: "t_in".into(),
                value: "1e9".into(),
                reason: "hotter than the sun".into(),
            },
        ];
        for e in failures {
            let json = serde_json::to_string(&e).unwrap_or_else(|err| panic!("{e:?}: {err}"));
            let back: ModelError = serde_json::from_str(&json).unwrap();
            assert_eq!(back, e, "{json}");
        }
        let json = serde_json::to_string(&ModelError::InvalidParams("x".into())).unwrap();
        assert_eq!(json, r#"{"kind":"invalid_params","reason":"x"}"#);
    }

    #[test]
    fn outputs_beyond_what_a_fit_can_square_are_named() {
        let names = vec!["t_in".to_string(), "t_out".to_string()];
        let e = check_outputs(Outputs::from(vec![20.0, 5e307]), &names).unwrap_err();
        let text = e.to_string();
        assert!(
            matches!(e, ModelError::Implausible { index: 1, .. }),
            "{text}"
        );
        assert!(text.contains("`t_out`") && text.contains("5e307"), "{text}");
        assert!(check_outputs(Outputs::from(vec![20.0, -1e150]), &names).is_ok());
    }
}
