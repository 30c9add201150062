//! Step 4 of the loop: score model outputs against the measurements.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::{Error, Observations, Result};

/// Mean absolute, root-mean-square and maximum absolute error over a set of values.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Mean absolute error.
    pub mae: f64,
    /// Root-mean-square error.
    pub rmse: f64,
    /// Largest absolute error.
    pub max_abs: f64,
    /// Number of compared values.
    pub count: usize,
}

/// Accumulates residuals into [`ErrorStats`].
#[derive(Debug, Clone, Copy, Default)]
struct Acc {
    abs: f64,
    sq: f64,
    max: f64,
    n: usize,
}

impl Acc {
    fn add(&mut self, r: f64) {
        self.abs += r.abs();
        self.sq += r * r;
        self.max = self.max.max(r.abs());
        self.n += 1;
    }
    fn stats(&self) -> ErrorStats {
        if self.n == 0 {
            return ErrorStats::default();
        }
        let n = self.n as f64;
        ErrorStats {
            mae: self.abs / n,
            rmse: (self.sq / n).sqrt(),
            max_abs: self.max,
            count: self.n,
        }
    }
}

/// Errors of one set of predictions against the measurements, at every granularity.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    /// Over every measured value.
    pub overall: ErrorStats,
    /// Per snapshot label, in snapshot order.
    pub per_snapshot: Vec<(String, ErrorStats)>,
    /// Per output group (e.g. `cold`, `hot`).
    pub per_group: BTreeMap<String, ErrorStats>,
    /// Per output name, in output order (over all snapshots).
    pub per_output: Vec<(String, ErrorStats)>,
}

/// Scores predictions (one vector per snapshot) against observations.
pub trait Validator: Sync {
    /// Errors at every granularity. Predictions of another shape than the observations
    /// (one vector per snapshot, one value per output) are an error.
    fn validate<S>(
        &self,
        observations: &Observations<S>,
        predicted: &[Vec<f64>],
    ) -> Result<Validation>;

    /// The single number the loop minimises (lower is better).
    fn score(&self, validation: &Validation) -> f64 {
        validation.overall.mae
    }
}

/// The default validator: residual `predicted - measured`, scored by overall MAE.
///
/// ```
/// use kalibre_core::{ErrorMetrics, Observations, OutputInfo, Snapshot, Validator};
/// let outputs = vec![
///     OutputInfo { name: "c01".into(), group: "cold".into() },
///     OutputInfo { name: "h01".into(), group: "hot".into() },
/// ];
/// let obs = Observations::new(outputs, vec![Snapshot {
///     label: "t0".into(), scenario: (), measured: vec![Some(20.0), Some(30.0)] }]).unwrap();
/// let v = ErrorMetrics.validate(&obs, &[vec![21.0, 27.0]]).unwrap();
/// assert_eq!(v.overall.mae, 2.0);
/// assert_eq!(v.overall.max_abs, 3.0);
/// assert_eq!(v.per_group["hot"].mae, 3.0);
/// // A missing prediction is an error, not a perfect score.
/// assert!(ErrorMetrics.validate(&obs, &[]).is_err());
/// assert!(ErrorMetrics.validate(&obs, &[vec![21.0]]).is_err());
/// ```
#[derive(Debug, Clone, Copy, Default)]
pub struct ErrorMetrics;

impl Validator for ErrorMetrics {
    fn validate<S>(
        &self,
        observations: &Observations<S>,
        predicted: &[Vec<f64>],
    ) -> Result<Validation> {
        check_prediction_shape(observations, predicted)?;
        let outputs = observations.outputs();
        let mut overall = Acc::default();
        let mut per_output = vec![Acc::default(); outputs.len()];
        let mut per_group: BTreeMap<String, Acc> = BTreeMap::new();
        let mut per_snapshot = Vec::new();
        for (snap, pred) in observations.snapshots().iter().zip(predicted) {
            let mut acc = Acc::default();
            for (k, (m, p)) in snap.measured.iter().zip(pred).enumerate() {
                if let Some(m) = m {
                    let r = p - m;
                    acc.add(r);
                    overall.add(r);
                    per_output[k].add(r);
                    per_group
                        .entry(outputs[k].group.clone())
                        .or_default()
                        .add(r);
                }
            }
            per_snapshot.push((snap.label.clone(), acc.stats()));
        }
        Ok(Validation {
            overall: overall.stats(),
            per_snapshot,
            per_group: per_group.into_iter().map(|(g, a)| (g, a.stats())).collect(),
            per_output: outputs
                .iter()
                .zip(&per_output)
                .map(|(o, a)| (o.name.clone(), a.stats()))
                .collect(),
        })
    }
}

/// Checks that `predicted` has one vector per snapshot of `observations`, each with one
/// value per output: what every [`Validator`] needs before it can score them.
pub fn check_prediction_shape<S>(
    observations: &Observations<S>,
    predicted: &[Vec<f64>],
) -> Result<()> {
    let snaps = observations.snapshots();
    let outputs = observations.outputs().len();
    if predicted.len() != snaps.len() {
        return Err(Error::Mismatch(format!(
            "{} predicted snapshots for {} observed ones",
            predicted.len(),
            snaps.len()
        )));
    }
    match snaps
        .iter()
        .zip(predicted)
        .find(|(_, p)| p.len() != outputs)
    {
        Some((snap, p)) => Err(Error::Mismatch(format!(
            "snapshot `{}`: {} predicted values for {outputs} outputs",
            snap.label,
            p.len()
        ))),
        None => Ok(()),
    }
}
