//! What the loop needs of a user's surrogate and prior, checked where it first uses
//! them: the search reads a prediction of another length or a NaN as a bad point and
//! would go on without a word, ending on a calibration no surrogate stood behind.

use crate::{Error, Observations, Regularizer, Result, Surrogate};

/// Checks `surrogate`, just fitted at `iteration`, at the physical point `params`: one
/// finite prediction per output at every snapshot, and one finite gradient entry per
/// parameter.
pub(crate) fn check_surrogate<Su: Surrogate>(
    surrogate: &Su,
    obs: &Observations<Su::Scenario>,
    params: &[f64],
    iteration: usize,
) -> Result<()> {
    let outputs = obs.outputs().len();
    let bad = |what: String| {
        Error::Mismatch(format!(
            "the surrogate, fitted at iteration {iteration}, {what}"
        ))
    };
    for snap in obs.snapshots() {
        let at = &snap.label;
        let pred = surrogate.predict(&snap.scenario, params);
        if pred.len() != outputs {
            return Err(bad(format!(
                "predicts {} values for {outputs} outputs at snapshot `{at}`",
                pred.len()
            )));
        }
        if let Some(k) = pred.iter().position(|v| !v.is_finite()) {
            let name = &obs.outputs()[k].name;
            return Err(bad(format!(
                "predicts {} for output `{name}` at snapshot `{at}`",
                pred[k]
            )));
        }
        let grad = surrogate.vjp(&snap.scenario, params, &vec![1.0; outputs]);
        if grad.len() != params.len() || grad.iter().any(|g| !g.is_finite()) {
            return Err(bad(format!(
                "gives a gradient of {} values, not {} finite ones, at snapshot `{at}`",
                grad.len(),
                params.len()
            )));
        }
    }
    Ok(())
}

/// Checks the prior at the physical point `params`: a finite value and one finite
/// gradient entry per parameter.
pub(crate) fn check_regularizer(reg: &dyn Regularizer, params: &[f64]) -> Result<()> {
    let (value, grad) = reg.value_and_gradient(params);
    if !value.is_finite() || grad.len() != params.len() || grad.iter().any(|g| !g.is_finite()) {
        return Err(Error::Mismatch(format!(
            "the prior (regulariser) gives {value} with a gradient of {} values at the \
             search's start, not a finite value and {} finite ones",
            grad.len(),
            params.len()
        )));
    }
    Ok(())
}
