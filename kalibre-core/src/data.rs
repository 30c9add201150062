//! Observations: what was measured, under which operating conditions.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// Description of one model output (for a data hall: a sensor).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputInfo {
    /// Unique name (sensor id).
    pub name: String,
    /// Group used for per-group errors (for a data hall: `cold` or `hot` aisle).
    pub group: String,
}

/// One operating condition and what was measured under it.
#[derive(Debug, Clone)]
pub struct Snapshot<S> {
    /// Label, unique within the observations (e.g. `t0`). It keys journaled runs.
    pub label: String,
    /// The operating condition the model is run at.
    pub scenario: S,
    /// One entry per output; `None` where the output was not measured (a dead sensor).
    pub measured: Vec<Option<f64>>,
}

/// Measurements over one or more snapshots, with their output descriptions.
#[derive(Debug, Clone)]
pub struct Observations<S> {
    outputs: Vec<OutputInfo>,
    snapshots: Vec<Snapshot<S>>,
}

impl<S> Observations<S> {
    /// Checked observations: output names unique and not empty (reports and journals
    /// name outputs by them), at least one snapshot, unique labels, one entry per
    /// output, every measured value finite, every snapshot with at least one measurement.
    pub fn new(outputs: Vec<OutputInfo>, snapshots: Vec<Snapshot<S>>) -> Result<Self> {
        let mut seen = std::collections::HashSet::with_capacity(outputs.len());
        for (k, o) in outputs.iter().enumerate() {
            if o.name.is_empty() {
                return Err(Error::Mismatch(format!("output {k} has an empty name")));
            }
            if !seen.insert(o.name.as_str()) {
                return Err(Error::Mismatch(format!(
                    "output {k}: duplicate output name `{}`",
                    o.name
                )));
            }
        }
        if snapshots.is_empty() {
            return Err(Error::Mismatch(
                "observations need at least one snapshot".into(),
            ));
        }
        for (i, s) in snapshots.iter().enumerate() {
            if snapshots[..i].iter().any(|o| o.label == s.label) {
                return Err(Error::Mismatch(format!(
                    "duplicate snapshot label `{}`",
                    s.label
                )));
            }
            if s.measured.len() != outputs.len() {
                return Err(Error::Mismatch(format!(
                    "snapshot `{}` has {} measurements for {} outputs",
                    s.label,
                    s.measured.len(),
                    outputs.len()
                )));
            }
            if let Some((k, v)) = s
                .measured
                .iter()
                .enumerate()
                .find_map(|(k, m)| m.filter(|v| !v.is_finite()).map(|v| (k, v)))
            {
                return Err(Error::Mismatch(format!(
                    "snapshot `{}`, output `{}`: measured value {v} is not finite",
                    s.label, outputs[k].name
                )));
            }
            if s.measured.iter().all(Option::is_none) {
                return Err(Error::Mismatch(format!(
                    "snapshot `{}` has no measurement",
                    s.label
                )));
            }
        }
        Ok(Observations { outputs, snapshots })
    }

    /// Output descriptions.
    pub fn outputs(&self) -> &[OutputInfo] {
        &self.outputs
    }

    /// Output names in order.
    pub fn output_names(&self) -> Vec<String> {
        self.outputs.iter().map(|o| o.name.clone()).collect()
    }

    /// The snapshots.
    pub fn snapshots(&self) -> &[Snapshot<S>] {
        &self.snapshots
    }

    /// Number of measured values over all snapshots.
    pub fn measured_count(&self) -> usize {
        self.snapshots
            .iter()
            .map(|s| s.measured.iter().flatten().count())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn output(name: &str) -> OutputInfo {
        OutputInfo {
            name: name.into(),
            group: "g".into(),
        }
    }

    #[test]
    fn output_names_must_be_unique_and_not_empty() {
        let snap = || {
            vec![Snapshot {
                label: "t0".into(),
                scenario: (),
                measured: vec![Some(20.0), Some(21.0)],
            }]
        };
        let e = Observations::new(vec![output("a"), output("a")], snap()).unwrap_err();
        assert!(e.to_string().contains("duplicate output name `a`"), "{e}");
        let e = Observations::new(vec![output("a"), output("")], snap()).unwrap_err();
        assert!(e.to_string().contains("output 1 has an empty name"), "{e}");
        Observations::new(vec![output("a"), output("b")], snap()).expect("distinct names");
    }
}
