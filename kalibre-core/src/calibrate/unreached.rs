//! The journal's runs a calibration did not reach.
//!
//! A resumed calibration replays its journaled runs in the order it asks for them, so a
//! smaller budget than the run that wrote the journal stops before the later ones, which
//! may hold a better point than any it reached. The report says so rather than let a
//! rerun with `--max-runs 15` quietly replace a better answer.

use serde::{Deserialize, Serialize};

use super::report::NamedValues;
use crate::{
    check_prediction_shape, Observations, ParamSpace, RunRecord, RunStatus, RunStore, Validator,
};

/// Journaled runs (of this model) the calibration did not ask for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnreachedRuns {
    /// How many journal lines of this model were never replayed.
    pub runs: usize,
    /// How many parameter points among them, within the space's bounds, ran
    /// successfully at every snapshot of these measurements (the points that can be
    /// scored). A point outside the bounds (a diagnosis's step of a parameter this
    /// calibration holds fixed) is no answer this calibration could give.
    pub complete_points: usize,
    /// The lowest-score complete point among them, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best: Option<UnreachedBest>,
}

/// The best point among the unreached runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnreachedBest {
    /// Its MAE against the measurements.
    pub mae_c: f64,
    /// Its score (what the loop minimises).
    pub score: f64,
    /// Its journal line of the first snapshot, to find it.
    pub line: usize,
    /// Its parameters.
    pub params: NamedValues,
}

/// One parameter point of the journal: its parameters, its first journal line and its
/// run at each snapshot (by the observations' order), in journal order.
type Point<'s> = (&'s [f64], usize, Vec<Option<&'s RunRecord>>);

/// What the calibration left unreached in `store`, scored with `validator` against
/// `observations`; `None` when it reached every journaled run.
pub(crate) fn summarise<S, V: Validator>(
    store: &RunStore,
    observations: &Observations<S>,
    validator: &V,
    space: &ParamSpace,
    scenario_keys: &[String],
    scales: Option<&[Vec<f64>]>,
) -> Option<UnreachedRuns> {
    let unreached = store.unreached();
    if unreached.is_empty() {
        return None;
    }
    let snapshots = observations.snapshots();
    let names = space.names();
    let mut points: Vec<Point> = Vec::new();
    for (line, rec) in &unreached {
        if rec.param_names != names
            || rec.status != RunStatus::Ok
            || space.check_physical(&rec.params).is_err()
        {
            continue;
        }
        let Some(s) = (0..snapshots.len())
            .find(|&s| snapshots[s].label == rec.scenario && scenario_keys[s] == rec.scenario_key)
        else {
            continue;
        };
        // The journal keys runs by the exact bits of the parameters; so do points here.
        let same = |p: &[f64]| {
            p.iter()
                .zip(&rec.params)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        };
        let at = match points.iter().position(|(p, _, _)| same(p)) {
            Some(at) => at,
            None => {
                points.push((&rec.params, *line, vec![None; snapshots.len()]));
                points.len() - 1
            }
        };
        points[at].2[s] = Some(rec);
    }
    let mut complete_points = 0;
    let mut best: Option<UnreachedBest> = None;
    for (params, line, runs) in &points {
        let Some(mut outputs) = runs
            .iter()
            .map(|r| r.and_then(|r| r.outputs.clone()))
            .collect::<Option<Vec<Vec<f64>>>>()
        else {
            continue;
        };
        // Journaled as they ran; judged, as the loop judged its runs, in scale units.
        for (row, sc) in outputs.iter_mut().zip(scales.into_iter().flatten()) {
            super::runner::divide(row, sc);
        }
        if check_prediction_shape(observations, &outputs).is_err() {
            continue;
        }
        complete_points += 1;
        let Ok(validation) = validator.validate(observations, &outputs) else {
            continue;
        };
        let score = validator.score(&validation);
        if score.is_finite() && best.as_ref().is_none_or(|b| score < b.score) {
            best = Some(UnreachedBest {
                mae_c: validation.overall.mae,
                score,
                line: *line,
                params: NamedValues::new(&names, params),
            });
        }
    }
    Some(UnreachedRuns {
        runs: unreached.len(),
        complete_points,
        best,
    })
}
