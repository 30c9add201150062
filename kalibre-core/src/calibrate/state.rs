//! What the loop accumulates: run counts, training samples, which points ran and failed,
//! and the best point so far.

use super::runner::RunResult;
use super::RunCounts;
use crate::{Observations, Sample, Validation, Validator};

/// The best point so far.
pub(crate) struct BestPoint {
    pub(crate) iteration: usize,
    pub(crate) unit: Vec<f64>,
    pub(crate) params: Vec<f64>,
    pub(crate) score: f64,
    pub(crate) validation: Validation,
    pub(crate) outputs: Vec<Vec<f64>>,
}

/// What one point's runs gave.
pub(crate) struct PointEval {
    pub(crate) validation: Option<Validation>,
    pub(crate) score: Option<f64>,
    pub(crate) ok_runs: usize,
}

/// Everything the loop accumulates.
#[derive(Default)]
pub(crate) struct State {
    pub(crate) samples: Vec<Sample>,
    pub(crate) ok_units: Vec<Vec<f64>>,
    /// Per successful point (as `ok_units`): physical parameters and outputs per snapshot.
    pub(crate) ok_runs: Vec<(Vec<f64>, Vec<Vec<f64>>)>,
    pub(crate) failed_units: Vec<Vec<f64>>,
    pub(crate) best: Option<BestPoint>,
    pub(crate) counts: RunCounts,
    /// While set, `absorb` books runs but leaves the best point to [`State::promote`]:
    /// the weighted polish's optimum is not the lowest MAE.
    pub(crate) best_held: bool,
}

impl State {
    /// Books one point's runs: counts, training samples, validation and the best point.
    pub(crate) fn absorb<S, V: Validator>(
        &mut self,
        validator: &V,
        obs: &Observations<S>,
        iteration: usize,
        unit: &[f64],
        params: &[f64],
        results: Vec<RunResult>,
    ) -> PointEval {
        let mut outputs = Vec::with_capacity(results.len());
        let mut ok_runs = 0;
        for (s, r) in results.into_iter().enumerate() {
            self.counts.total += 1;
            if r.cached {
                self.counts.cached += 1;
            } else {
                self.counts.new += 1;
            }
            match r.result {
                Ok(o) => {
                    ok_runs += 1;
                    self.samples.push(Sample {
                        snapshot: s,
                        params: params.to_vec(),
                        outputs: o.values.clone(),
                        weight: 1.0,
                    });
                    outputs.push(o.values);
                }
                Err(_) => self.counts.failed += 1,
            }
        }
        if ok_runs < obs.snapshots().len() {
            self.failed_units.push(unit.to_vec());
            return PointEval {
                validation: None,
                score: None,
                ok_runs,
            };
        }
        self.ok_units.push(unit.to_vec());
        self.ok_runs.push((params.to_vec(), outputs.clone()));
        let validation = validator.validate(obs, &outputs);
        let score = validator.score(&validation);
        if !self.best_held
            && score.is_finite()
            && self.best.as_ref().is_none_or(|b| score < b.score)
        {
            self.best = Some(BestPoint {
                iteration,
                unit: unit.to_vec(),
                params: params.to_vec(),
                score,
                validation: validation.clone(),
                outputs,
            });
        }
        PointEval {
            validation: Some(validation),
            score: Some(score),
            ok_runs,
        }
    }

    /// Makes a point that ran at every snapshot the best one whatever its score: the
    /// weighted polish's optimum, which minimises a weighted misfit rather than the MAE.
    pub(crate) fn promote<S, V: Validator>(
        &mut self,
        validator: &V,
        obs: &Observations<S>,
        iteration: usize,
        unit: &[f64],
        params: &[f64],
        outputs: Vec<Vec<f64>>,
    ) {
        if self.best.as_ref().is_some_and(|b| b.unit == unit) {
            return;
        }
        let validation = validator.validate(obs, &outputs);
        let score = validator.score(&validation);
        self.best = Some(BestPoint {
            iteration,
            unit: unit.to_vec(),
            params: params.to_vec(),
            score,
            validation,
            outputs,
        });
    }
}
