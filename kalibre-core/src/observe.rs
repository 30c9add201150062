//! Progress events of a calibration, for progress bars, logs and experiment recorders.
//!
//! Library code never prints: the [`crate::Calibrator`] hands every event to its
//! observers. Model runs of one step finish in parallel, so observers are called from
//! several threads at once ([`Observe`] takes `&self` and is `Sync`; use interior
//! mutability to record).

use crate::{FitSummary, ModelError, SearchOutcome};

use crate::calibrate::{IterationRecord, StopReason};

/// What happened. Borrowed data lives only for the call.
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub enum Event<'a> {
    /// A model run is about to start (or to be replayed from the journal when `cached`).
    RunStarted {
        /// Loop iteration (0 is the initial design).
        iteration: usize,
        /// Snapshot label.
        snapshot: &'a str,
        /// Physical parameter values.
        params: &'a [f64],
        /// True when the run is replayed from the journal instead of computed.
        cached: bool,
    },
    /// A model run finished (or was replayed from the journal when `cached`).
    RunFinished {
        /// Loop iteration (0 is the initial design).
        iteration: usize,
        /// Snapshot label.
        snapshot: &'a str,
        /// Physical parameter values.
        params: &'a [f64],
        /// True when the run was replayed from the journal.
        cached: bool,
        /// Why the run failed, when it did.
        error: Option<&'a ModelError>,
        /// Wall time of the run (as journaled, for a cached run), in seconds.
        wall_s: f64,
    },
    /// The initial design has run.
    DesignDone {
        /// Distinct parameter points of the design.
        points: usize,
        /// Model runs (points times snapshots).
        model_runs: usize,
        /// Runs that failed.
        failed: usize,
    },
    /// Step 1: the surrogate was fitted.
    FitDone {
        /// Loop iteration.
        iteration: usize,
        /// Training samples used (augmented copies included).
        samples: usize,
        /// What the fit reports.
        summary: &'a FitSummary,
        /// Wall time, seconds.
        wall_s: f64,
    },
    /// Step 2: the search on the surrogate finished.
    SearchDone {
        /// Loop iteration.
        iteration: usize,
        /// The search's result (with its trace).
        outcome: &'a SearchOutcome,
        /// Wall time, seconds.
        wall_s: f64,
    },
    /// A proposal sat on an earlier failed point and was moved with seeded noise.
    Perturbed {
        /// Loop iteration.
        iteration: usize,
        /// The proposal, unit box.
        from_unit: &'a [f64],
        /// Where it was moved, unit box.
        to_unit: &'a [f64],
    },
    /// Steps 3 and 4 done: the iteration's record, as it goes into the report.
    IterationDone {
        /// The record.
        record: &'a IterationRecord,
    },
    /// The loop stopped.
    Stopped {
        /// Why.
        reason: StopReason,
    },
}

/// Receives calibration [`Event`]s. Called from several threads during parallel runs.
pub trait Observe: Sync {
    /// Handles one event.
    fn observe(&self, event: &Event<'_>);
}

impl<F: Fn(&Event<'_>) + Sync> Observe for F {
    fn observe(&self, event: &Event<'_>) {
        self(event)
    }
}
