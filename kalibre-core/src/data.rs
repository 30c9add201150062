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
    /// Each measurement's scale (its standard uncertainty), per snapshot and output;
    /// `None`: every residual counts in the outputs' own units.
    scales: Option<Vec<Vec<f64>>>,
    /// What one snapshot is called in messages ([`Self::new_called`]).
    noun: &'static str,
}

/// A name for a message: escaped (a control character is shown, not sent to the
/// terminal) and cut short when long.
fn quoted(name: &str) -> String {
    const SHOWN: usize = 40;
    let short: String = name.chars().take(SHOWN).collect();
    let more = if name.chars().count() > SHOWN {
        "..."
    } else {
        ""
    };
    format!("`{}{more}`", short.escape_debug())
}

impl<S> Observations<S> {
    /// Checked observations: output names unique and not empty (reports and journals
    /// name outputs by them), at least one snapshot, unique labels, one entry per
    /// output, every measured value finite, every snapshot with at least one measurement.
    /// Output names and snapshot labels must be printable: not empty, no control
    /// character, at most [`crate::MAX_NAME_CHARS`] characters ([`crate::unprintable_name`]).
    ///
    /// ```
    /// use kalibre_core::{Observations, OutputInfo, Snapshot};
    /// let outputs = || vec![OutputInfo { name: "t_out_c".into(), group: String::new() }];
    /// let snap = |label: &str| Snapshot { label: label.into(), scenario: (), measured: vec![Some(30.1)] };
    /// assert!(Observations::new(outputs(), vec![snap("winter")]).is_ok());
    /// let e = Observations::new(outputs(), vec![snap("win\u{1b}[2Jter")]).unwrap_err();
    /// assert!(e.to_string().contains("control character"), "{e}");
    /// assert!(Observations::new(outputs(), vec![snap("")]).is_err());
    /// ```
    pub fn new(outputs: Vec<OutputInfo>, snapshots: Vec<Snapshot<S>>) -> Result<Self> {
        Self::new_called("snapshot", outputs, snapshots)
    }

    /// As [`Self::new`], for observations whose user calls an operating condition by
    /// another name (`scenario`, `test case`): the loop's messages about one (its checks
    /// here, a failed or mis-shaped run, none that ran everywhere) then use that name.
    ///
    /// ```
    /// use kalibre_core::{Observations, OutputInfo, Snapshot};
    /// let outputs = vec![OutputInfo { name: "t_out_c".into(), group: String::new() }];
    /// let snap = Snapshot { label: "winter".into(), scenario: (), measured: vec![None] };
    /// let e = Observations::new_called("scenario", outputs, vec![snap]).unwrap_err();
    /// assert!(e.to_string().contains("scenario `winter` has no measurement"), "{e}");
    /// ```
    pub fn new_called(
        noun: &'static str,
        outputs: Vec<OutputInfo>,
        snapshots: Vec<Snapshot<S>>,
    ) -> Result<Self> {
        let mut seen = std::collections::HashSet::with_capacity(outputs.len());
        for (k, o) in outputs.iter().enumerate() {
            if o.name.is_empty() {
                return Err(Error::Mismatch(format!("output {k} has an empty name")));
            }
            if let Some(why) = crate::unprintable_name(&o.name) {
                return Err(Error::Mismatch(format!(
                    "output {k}: name {} {why}",
                    quoted(&o.name)
                )));
            }
            if !seen.insert(o.name.as_str()) {
                return Err(Error::Mismatch(format!(
                    "output {k}: duplicate output name `{}`",
                    o.name
                )));
            }
        }
        if outputs.is_empty() {
            return Err(Error::Mismatch(
                "observations need at least one output".into(),
            ));
        }
        if snapshots.is_empty() {
            return Err(Error::Mismatch(format!(
                "observations need at least one {noun}"
            )));
        }
        for (i, s) in snapshots.iter().enumerate() {
            // Labels key journaled runs and are printed in messages, reports and file
            // names: an empty one names nothing, and the rest must be printable.
            if s.label.is_empty() {
                return Err(Error::Mismatch(format!(
                    "{noun} {i} has an empty label; expected a name"
                )));
            }
            if let Some(why) = crate::unprintable_name(&s.label) {
                return Err(Error::Mismatch(format!(
                    "{noun} {i}: label {} {why}",
                    quoted(&s.label)
                )));
            }
            if snapshots[..i].iter().any(|o| o.label == s.label) {
                return Err(Error::Mismatch(format!(
                    "duplicate {noun} label `{}`",
                    s.label
                )));
            }
            if s.measured.len() != outputs.len() {
                return Err(Error::Mismatch(format!(
                    "{noun} `{}` has {} measurements for {} outputs",
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
                    "{noun} `{}`, output `{}`: measured value {v} is not finite",
                    s.label, outputs[k].name
                )));
            }
            if s.measured.iter().all(Option::is_none) {
                return Err(Error::Mismatch(format!(
                    "{noun} `{}` has no measurement",
                    s.label
                )));
            }
        }
        Ok(Observations {
            outputs,
            snapshots,
            scales: None,
            noun,
        })
    }

    /// The observations with each measurement's scale: `scales[snapshot][output]`, in the
    /// output's units (its standard uncertainty, say). The loop then weighs each residual
    /// by its scale (weighted least squares): it sees the model's outputs and the
    /// measurements divided by them, so its errors are in scale units, and outputs of
    /// different units (a pressure in Pa beside a temperature in C) count alike. The
    /// journal keeps the model's outputs as they ran, so a change of scales repeats no
    /// run. The surrogate is fitted to the scaled outputs too: a surrogate of a physical
    /// form must allow for that, and one that pools snapshots whose scenarios compare
    /// equal ([`crate::GaussianProcess`]) needs them on equal scales. Every scale must be
    /// finite and positive, where measured or not.
    ///
    /// ```
    /// use kalibre_core::{Observations, OutputInfo, Snapshot};
    /// let outputs = vec![
    ///     OutputInfo { name: "t_out_c".into(), group: String::new() },
    ///     OutputInfo { name: "dp_pa".into(), group: String::new() },
    /// ];
    /// let snap = Snapshot { label: "winter".into(), scenario: (), measured: vec![Some(30.1), Some(1250.0)] };
    /// let obs = Observations::new(outputs, vec![snap])?.with_scales(vec![vec![0.5, 200.0]])?;
    /// assert_eq!(obs.normalised().snapshots()[0].measured, vec![Some(60.2), Some(6.25)]);
    /// # Ok::<(), kalibre_core::Error>(())
    /// ```
    pub fn with_scales(mut self, scales: Vec<Vec<f64>>) -> Result<Self> {
        if scales.len() != self.snapshots.len() {
            return Err(Error::Mismatch(format!(
                "{} rows of scales for {} {}s",
                scales.len(),
                self.snapshots.len(),
                self.noun
            )));
        }
        for (snap, row) in self.snapshots.iter().zip(&scales) {
            if row.len() != self.outputs.len() {
                return Err(Error::Mismatch(format!(
                    "{} `{}` has {} scales for {} outputs",
                    self.noun,
                    snap.label,
                    row.len(),
                    self.outputs.len()
                )));
            }
            for ((m, scale), info) in snap.measured.iter().zip(row).zip(&self.outputs) {
                if !(scale.is_finite() && *scale > 0.0) {
                    return Err(Error::Mismatch(format!(
                        "{} `{}`, output `{}`: scale {scale} is not a finite positive \
                         number",
                        self.noun, snap.label, info.name
                    )));
                }
                if let Some(v) = m.filter(|v| !(v / scale).is_finite()) {
                    return Err(Error::Mismatch(format!(
                        "{} `{}`, output `{}`: measured value {v} over its scale {scale:e} \
                         is not finite",
                        self.noun, snap.label, info.name
                    )));
                }
            }
        }
        self.scales = Some(scales);
        Ok(self)
    }

    /// Each measurement's scale, `[snapshot][output]`, if given ([`Self::with_scales`]).
    pub fn scales(&self) -> Option<&[Vec<f64>]> {
        self.scales.as_deref()
    }

    /// The observations as the loop sees them: each measurement divided by its scale
    /// (and no scales left), or a copy where there are none.
    pub fn normalised(&self) -> Self
    where
        S: Clone,
    {
        let mut snapshots = self.snapshots.clone();
        if let Some(scales) = &self.scales {
            for (snap, row) in snapshots.iter_mut().zip(scales) {
                for (m, scale) in snap.measured.iter_mut().zip(row) {
                    *m = m.map(|v| v / scale);
                }
            }
        }
        Observations {
            outputs: self.outputs.clone(),
            snapshots,
            scales: None,
            noun: self.noun,
        }
    }

    /// Output descriptions.
    pub fn outputs(&self) -> &[OutputInfo] {
        &self.outputs
    }

    /// Output names in order.
    pub fn output_names(&self) -> Vec<String> {
        self.outputs.iter().map(|o| o.name.clone()).collect()
    }

    /// What one snapshot is called in messages: `snapshot` unless made with
    /// [`Self::new_called`].
    pub fn noun(&self) -> &'static str {
        self.noun
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

    /// Labels key journaled runs and are printed: empty, too long or holding a control
    /// character is refused, naming the snapshot (escaped, cut short).
    #[test]
    fn snapshot_labels_must_be_printable_names() {
        let with_label = |label: String| {
            Observations::new(
                vec![output("a")],
                vec![Snapshot {
                    label,
                    scenario: (),
                    measured: vec![Some(20.0)],
                }],
            )
        };
        let e = with_label(String::new()).unwrap_err().to_string();
        assert!(e.contains("snapshot 0 has an empty label"), "{e}");
        // No outputs at all: said as such, not as a snapshot with no measurement.
        let none = Observations::new(
            Vec::new(),
            vec![Snapshot {
                label: "a".to_string(),
                scenario: (),
                measured: Vec::new(),
            }],
        );
        let e = none.unwrap_err().to_string();
        assert!(e.contains("at least one output"), "{e}");
        let e = with_label("x".repeat(500)).unwrap_err().to_string();
        assert!(
            e.contains("is 500 characters long; expected at most 200"),
            "{e}"
        );
        assert!(e.len() < 200, "the label is cut short: {e}");
        let e = with_label("win\u{1b}[2Jter".into())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`win\\u{1b}[2Jter`") && e.contains("U+001B"),
            "{e}"
        );
        assert!(
            !e.contains('\u{1b}'),
            "escaped, not sent to the terminal: {e}"
        );
        let e = Observations::new(
            vec![output("a\nb")],
            vec![Snapshot {
                label: "t0".into(),
                scenario: (),
                measured: vec![Some(20.0)],
            }],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("output 0: name `a\\nb`"), "{e}");
        with_label("x".repeat(200)).expect("200 characters is the limit");
    }

    #[test]
    fn scales_must_fit_the_measurements_and_be_positive() {
        let obs = || {
            Observations::new(
                vec![output("a"), output("b")],
                vec![Snapshot {
                    label: "t0".into(),
                    scenario: (),
                    measured: vec![Some(20.0), None],
                }],
            )
            .unwrap()
        };
        let e = obs().with_scales(vec![]).unwrap_err();
        assert!(
            e.to_string().contains("0 rows of scales for 1 snapshots"),
            "{e}"
        );
        let e = obs().with_scales(vec![vec![1.0]]).unwrap_err();
        assert!(e.to_string().contains("1 scales for 2 outputs"), "{e}");
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = obs().with_scales(vec![vec![1.0, bad]]).unwrap_err();
            assert!(e.to_string().contains("output `b`: scale"), "{bad}: {e}");
        }
        let e = obs().with_scales(vec![vec![1e-310, 1.0]]).unwrap_err();
        assert!(
            e.to_string()
                .contains("over its scale 1e-310 is not finite"),
            "{e}"
        );
        let scaled = obs().with_scales(vec![vec![4.0, 2.0]]).unwrap();
        assert_eq!(scaled.scales(), Some(&[vec![4.0, 2.0]][..]));
        let n = scaled.normalised();
        assert_eq!(n.snapshots()[0].measured, vec![Some(5.0), None]);
        assert!(n.scales().is_none());
    }
}
