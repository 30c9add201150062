//! An [`Objective`] seen as an argmin problem, and what the searchers share at the
//! argmin boundary (state type, start-point checks, error conversion, NaN handling).

use std::time::Instant;

use argmin::core::{CostFunction, Gradient, IterState, State};
use ndarray::Array1;

use super::Objective;
use crate::{Error, Result};

/// The argmin state all kalibre searchers run on: parameters and gradients are
/// `Array1<f64>` in the unit box, costs `f64`.
pub type BoxState = IterState<Array1<f64>, Array1<f64>, (), (), (), f64>;

/// Key under which cost-only evaluations are counted in argmin's `Problem`.
pub(crate) const COST_COUNT: &str = "cost_count";
/// Key under which cost-and-gradient evaluations are counted.
pub(crate) const COST_GRADIENT_COUNT: &str = "cost_gradient_count";

/// An [`Objective`] over the unit box as an argmin problem (`CostFunction` and
/// `Gradient`), so that argmin's own solvers can run on it too.
#[derive(Clone, Copy)]
pub struct UnitBoxProblem<'a> {
    objective: &'a dyn Objective,
}

impl<'a> UnitBoxProblem<'a> {
    /// Wraps an objective.
    pub fn new(objective: &'a dyn Objective) -> Self {
        UnitBoxProblem { objective }
    }

    /// The wrapped objective.
    pub fn objective(&self) -> &'a dyn Objective {
        self.objective
    }

    /// Cost at `x`, with a non-finite value (NaN, +-inf) mapped to `+inf` so that such a
    /// point is never taken as the best.
    pub fn finite_cost(&self, x: &[f64]) -> f64 {
        finite_or_inf(self.objective.cost(x))
    }
}

impl CostFunction for UnitBoxProblem<'_> {
    type Param = Array1<f64>;
    type Output = f64;

    fn cost(&self, param: &Array1<f64>) -> std::result::Result<f64, argmin::core::Error> {
        Ok(match param.as_slice() {
            Some(x) => self.finite_cost(x),
            None => self.finite_cost(&param.to_vec()),
        })
    }
}

impl Gradient for UnitBoxProblem<'_> {
    type Param = Array1<f64>;
    type Gradient = Array1<f64>;

    fn gradient(
        &self,
        param: &Array1<f64>,
    ) -> std::result::Result<Array1<f64>, argmin::core::Error> {
        let (_, g) = match param.as_slice() {
            Some(x) => self.objective.cost_and_gradient(x),
            None => self.objective.cost_and_gradient(&param.to_vec()),
        };
        Ok(Array1::from(g))
    }
}

/// `c` if finite, else `+inf`.
pub(crate) fn finite_or_inf(c: f64) -> f64 {
    if c.is_finite() {
        c
    } else {
        f64::INFINITY
    }
}

/// Checks that `start` fits the objective and lies in the unit box.
pub(crate) fn check_start(objective: &dyn Objective, start: &[f64]) -> Result<()> {
    let dim = objective.dim();
    if dim == 0 {
        return Err(Error::Mismatch(
            "search: the objective has no coordinates".into(),
        ));
    }
    if start.len() != dim {
        return Err(Error::Mismatch(format!(
            "search: start point has {} coordinates, the objective {dim}",
            start.len()
        )));
    }
    if let Some((i, v)) = start
        .iter()
        .enumerate()
        .find(|(_, v)| !(0.0..=1.0).contains(*v))
    {
        return Err(Error::InvalidParam {
            name: format!("#{i}"),
            reason: format!("start coordinate {v} is outside the unit box [0, 1]"),
        });
    }
    Ok(())
}

/// What [`run_from_start`] returns: the best point, its cost, the evaluations, the solver
/// (whose trace the caller keeps) and whether the deadline ended the run.
pub(crate) type RunOutcome<S> = (Vec<f64>, f64, usize, S, bool);

/// Runs a unit-box `solver` from `start` for at most `max_iters` iterations through argmin's
/// executor, and past `deadline` no further than the iteration under way: the best point
/// (the start when none was recorded), its cost, the evaluations, the solver and whether
/// the deadline stopped it.
pub(crate) fn run_from_start<'a, S>(
    objective: &'a dyn Objective,
    solver: S,
    start: &[f64],
    max_iters: u64,
    deadline: Option<Instant>,
) -> Result<RunOutcome<S>>
where
    S: argmin::core::Solver<UnitBoxProblem<'a>, BoxState>,
{
    let executor = argmin::core::Executor::new(UnitBoxProblem::new(objective), solver)
        .configure(|state| {
            state
                .param(Array1::from(start.to_vec()))
                .max_iters(max_iters)
        })
        .ctrlc(false);
    let result = with_deadline(executor, deadline)
        .run()
        .map_err(from_argmin)?;
    let timed_out = timed_out(&result.state);
    let best_cost = result.state.get_best_cost();
    let best_unit = match result.state.get_best_param() {
        Some(p) => p.to_vec(),
        None => start.to_vec(),
    };
    Ok((
        best_unit,
        best_cost,
        evaluations(&result.problem),
        result.solver,
        timed_out,
    ))
}

/// The executor with argmin's timeout at `deadline` (checked after each iteration; a
/// deadline already past ends the run after its first).
pub(crate) fn with_deadline<O, S: argmin::core::Solver<O, I>, I: State>(
    executor: argmin::core::Executor<O, S, I>,
    deadline: Option<Instant>,
) -> argmin::core::Executor<O, S, I> {
    match deadline {
        Some(d) => executor.timeout(d.saturating_duration_since(Instant::now())),
        None => executor,
    }
}

/// Whether argmin stopped a run at its timeout.
pub(crate) fn timed_out<I: State>(state: &I) -> bool {
    matches!(
        state.get_termination_reason(),
        Some(argmin::core::TerminationReason::Timeout)
    )
}

pub(crate) fn from_argmin(e: argmin::core::Error) -> Error {
    Error::Argmin(format!("{e:#}"))
}

/// Evaluations counted by argmin's `Problem` (cost and cost-and-gradient calls).
pub(crate) fn evaluations<O>(problem: &argmin::core::Problem<O>) -> usize {
    [COST_COUNT, COST_GRADIENT_COUNT]
        .iter()
        .map(|k| problem.counts.get(k).copied().unwrap_or(0) as usize)
        .sum()
}

/// Checks a setting with a predicate, naming it in the error.
pub(crate) fn require(ok: bool, name: &str, reason: impl FnOnce() -> String) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::InvalidSetting {
            name: name.into(),
            reason: reason(),
        })
    }
}
