//! The output correction of step 2: the current surrogate's discrepancy against the
//! model at the best run (and, for the linear term, at the other runs).

use super::state::{BestPoint, State};
use crate::search::{OutputCorrection, CORRECTION_LENGTH_UNIT, CORRECTION_RIDGE_REL};
use crate::{Observations, Surrogate};

/// Model minus surrogate per snapshot and output at physical `params`.
fn discrepancy<Su: Surrogate>(
    surrogate: &Su,
    obs: &Observations<Su::Scenario>,
    params: &[f64],
    outputs: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    obs.snapshots()
        .iter()
        .zip(outputs)
        .map(|(snap, model)| {
            let sur = surrogate.predict(&snap.scenario, params);
            // A prediction of another length is no discrepancy: NaN, so the fit leaves
            // the run out rather than zipping the outputs it has.
            if sur.len() != model.len() {
                return vec![f64::NAN; model.len()];
            }
            model.iter().zip(sur).map(|(m, s)| m - s).collect()
        })
        .collect()
}

/// The correction anchored at the best run; with `linear`, fitted to every other
/// successful run too.
pub(crate) fn fit<Su: Surrogate>(
    surrogate: &Su,
    obs: &Observations<Su::Scenario>,
    state: &State,
    best: &BestPoint,
    linear: bool,
) -> OutputCorrection {
    let anchor = discrepancy(surrogate, obs, &best.params, &best.outputs);
    if !linear {
        return OutputCorrection::constant(anchor);
    }
    let others: Vec<(Vec<f64>, Vec<Vec<f64>>)> = state
        .ok_units
        .iter()
        .zip(&state.ok_runs)
        .filter(|(u, _)| u.as_slice() != best.unit.as_slice())
        .map(|(u, (params, outputs))| (u.clone(), discrepancy(surrogate, obs, params, outputs)))
        .collect();
    OutputCorrection::fit(
        &best.unit,
        anchor,
        &others,
        CORRECTION_LENGTH_UNIT,
        CORRECTION_RIDGE_REL,
    )
}
