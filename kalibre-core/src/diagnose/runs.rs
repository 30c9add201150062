//! Model runs of a diagnosis beyond its linearisation: at a hypothesis's fitted point, at
//! the calibrated parameters' own refit, and the helpers every run of the diagnosis shares
//! (through the journal, outputs in the observations' scale units).

use super::linearise::check;
use super::{CandidateEffect, Diagnosis, LineariseSettings};
use crate::calibrate::runner::{RunResult, Runner};
use crate::calibrate::NamedValues;
use crate::{Model, Observations, ParamSpace, Result, RunStore};

/// What the model itself reads at a hypothesis's fitted point ([`run_fitted`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FittedRun {
    /// The point: the calibrated parameters moved by the joint fit's change, the
    /// candidate's at `absent` plus its fitted change, each clamped into its range.
    pub params: Vec<f64>,
    /// The model's mean absolute residual there (in the observations' scale units, as
    /// [`super::Diagnosis::mae`]), or why a run there failed.
    pub mae: std::result::Result<f64, String>,
    /// Model runs made (not in the journal before).
    pub runs: usize,
    /// Runs read from the journal.
    pub cached: usize,
}

/// Runs the model where the diagnosis fitted `candidate` (`result`'s `fitted`, its
/// parameters' changes from absent, and `current_change`, the calibrated parameters'
/// change beside it), through `store`: the linearisation's prediction checked by the
/// model itself. A candidate that reads no better there than the calibrated point (or,
/// when the calibration had not converged, than [`Calibrated::run_refit_alone`]) is
/// refuted ([`Hypothesis::refuted`](super::Hypothesis::refuted)).
pub fn run_fitted<M: Model>(
    model: &M,
    obs: &Observations<M::Scenario>,
    space: &ParamSpace,
    params: &[f64],
    candidate: &CandidateEffect,
    result: &super::HypothesisResult,
    store: &RunStore,
) -> Result<FittedRun> {
    check(
        space,
        params,
        std::slice::from_ref(candidate),
        &LineariseSettings::default(),
    )?;
    let at = Calibrated {
        model,
        obs,
        space,
        params,
        store,
    };
    let point = at.fitted_point(candidate, result);
    let run = at.run(std::slice::from_ref(&point))?.remove(0);
    Ok(FittedRun {
        mae: run.mae(),
        params: run.params,
        runs: run.runs,
        cached: run.cached,
    })
}

/// A model at its calibrated parameters, with the observations it was calibrated on and
/// the journal every run goes through: what a diagnosis's own model runs need.
pub struct Calibrated<'a, M: Model> {
    /// The model.
    pub model: &'a M,
    /// The observations it was calibrated on.
    pub obs: &'a Observations<M::Scenario>,
    /// Its parameter space (each candidate's parameters fixed at their absent values).
    pub space: &'a ParamSpace,
    /// The calibrated parameters, a point of `space`.
    pub params: &'a [f64],
    /// The journal: a run already there is read, a new one kept.
    pub store: &'a RunStore,
}

/// One point run at every snapshot.
#[derive(Debug, Clone, PartialEq)]
pub struct PointRun {
    /// The point.
    pub params: Vec<f64>,
    /// Model minus measurement over the measured rows (as
    /// [`measured_rows`](super::measured_rows) orders them, in the observations' scale
    /// units), or the first snapshot that failed and why.
    pub residuals: std::result::Result<Vec<f64>, String>,
    /// Model runs made (not in the journal before).
    pub runs: usize,
    /// Runs read from the journal.
    pub cached: usize,
}

impl PointRun {
    /// The mean absolute residual (as [`Diagnosis::mae`]), or why a run failed.
    pub fn mae(&self) -> std::result::Result<f64, String> {
        (self.residuals.as_ref())
            .map(|r| super::mean_abs(r))
            .map_err(Clone::clone)
    }
}

impl<M: Model> Calibrated<'_, M> {
    /// Runs the model at each of `points` (every snapshot of each, in parallel).
    pub fn run(&self, points: &[Vec<f64>]) -> Result<Vec<PointRun>> {
        let inputs = RunInputs::new(self.model, self.obs, self.space);
        let results = (inputs.runner(self.model, self.obs, self.store)).run(0, points)?;
        Ok((points.iter().zip(&results))
            .map(|(point, results)| {
                let mut tally = Tally::default();
                tally.count(std::slice::from_ref(results));
                let residuals = all_ran(results)
                    .map(|outputs| scaled_residuals(self.obs, &outputs))
                    .map_err(|(s, why)| format!("`{}`: {why}", self.obs.snapshots()[s].label));
                PointRun {
                    params: point.clone(),
                    residuals,
                    runs: tally.runs,
                    cached: tally.cached,
                }
            })
            .collect())
    }

    /// The calibrated parameters moved by `change` (by name; a name not in it stays),
    /// each clamped into its bounds.
    pub fn moved(&self, change: &NamedValues) -> Vec<f64> {
        (self.space.params().iter().zip(self.params))
            .map(|(p, x)| match change.get(&p.name) {
                Some(dx) => (x + dx).clamp(p.lower, p.upper),
                None => *x,
            })
            .collect()
    }

    /// Where `result` fitted `candidate`: the calibrated parameters moved by the joint
    /// fit's change, the candidate's at `absent` plus its fitted change, each clamped into
    /// its range (where [`run_fitted`] runs).
    pub fn fitted_point(
        &self,
        candidate: &CandidateEffect,
        result: &super::HypothesisResult,
    ) -> Vec<f64> {
        let mut point = self.moved(&result.current_change);
        for c in &candidate.params {
            let change = result.fitted.get(&c.name).unwrap_or(0.0);
            point[c.index] = (c.absent + change).clamp(c.lower, c.upper);
        }
        point
    }

    /// Runs the model where `diagnosis` refit the calibrated parameters alone
    /// ([`Diagnosis::refit_change`]): the floor a candidate must beat, read by the model,
    /// when the calibration stopped short of it.
    pub fn run_refit_alone(&self, diagnosis: &Diagnosis) -> Result<PointRun> {
        let point = self.moved(&diagnosis.refit_change);
        Ok(self.run(std::slice::from_ref(&point))?.remove(0))
    }
}

/// Model minus measurement over the measured rows (as [`measured_rows`] orders them), in
/// the scales' units: `outputs` per snapshot, as the runner gives them, already are.
pub(super) fn scaled_residuals<S>(obs: &Observations<S>, outputs: &[Vec<f64>]) -> Vec<f64> {
    let mut r = Vec::new();
    for (s, snap) in obs.snapshots().iter().enumerate() {
        for (o, m) in snap.measured.iter().enumerate() {
            if let Some(m) = m {
                let scale = obs.scales().map_or(1.0, |sc| sc[s][o]);
                r.push(outputs[s][o] - m / scale);
            }
        }
    }
    r
}

/// What a [`Runner`] borrows besides the model, the observations and the journal.
pub(super) struct RunInputs {
    pub(super) names: Vec<String>,
    pub(super) output_names: Vec<String>,
    pub(super) scenario_keys: Vec<String>,
}

impl RunInputs {
    pub(super) fn new<M: Model>(
        model: &M,
        obs: &Observations<M::Scenario>,
        space: &ParamSpace,
    ) -> Self {
        RunInputs {
            names: space.names(),
            output_names: obs.outputs().iter().map(|o| o.name.clone()).collect(),
            scenario_keys: (obs.snapshots().iter())
                .map(|s| model.scenario_key(&s.scenario))
                .collect(),
        }
    }

    /// Runs through `store`, as the loop's step 3 does (outputs in scale units).
    pub(super) fn runner<'r, M: Model>(
        &'r self,
        model: &'r M,
        obs: &'r Observations<M::Scenario>,
        store: &'r RunStore,
    ) -> Runner<'r, M> {
        Runner {
            model,
            observations: obs,
            store,
            param_names: &self.names,
            scenario_keys: &self.scenario_keys,
            output_names: &self.output_names,
            observers: &[],
            pool: None,
            scales: obs.scales(),
        }
    }
}

/// Runs made and read.
#[derive(Default)]
pub(super) struct Tally {
    pub(super) runs: usize,
    pub(super) cached: usize,
}

impl Tally {
    pub(super) fn count(&mut self, results: &[Vec<RunResult>]) {
        for r in results.iter().flatten() {
            if r.cached {
                self.cached += 1;
            } else {
                self.runs += 1;
            }
        }
    }
}

/// One point's outputs at every snapshot, or the first snapshot that failed and why.
pub(super) fn all_ran(
    results: &[RunResult],
) -> std::result::Result<Vec<Vec<f64>>, (usize, String)> {
    (results.iter().enumerate())
        .map(|(s, r)| match &r.result {
            Ok(o) => Ok(o.values.clone()),
            // The log's gist says why, where the reason only says that it failed.
            Err(e) => Err((
                s,
                match e.log_gist() {
                    Some(gist) => format!("{e} ({gist})"),
                    None => e.to_string(),
                },
            )),
        })
        .collect()
}
