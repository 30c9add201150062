//! What the loop needs of a user's model, space, surrogate and prior, checked where it
//! first uses them: the search reads a prediction of another length or a NaN as a bad
//! point and would go on without a word, ending on a calibration no surrogate stood
//! behind; values in another order would calibrate the wrong parameters.

use crate::{Error, Model, Observations, ParamSpace, Regularizer, Result, Surrogate};

/// Checks the space (not empty, not every parameter fixed) and that its names and the
/// observations' are those the model gives ([`Model::param_names`],
/// [`Model::output_names`]), in the same order.
pub(crate) fn check_inputs<M: Model>(
    model: &M,
    space: &ParamSpace,
    observations: &Observations<M::Scenario>,
) -> Result<()> {
    if space.is_empty() {
        return Err(Error::Mismatch("the parameter space is empty".into()));
    }
    // Every design point would be the same point, run once and answered from the store
    // ever after.
    if space.params().iter().all(|p| p.is_fixed()) {
        return Err(Error::Mismatch(format!(
            "every parameter has equal bounds ({}): nothing to calibrate",
            crate::some_names(&space.names())
        )));
    }
    let differ = |what: &str, model: Vec<String>, ours: Vec<String>, where_: &str| {
        (model != ours).then(|| {
            Error::Mismatch(format!(
                "the model's {what} are [{}], {where_} [{}]: they must be the same names in \
                 the same order",
                crate::some_names(&model),
                crate::some_names(&ours)
            ))
        })
    };
    let params = (model.param_names())
        .and_then(|m| differ("parameters", m, space.names(), "the parameter space's"));
    let outputs = model.output_names().and_then(|m| {
        differ(
            "outputs",
            m,
            observations.output_names(),
            "the observations'",
        )
    });
    params.or(outputs).map_or(Ok(()), Err)
}

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
