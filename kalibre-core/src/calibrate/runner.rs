//! Step 3: run the model at parameter points for every snapshot, in parallel, through the
//! journal (a journaled run is replayed, never repeated).

use std::time::Instant;

use rayon::prelude::*;

use crate::observe::{Event, Observe};
use crate::{check_outputs, Error, Model, ModelError, Observations, Outputs, Result, RunStore};

/// One run's result and whether it came from the journal.
#[derive(Debug, Clone)]
pub(crate) struct RunResult {
    pub result: std::result::Result<Outputs, ModelError>,
    pub cached: bool,
}

/// What step 3 needs, borrowed from the calibrator.
pub(crate) struct Runner<'r, M: Model> {
    pub model: &'r M,
    pub observations: &'r Observations<M::Scenario>,
    pub store: &'r RunStore,
    pub param_names: &'r [String],
    /// Each snapshot's [`Model::scenario_key`], computed once.
    pub scenario_keys: &'r [String],
    pub output_names: &'r [String],
    pub observers: &'r [Box<dyn Observe + 'r>],
    pub pool: Option<&'r rayon::ThreadPool>,
    /// Each measurement's scale ([`Observations::with_scales`]): the loop sees the
    /// outputs divided by it; the journal keeps them as they ran.
    pub scales: Option<&'r [Vec<f64>]>,
}

impl<M: Model> Runner<'_, M> {
    /// Snapshot `s`'s outputs as the loop compares them ([`scaled`]).
    fn scaled(&self, s: usize, outputs: Outputs) -> Outputs {
        scaled(outputs, self.scales.map(|sc| &sc[s][..]))
    }

    /// Runs every point at every snapshot; `out[point][snapshot]`, in order whatever the
    /// thread count.
    pub fn run(&self, iteration: usize, points: &[Vec<f64>]) -> Result<Vec<Vec<RunResult>>> {
        let n_snap = self.observations.snapshots().len();
        let jobs: Vec<(usize, usize)> = (0..points.len())
            .flat_map(|p| (0..n_snap).map(move |s| (p, s)))
            .collect();
        let go = || {
            jobs.par_iter()
                .map(|&(p, s)| self.run_one(iteration, s, &points[p]))
                .collect::<Result<Vec<_>>>()
        };
        let flat = match self.pool {
            Some(pool) => pool.install(go)?,
            None => go()?,
        };
        let mut it = flat.into_iter();
        Ok((0..points.len())
            .map(|_| it.by_ref().take(n_snap).collect())
            .collect())
    }

    /// A successful run's outputs as the loop accepts them: one finite value per output,
    /// a spread (if any) to match, finite extras, and nothing the model calls impossible.
    fn checked(&self, outputs: Outputs) -> std::result::Result<Outputs, ModelError> {
        let o = check_outputs(outputs, self.output_names)?;
        if let Some(sp) = &o.spread {
            // A spread is a standard deviation: finite and not negative.
            if sp.len() != o.values.len() || sp.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(ModelError::failed(
                    "output spread has the wrong length, or a negative or non-finite value",
                ));
            }
        }
        // JSON has no NaN or infinity: a non-finite extra would be journaled as `null`,
        // a line no later opening reads back, so the run would be lost (or the journal
        // refused). Such a run fails here, named, like a non-finite output.
        if let Some(reason) = crate::model::non_finite_extra(&o.extras) {
            return Err(ModelError::failed(reason));
        }
        self.model.check_plausible(&o)?;
        Ok(o)
    }

    fn emit(&self, event: Event<'_>) {
        for o in self.observers {
            o.observe(&event);
        }
    }

    fn run_one(&self, iteration: usize, s: usize, params: &[f64]) -> Result<RunResult> {
        let snap = &self.observations.snapshots()[s];
        let label = snap.label.as_str();
        let inputs = &self.scenario_keys[s];
        if let Some((line, rec)) = self
            .store
            .get_keyed(label, inputs, self.param_names, params)
        {
            self.emit(Event::RunStarted {
                iteration,
                snapshot: label,
                params,
                cached: true,
            });
            let result = rec.result();
            // A record this loop wrote passed these checks; one that fails them was
            // edited or written by another tool, and must not reach the surrogate.
            if let Some(Err(e)) = result.as_ref().ok().map(|o| self.checked(o.clone())) {
                // A count that does not fit is rarely one line's: the model's outputs
                // changed under an unchanged fingerprint, so every line is stale.
                let cure = if matches!(e, ModelError::WrongOutputCount { .. }) {
                    "the model's outputs changed since it ran, but not its fingerprint \
                     (`Model::fingerprint`), so every run there is another model's: give the \
                     model a new fingerprint, or start a new journal"
                } else {
                    "delete the line to run the model there again"
                };
                return Err(Error::Journal {
                    path: self
                        .store
                        .path()
                        .map_or_else(|| "(in memory)".to_string(), |p| p.display().to_string()),
                    reason: format!(
                        "line {line} ({} `{label}`, status ok): {e}; {cure}",
                        self.observations.noun()
                    ),
                });
            }
            self.emit(Event::RunFinished {
                iteration,
                snapshot: label,
                params,
                cached: true,
                error: result.as_ref().err(),
                wall_s: rec.wall_s,
            });
            return Ok(RunResult {
                result: result.map(|o| self.scaled(s, o)),
                cached: true,
            });
        }
        self.emit(Event::RunStarted {
            iteration,
            snapshot: label,
            params,
            cached: false,
        });
        let t0 = Instant::now();
        // A model that panics (an `unwrap`, an index out of range) fails this run, which
        // is journaled like any other, instead of ending the calibration and the runs
        // in flight beside it.
        let evaluated = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.model.evaluate(&snap.scenario, params)
        }))
        .unwrap_or_else(|payload| {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".into());
            Err(ModelError::failed(format!("the model panicked: {what}")))
        });
        let result = evaluated.and_then(|o| self.checked(o));
        let wall_s = t0.elapsed().as_secs_f64();
        // A run that failed once kalibre's stop began (Ctrl-C, `kill`) was killed or
        // refused by the stop, not by the model: journaled as failed, it would be taken
        // for the model's failure on the resume. This thread waits for the stop to end
        // the process instead, so neither the run nor the loop goes on.
        if result.is_err() && crate::external::stopping() {
            crate::external::await_stop();
        }
        self.store
            .record_keyed(label, inputs, self.param_names, params, &result, wall_s)?;
        self.emit(Event::RunFinished {
            iteration,
            snapshot: label,
            params,
            cached: false,
            error: result.as_ref().err(),
            wall_s,
        });
        // A count that does not fit the observations is almost always the model's make,
        // not its parameters', so the first one stops the calibration (journaled, like
        // the runs in flight beside it) rather than failing run after run.
        if let Err(ModelError::WrongOutputCount { expected, got }) = &result {
            return Err(Error::Mismatch(format!(
                "{} `{label}`: the model returned {got} outputs where the observations \
                 have {expected}, so the calibration stops at the first such run (the model \
                 and the observations must list the same outputs, at every parameter value)",
                self.observations.noun()
            )));
        }
        Ok(RunResult {
            result: result.map(|o| self.scaled(s, o)),
            cached: false,
        })
    }
}

/// `outputs` (values and spread) divided by their measurements' `scales`, if any.
pub(crate) fn scaled(mut outputs: Outputs, scales: Option<&[f64]>) -> Outputs {
    if let Some(scales) = scales {
        divide(&mut outputs.values, scales);
        if let Some(spread) = &mut outputs.spread {
            divide(spread, scales);
        }
    }
    outputs
}

/// Each of `values` divided by its scale: one snapshot's outputs in scale units.
pub(crate) fn divide(values: &mut [f64], scales: &[f64]) {
    for (v, scale) in values.iter_mut().zip(scales) {
        *v /= scale;
    }
}

/// The snapshots at which every point of `results` (one row per point, one run per
/// snapshot) failed, each with its first failure and its kept directory: said when no
/// point then runs at every snapshot, so that the error names where and why (all fans off
/// in one snapshot) and where to look, not only that nothing ran. `None` when every
/// snapshot ran somewhere.
pub(crate) fn snapshots_failed_throughout(
    results: &[Vec<RunResult>],
    labels: &[&str],
    noun: &str,
    store: &RunStore,
) -> Option<String> {
    let dead: Vec<String> = labels
        .iter()
        .enumerate()
        .filter_map(|(j, label)| {
            let mut runs = results.iter().filter_map(|point| point.get(j));
            let first = runs.next()?.result.as_ref().err()?;
            runs.all(|r| r.result.is_err()).then(|| {
                let gist = first
                    .log_gist()
                    .map_or_else(String::new, |g| format!("; its log: {g}"));
                let kept = first
                    .run_dir()
                    .map_or_else(String::new, |d| format!("; its directory is kept: {d}"));
                format!(
                    "{noun} `{label}` failed at every design point (the first: \
                     {first}{gist}{kept})"
                )
            })
        })
        .collect();
    let journal = store.path().map_or_else(String::new, |p| {
        format!(
            " (each run's reason is in the run journal, {})",
            p.display()
        )
    });
    (!dead.is_empty()).then(|| format!("{}{journal}", dead.join("; ")))
}

/// The pool of `max_parallel_runs` threads for model runs (`None`: rayon's global pool).
pub(crate) fn pool(max_parallel_runs: Option<usize>) -> Result<Option<rayon::ThreadPool>> {
    max_parallel_runs
        .map(|n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| Error::InvalidSetting {
                    name: "max_parallel_runs".into(),
                    reason: e.to_string(),
                })
        })
        .transpose()
}

/// The error when all `design_runs` runs of the initial design failed, with the first
/// failure (by design order) and where each run's reason is.
pub(crate) fn design_failed(
    design_runs: usize,
    first_failure: Option<ModelError>,
    store: &RunStore,
) -> Error {
    let why = first_failure.map_or_else(String::new, |e| {
        let gist = e.log_gist().map(|g| format!("; its log: {g}"));
        // Where to look first: the kept directory (the command, its inputs, its logs).
        let kept = e
            .run_dir()
            .map(|d| format!(" (its directory is kept: {d})"));
        format!(
            "; the first: {e}{}{}",
            gist.unwrap_or_default(),
            kept.unwrap_or_default()
        )
    });
    // An in-memory store keeps the reasons with the calibrator, not in a file.
    let where_ = match store.path() {
        Some(p) => format!(
            " (each run's reason is in the run journal, {})",
            p.display()
        ),
        None => {
            " (a journal, `with_store(RunStore::open(..))`, keeps each run's reason)".to_string()
        }
    };
    Error::NoSuccessfulRun(format!(
        "all {design_runs} runs of the initial design failed{why}{where_}"
    ))
}
