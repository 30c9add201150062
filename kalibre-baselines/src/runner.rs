//! Running the model at one parameter point for every snapshot (through the run journal
//! when one is given), scoring it, and the history every model-in-the-loop baseline keeps.

use std::time::Instant;

use kalibre_core::{
    check_outputs, ErrorMetrics, Model, Observations, ParamSpace, RunStore, Validator,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::Result;

/// One iteration of a baseline: how many model runs it has used and the MAE it reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistoryPoint {
    /// Iteration (0 is the evaluation of the start point).
    pub iteration: usize,
    /// Model runs so far (one per snapshot per evaluated point).
    pub model_runs: usize,
    /// MAE of this iteration's point (C); infinite when a run failed.
    pub mae_c: f64,
    /// Lowest MAE so far (C).
    pub best_mae_c: f64,
}

/// What a model-in-the-loop baseline returns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaselineReport {
    /// Which baseline (`one_plus_one_es`, `manual_heuristic`).
    pub method: String,
    /// Parameter names, in order.
    pub param_names: Vec<String>,
    /// Best parameters found (physical values).
    pub best_params: Vec<f64>,
    /// MAE at the best parameters (C).
    pub best_mae_c: f64,
    /// MAE at the initial parameters (C); infinite when a run failed.
    pub initial_mae_c: f64,
    /// Model runs used (one per snapshot per evaluated point, journal replays included).
    pub model_runs: usize,
    /// One point per iteration.
    pub history: Vec<HistoryPoint>,
    /// Wall time, seconds.
    pub wall_s: f64,
}

impl BaselineReport {
    /// Model runs used when the MAE first reached `mae_c` or lower (`None`: never).
    pub fn runs_to_reach(&self, mae_c: f64) -> Option<usize> {
        self.history
            .iter()
            .find(|h| h.best_mae_c <= mae_c)
            .map(|h| h.model_runs)
    }
}

/// The result of running the model at one point for every snapshot.
#[derive(Debug, Clone, PartialEq)]
pub struct PointResult {
    /// Outputs per snapshot; `None` when any run failed.
    pub outputs: Option<Vec<Vec<f64>>>,
    /// Overall MAE over every measured value (C); `+inf` when a run failed.
    pub mae_c: f64,
}

/// Runs a model at physical parameter points for every snapshot and scores the result
/// with [`ErrorMetrics`]. With a [`RunStore`], journaled runs are replayed and new runs
/// journaled.
pub struct ModelMae<'a, M: Model> {
    model: &'a M,
    observations: &'a Observations<M::Scenario>,
    space: &'a ParamSpace,
    store: Option<&'a RunStore>,
    param_names: Vec<String>,
    output_names: Vec<String>,
    /// Each snapshot's [`Model::scenario_key`], computed once.
    scenario_keys: Vec<String>,
}

impl<'a, M: Model> ModelMae<'a, M>
where
    M::Scenario: Sync,
{
    /// An evaluator; a store must carry the model's fingerprint.
    pub fn new(
        model: &'a M,
        observations: &'a Observations<M::Scenario>,
        space: &'a ParamSpace,
        store: Option<&'a RunStore>,
    ) -> Result<Self> {
        if space.is_empty() {
            return Err(crate::Error::Mismatch(
                "the parameter space is empty".into(),
            ));
        }
        if let Some(s) = store {
            if s.fingerprint() != model.fingerprint() {
                return Err(crate::Error::Mismatch(format!(
                    "run journal is for model fingerprint `{}`, the model's is `{}`",
                    s.fingerprint(),
                    model.fingerprint()
                )));
            }
        }
        Ok(ModelMae {
            model,
            observations,
            space,
            store,
            param_names: space.names(),
            output_names: observations.output_names(),
            scenario_keys: (observations.snapshots().iter())
                .map(|snap| model.scenario_key(&snap.scenario))
                .collect(),
        })
    }

    /// The parameter space.
    pub fn space(&self) -> &ParamSpace {
        self.space
    }

    /// The observations.
    pub fn observations(&self) -> &Observations<M::Scenario> {
        self.observations
    }

    /// Model runs per evaluated point (the number of snapshots).
    pub fn runs_per_point(&self) -> usize {
        self.observations.snapshots().len()
    }

    /// Runs the model at `params` (physical) for every snapshot, in snapshot order.
    /// A failed run is a value (MAE `+inf`); only a journal error is an `Err`.
    pub fn run(&self, params: &[f64]) -> Result<PointResult> {
        self.space.check_physical(params)?;
        // Snapshots run in parallel; results are collected in snapshot order.
        let results = self
            .observations
            .snapshots()
            .par_iter()
            .zip(&self.scenario_keys)
            .map(|(snap, inputs)| {
                let cached = self
                    .store
                    .and_then(|s| s.get_keyed(&snap.label, inputs, &self.param_names, params));
                if let Some((_, rec)) = cached {
                    return Ok(rec.result());
                }
                let t0 = Instant::now();
                let r = self
                    .model
                    .evaluate(&snap.scenario, params)
                    .and_then(|o| check_outputs(o, &self.output_names));
                if let Some(s) = self.store {
                    s.record_keyed(
                        &snap.label,
                        inputs,
                        &self.param_names,
                        params,
                        &r,
                        t0.elapsed().as_secs_f64(),
                    )?;
                }
                Ok(r)
            })
            .collect::<Result<Vec<_>>>()?;
        let mut outputs = Vec::with_capacity(results.len());
        let mut failed = false;
        for r in results {
            match r {
                Ok(o) => outputs.push(o.values),
                Err(_) => failed = true,
            }
        }
        if failed {
            return Ok(PointResult {
                outputs: None,
                mae_c: f64::INFINITY,
            });
        }
        let v = ErrorMetrics.validate(self.observations, &outputs)?;
        Ok(PointResult {
            outputs: Some(outputs),
            mae_c: ErrorMetrics.score(&v),
        })
    }
}
