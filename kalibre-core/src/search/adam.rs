//! Adam (Kingma and Ba, 2015) projected onto the unit box, as an argmin solver.
//!
//! Each step moves by the bias-corrected first moment over the square root of the second,
//! times a decaying learning rate, then clips every coordinate into `[0, 1]` (projection
//! onto the box). The best point evaluated is kept: Adam's iterates are not monotone.

use argmin::core::{Problem, Solver, State, TerminationReason, TerminationStatus, KV};
use ndarray::Array1;

use std::time::Instant;

use super::kernels::{adam_update, norm_and_finite, AdamStep};
use super::problem::{
    check_start, finite_or_inf, require, run_from_start, BoxState, UnitBoxProblem,
    COST_GRADIENT_COUNT,
};
use super::{Objective, SearchOutcome, Searcher, TracePoint};
use crate::Result;

/// Adam settings, checked by [`AdamBuilder::build`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `learning_rate` | 0.1 | initial step scale, in unit-box coordinates | > 0 |
/// | `decay` | 0.8 | learning-rate factor per `decay_every` steps | (0, 1] |
/// | `decay_every` | 10 | steps per decay factor | >= 1 |
/// | `beta1` | 0.9 | first-moment decay | [0, 1) |
/// | `beta2` | 0.999 | second-moment decay | [0, 1) |
/// | `epsilon` | 1e-8 | denominator guard | > 0 |
/// | `steps` | 100 | update steps (each one cost-and-gradient evaluation) | >= 1 |
///
/// The learning rate of step `t` (from 0) is `learning_rate * decay^(t / decay_every)`,
/// a smooth exponential schedule. Learning rate and decay are the paper's (Table 3);
/// with `decay_every = 10` the rate falls from 0.1 to 0.011 over 100 steps and to
/// 0.0036 over 150: early steps cross the box (Adam moves each coordinate by about the
/// learning rate per step, whatever the gradient's scale), late steps refine to about
/// 1% of a bound range.
///
/// A point where the objective or its gradient is not finite is never taken as the best;
/// the next iterate goes halfway back to the best point, and the moments are left as
/// they were. If that happens at the best point itself, Adam stops.
#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    learning_rate: f64,
    decay: f64,
    decay_every: usize,
    beta1: f64,
    beta2: f64,
    epsilon: f64,
    steps: usize,
}

impl Default for Adam {
    fn default() -> Self {
        Adam {
            learning_rate: 0.1,
            decay: 0.8,
            decay_every: 10,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            steps: 100,
        }
    }
}

/// The most steps a builder accepts (the loop's default: 100): a bound on one search's
/// time, which the loop's wall-time budget checks only between steps of the loop.
pub const MAX_ADAM_STEPS: usize = 1_000_000;

/// Unchecked [`Adam`] settings; [`build`](Self::build) checks them.
#[derive(Debug, Clone, PartialEq)]
pub struct AdamBuilder(Adam);

impl AdamBuilder {
    /// Initial learning rate (> 0), in unit-box coordinates.
    pub fn with_learning_rate(mut self, learning_rate: f64) -> Self {
        self.0.learning_rate = learning_rate;
        self
    }
    /// Learning-rate factor per `decay_every` steps, in `(0, 1]` (1: constant rate).
    pub fn with_decay(mut self, decay: f64) -> Self {
        self.0.decay = decay;
        self
    }
    /// Steps per decay factor (>= 1).
    pub fn with_decay_every(mut self, decay_every: usize) -> Self {
        self.0.decay_every = decay_every;
        self
    }
    /// First-moment decay in `[0, 1)`.
    pub fn with_beta1(mut self, beta1: f64) -> Self {
        self.0.beta1 = beta1;
        self
    }
    /// Second-moment decay in `[0, 1)`.
    pub fn with_beta2(mut self, beta2: f64) -> Self {
        self.0.beta2 = beta2;
        self
    }
    /// Denominator guard (> 0).
    pub fn with_epsilon(mut self, epsilon: f64) -> Self {
        self.0.epsilon = epsilon;
        self
    }
    /// Number of update steps (>= 1).
    pub fn with_steps(mut self, steps: usize) -> Self {
        self.0.steps = steps;
        self
    }
    /// Checks the settings; a bad one gives [`crate::Error::InvalidSetting`] naming it.
    pub fn build(self) -> Result<Adam> {
        let s = self.0;
        require(
            s.learning_rate.is_finite() && s.learning_rate > 0.0,
            "learning_rate",
            || {
                format!(
                    "must be positive and finite, got {}",
                    crate::number(s.learning_rate)
                )
            },
        )?;
        require(s.decay > 0.0 && s.decay <= 1.0, "decay", || {
            format!("must be in (0, 1], got {}", crate::number(s.decay))
        })?;
        require(s.decay_every >= 1, "decay_every", || {
            "must be at least 1 step".into()
        })?;
        require((0.0..1.0).contains(&s.beta1), "beta1", || {
            format!("must be in [0, 1), got {}", crate::number(s.beta1))
        })?;
        require((0.0..1.0).contains(&s.beta2), "beta2", || {
            format!("must be in [0, 1), got {}", crate::number(s.beta2))
        })?;
        require(s.epsilon.is_finite() && s.epsilon > 0.0, "epsilon", || {
            format!(
                "must be positive and finite, got {}",
                crate::number(s.epsilon)
            )
        })?;
        require((1..=MAX_ADAM_STEPS).contains(&s.steps), "steps", || {
            format!("must be in 1..={MAX_ADAM_STEPS}, got {}", s.steps)
        })?;
        Ok(s)
    }
}

impl Adam {
    /// A builder starting from the defaults.
    pub fn builder() -> AdamBuilder {
        AdamBuilder(Adam::default())
    }
    /// A builder starting from these settings.
    pub fn to_builder(&self) -> AdamBuilder {
        AdamBuilder(self.clone())
    }
    /// Initial learning rate.
    pub fn learning_rate(&self) -> f64 {
        self.learning_rate
    }
    /// Learning-rate factor per `decay_every` steps.
    pub fn decay(&self) -> f64 {
        self.decay
    }
    /// Steps per decay factor.
    pub fn decay_every(&self) -> usize {
        self.decay_every
    }
    /// Number of update steps.
    pub fn steps(&self) -> usize {
        self.steps
    }
    /// The learning rate of step `t` (counted from 0).
    pub fn rate_at(&self, t: usize) -> f64 {
        self.learning_rate * self.decay.powf(t as f64 / self.decay_every as f64)
    }

    /// The argmin solver for one run; the start point is the state's parameter.
    pub fn solver(&self) -> AdamSolver {
        AdamSolver {
            settings: self.clone(),
            m: Vec::new(),
            v: Vec::new(),
            t: 0,
            last_usable: false,
            phase_offset: 0,
            trace: Vec::new(),
        }
    }

    /// Runs Adam from `start` until its steps are done or `deadline`, numbering trace
    /// points from `trace_offset`.
    pub(crate) fn run(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        trace_offset: usize,
        deadline: Option<Instant>,
    ) -> Result<SearchOutcome> {
        check_start(objective, start)?;
        let mut solver = self.solver();
        solver.phase_offset = trace_offset;
        let (best_unit, best_cost, evaluations, solver, timed_out) =
            run_from_start(objective, solver, start, self.steps as u64, deadline)?;
        SearchOutcome {
            best_unit,
            best_cost,
            evaluations,
            trace: solver.trace,
            timed_out,
        }
        .found_finite("Adam")
    }
}

impl Searcher for Adam {
    /// Adam is deterministic: the seed is not used.
    fn search(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        _seed: u64,
    ) -> Result<SearchOutcome> {
        self.run(objective, start, 0, None)
    }

    fn search_until(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        _seed: u64,
        deadline: Option<Instant>,
    ) -> Result<SearchOutcome> {
        self.run(objective, start, 0, deadline)
    }
}

/// The running Adam: moments, step count and trace. Made by [`Adam::solver`].
pub struct AdamSolver {
    settings: Adam,
    m: Vec<f64>,
    v: Vec<f64>,
    t: usize,
    /// Whether the last evaluation had a finite cost and gradient.
    last_usable: bool,
    phase_offset: usize,
    trace: Vec<TracePoint>,
}

impl AdamSolver {
    /// One trace point per evaluation (the start point is the first).
    pub fn trace(&self) -> &[TracePoint] {
        &self.trace
    }

    /// Evaluates at `x`, puts point, cost and gradient into the state, records the trace.
    fn evaluate(
        &mut self,
        problem: &mut Problem<UnitBoxProblem<'_>>,
        state: BoxState,
        x: Array1<f64>,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let (cost, grad) = problem.problem(COST_GRADIENT_COUNT, |p| {
            Ok(match x.as_slice() {
                Some(s) => p.objective().cost_and_gradient(s),
                None => p.objective().cost_and_gradient(&x.to_vec()),
            })
        })?;
        let (grad_norm, grad_finite) = norm_and_finite(&grad);
        self.last_usable = cost.is_finite() && grad_finite;
        let cost = finite_or_inf(cost);
        let best_cost = state.get_best_cost().min(cost);
        self.trace.push(TracePoint {
            iteration: self.phase_offset + self.trace.len(),
            phase: "adam".into(),
            best_cost,
            cost,
            grad_norm: grad_norm.is_finite().then_some(grad_norm),
        });
        let kv = argmin::kv!("lr" => self.settings.rate_at(self.t); "grad_norm" => grad_norm;);
        Ok((
            state.param(x).cost(cost).gradient(Array1::from(grad)),
            Some(kv),
        ))
    }
}

impl Solver<UnitBoxProblem<'_>, BoxState> for AdamSolver {
    fn name(&self) -> &str {
        "Adam (projected onto the unit box)"
    }

    fn init(
        &mut self,
        problem: &mut Problem<UnitBoxProblem<'_>>,
        mut state: BoxState,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let x = state
            .take_param()
            .ok_or_else(|| argmin::core::Error::msg("Adam needs a start point"))?;
        self.m = vec![0.0; x.len()];
        self.v = vec![0.0; x.len()];
        self.t = 0;
        self.evaluate(problem, state, x)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<UnitBoxProblem<'_>>,
        mut state: BoxState,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let mut x = state
            .take_param()
            .ok_or_else(|| argmin::core::Error::msg("Adam lost its iterate"))?;
        let grad = state
            .take_gradient()
            .ok_or_else(|| argmin::core::Error::msg("Adam lost its gradient"))?;
        if self.last_usable {
            let s = &self.settings;
            let lr = s.rate_at(self.t);
            self.t += 1;
            let step = AdamStep {
                lr_c1: lr / (1.0 - s.beta1.powf(self.t as f64)),
                inv_c2: 1.0 / (1.0 - s.beta2.powf(self.t as f64)),
                beta1: s.beta1,
                beta2: s.beta2,
                epsilon: s.epsilon,
            };
            let xs = x
                .as_slice_mut()
                .ok_or_else(|| argmin::core::Error::msg("Adam iterate is not contiguous"))?;
            let gs = grad
                .as_slice()
                .ok_or_else(|| argmin::core::Error::msg("gradient is not contiguous"))?;
            adam_update(xs, &mut self.m, &mut self.v, gs, &step);
        } else {
            // Retreat halfway to the best point; `terminate` stops if this is the best.
            let best = state
                .get_best_param()
                .ok_or_else(|| argmin::core::Error::msg("Adam has no best point"))?;
            x.zip_mut_with(best, |xi, bi| *xi = 0.5 * (*xi + bi));
        }
        self.evaluate(problem, state, x)
    }

    fn terminate(&mut self, state: &BoxState) -> TerminationStatus {
        let stuck = !self.last_usable
            && match (state.get_param(), state.get_best_param()) {
                (Some(x), Some(best)) => x == best,
                _ => false,
            };
        if stuck {
            TerminationStatus::Terminated(TerminationReason::SolverExit(
                "objective or gradient not finite at the best point".into(),
            ))
        } else {
            TerminationStatus::NotTerminated
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Linear;
    impl Objective for Linear {
        fn dim(&self) -> usize {
            1
        }
        fn cost(&self, x: &[f64]) -> f64 {
            3.0 * x[0]
        }
        fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
            (self.cost(x), vec![3.0])
        }
    }

    #[test]
    fn schedule_decays_by_the_factor_every_decay_every_steps() {
        let a = Adam::default();
        assert_eq!(a.rate_at(0), 0.1);
        assert!((a.rate_at(10) - 0.08).abs() < 1e-15);
        assert!((a.rate_at(5) - 0.1 * 0.8f64.sqrt()).abs() < 1e-15);
        assert!((a.rate_at(100) - 0.1 * 0.8f64.powi(10)).abs() < 1e-15);
    }

    #[test]
    fn first_step_moves_by_the_learning_rate_and_is_projected() {
        // Adam's first step is lr * g / (|g| + eps): the learning rate, whatever the scale.
        let a = Adam::builder().with_steps(1).build().unwrap();
        let out = a.search(&Linear, &[0.5], 0).unwrap();
        assert!((out.best_unit[0] - 0.4).abs() < 1e-9);
        assert_eq!(out.evaluations, 2);
        // From 0.05 the step would leave the box: it stops at the bound.
        let out = a.search(&Linear, &[0.05], 0).unwrap();
        assert_eq!(out.best_unit, vec![0.0]);
    }
}
