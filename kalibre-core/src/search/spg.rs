//! Spectral projected gradient (Birgin, Martinez and Raydan, 2000) on the unit box, as an
//! argmin solver: the local, monotone phase after Adam.
//!
//! Each step goes along the projected gradient `P(x - lambda g) - x` with the
//! Barzilai-Borwein step length `lambda = s.s / s.y`, and backtracks until the Armijo
//! condition holds, so the cost never rises. Adam's sign-like steps overshoot in narrow
//! valleys of a smooth, ill-conditioned loss (calibration near its optimum); this phase
//! finds the descent that remains there, in any dimension, from the gradient alone.

use argmin::core::{Problem, Solver, State, TerminationReason, TerminationStatus, KV};
use ndarray::Array1;

use std::time::Instant;

use super::kernels::norm_and_finite;
use super::problem::{
    check_start, finite_or_inf, require, run_from_start, BoxState, UnitBoxProblem, COST_COUNT,
    COST_GRADIENT_COUNT,
};
use super::{Objective, SearchOutcome, Searcher, TracePoint};
use crate::Result;

/// Spectral projected gradient settings.
///
/// | Setting | Default |
/// |---|---|
/// | steps | 40 |
/// | Armijo sufficient-decrease factor | 1e-4 |
/// | halvings per line search | 30 |
/// | stop when the projected step (max norm) is below | 1e-9 |
///
/// ```
/// use kalibre_core::search::{Objective, ProjectedGradient, Searcher};
/// // An ill-conditioned quadratic with its minimum at (0.3, 0.6).
/// struct Valley;
/// impl Objective for Valley {
///     fn dim(&self) -> usize { 2 }
///     fn cost(&self, x: &[f64]) -> f64 {
///         (x[0] - 0.3).powi(2) + 1e3 * (x[1] - 0.6).powi(2)
///     }
///     fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
///         (self.cost(x), vec![2.0 * (x[0] - 0.3), 2e3 * (x[1] - 0.6)])
///     }
/// }
/// let out = ProjectedGradient::default().search(&Valley, &[0.9, 0.1], 0).unwrap();
/// assert!((out.best_unit[0] - 0.3).abs() < 1e-4 && (out.best_unit[1] - 0.6).abs() < 1e-4);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectedGradient {
    steps: usize,
    armijo: f64,
    max_halvings: usize,
    tolerance: f64,
}

impl Default for ProjectedGradient {
    fn default() -> Self {
        ProjectedGradient {
            steps: 40,
            armijo: 1e-4,
            max_halvings: 30,
            tolerance: 1e-9,
        }
    }
}

impl ProjectedGradient {
    /// Settings with `steps` iterations (0 is allowed: the phase is then skipped by the
    /// hybrid; alone it evaluates the start only).
    pub fn with_steps(steps: usize) -> Result<Self> {
        require(steps <= 100_000, "local_steps", || {
            format!("must be at most 100000, got {steps}")
        })?;
        Ok(ProjectedGradient {
            steps,
            ..Self::default()
        })
    }

    /// Iterations.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Runs from `start` until done or `deadline`; trace iterations are numbered from
    /// `trace_offset`.
    pub(crate) fn run(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        trace_offset: usize,
        deadline: Option<Instant>,
    ) -> Result<SearchOutcome> {
        check_start(objective, start)?;
        let solver = SpgSolver {
            settings: self.clone(),
            lambda: 1.0,
            done: false,
            phase_offset: trace_offset,
            trace: Vec::new(),
        };
        let (best_unit, best_cost, evaluations, solver, timed_out) =
            run_from_start(objective, solver, start, self.steps as u64, deadline)?;
        SearchOutcome {
            best_unit,
            best_cost,
            evaluations,
            trace: solver.trace,
            timed_out,
        }
        .found_finite("projected gradient")
    }
}

impl Searcher for ProjectedGradient {
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

/// The argmin solver behind [`ProjectedGradient`].
struct SpgSolver {
    settings: ProjectedGradient,
    /// Barzilai-Borwein step length.
    lambda: f64,
    /// No descent is left (or the gradient is unusable).
    done: bool,
    phase_offset: usize,
    trace: Vec<TracePoint>,
}

type Step = std::result::Result<(BoxState, Option<KV>), argmin::core::Error>;

impl SpgSolver {
    fn push_trace(&mut self, best_cost: f64, cost: f64, grad_norm: f64) {
        self.trace.push(TracePoint {
            iteration: self.phase_offset + self.trace.len(),
            phase: "spg".into(),
            best_cost,
            cost,
            grad_norm: grad_norm.is_finite().then_some(grad_norm),
        });
    }
}

/// `P(x - lambda g) - x` on the unit box.
fn projected_step(x: &[f64], g: &[f64], lambda: f64) -> Vec<f64> {
    x.iter()
        .zip(g)
        .map(|(xi, gi)| (xi - lambda * gi).clamp(0.0, 1.0) - xi)
        .collect()
}

impl Solver<UnitBoxProblem<'_>, BoxState> for SpgSolver {
    fn name(&self) -> &str {
        "spectral projected gradient (unit box)"
    }

    fn init(&mut self, problem: &mut Problem<UnitBoxProblem<'_>>, state: BoxState) -> Step {
        let x = state
            .get_param()
            .cloned()
            .ok_or_else(|| argmin::core::Error::msg("SPG needs a start point"))?;
        let (cost, grad) = problem.problem(COST_GRADIENT_COUNT, |p| {
            Ok(p.objective().cost_and_gradient(&x.to_vec()))
        })?;
        let (grad_norm, finite) = norm_and_finite(&grad);
        let cost = finite_or_inf(cost);
        self.done = !(finite && cost.is_finite());
        // First step length: one unit of the projected gradient's largest coordinate.
        let step = projected_step(x.as_slice().unwrap_or(&x.to_vec()), &grad, 1.0);
        let big = step.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        self.lambda = if big > 0.0 {
            (0.1 / big).min(1e10)
        } else {
            1.0
        };
        self.push_trace(cost, cost, grad_norm);
        Ok((state.param(x).cost(cost).gradient(Array1::from(grad)), None))
    }

    fn next_iter(&mut self, problem: &mut Problem<UnitBoxProblem<'_>>, state: BoxState) -> Step {
        let x: Vec<f64> = state
            .get_param()
            .ok_or_else(|| argmin::core::Error::msg("SPG lost its iterate"))?
            .to_vec();
        let g: Vec<f64> = state
            .get_gradient()
            .ok_or_else(|| argmin::core::Error::msg("SPG lost its gradient"))?
            .to_vec();
        let f = state.get_cost();
        let d = projected_step(&x, &g, self.lambda);
        let d_max = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let slope: f64 = g.iter().zip(&d).map(|(a, b)| a * b).sum();
        if d_max < self.settings.tolerance || slope >= 0.0 {
            self.done = true;
            return Ok((state, None));
        }
        let mut t = 1.0;
        let mut accepted = None;
        for _ in 0..=self.settings.max_halvings {
            let trial: Vec<f64> = x
                .iter()
                .zip(&d)
                .map(|(xi, di)| (xi + t * di).clamp(0.0, 1.0))
                .collect();
            let c = problem.problem(COST_COUNT, |p| Ok(p.finite_cost(&trial)))?;
            if c <= f + self.settings.armijo * t * slope {
                accepted = Some(trial);
                break;
            }
            t *= 0.5;
        }
        let Some(x_new) = accepted else {
            self.done = true;
            return Ok((state, None));
        };
        let (cost, g_new) = problem.problem(COST_GRADIENT_COUNT, |p| {
            Ok(p.objective().cost_and_gradient(&x_new))
        })?;
        let (grad_norm, finite) = norm_and_finite(&g_new);
        let cost = finite_or_inf(cost);
        if !(finite && cost.is_finite()) {
            self.done = true;
            return Ok((state, None));
        }
        let (mut ss, mut sy) = (0.0, 0.0);
        for i in 0..x.len() {
            let s = x_new[i] - x[i];
            ss += s * s;
            sy += s * (g_new[i] - g[i]);
        }
        self.lambda = if sy > 0.0 {
            (ss / sy).clamp(1e-10, 1e10)
        } else {
            1e10
        };
        let best = state.get_best_cost().min(cost);
        self.push_trace(best, cost, grad_norm);
        let kv = argmin::kv!("lambda" => self.lambda; "grad_norm" => grad_norm;);
        Ok((
            state
                .param(Array1::from(x_new))
                .cost(cost)
                .gradient(Array1::from(g_new)),
            Some(kv),
        ))
    }

    fn terminate(&mut self, _state: &BoxState) -> TerminationStatus {
        if self.done {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Tilted;
    impl Objective for Tilted {
        fn dim(&self) -> usize {
            2
        }
        fn cost(&self, x: &[f64]) -> f64 {
            // Minimum outside the box at (1.5, -0.2): the solution is the corner (1, 0).
            (x[0] - 1.5).powi(2) + 10.0 * (x[1] + 0.2).powi(2)
        }
        fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
            (self.cost(x), vec![2.0 * (x[0] - 1.5), 20.0 * (x[1] + 0.2)])
        }
    }

    #[test]
    fn reaches_the_bound_constrained_minimum_and_never_rises() {
        let out = ProjectedGradient::default()
            .search(&Tilted, &[0.2, 0.7], 0)
            .unwrap();
        assert!((out.best_unit[0] - 1.0).abs() < 1e-9, "{:?}", out.best_unit);
        assert!(out.best_unit[1].abs() < 1e-9, "{:?}", out.best_unit);
        for w in out.trace.windows(2) {
            assert!(w[1].cost <= w[0].cost, "{:?}", out.trace);
        }
    }

    #[test]
    fn stays_at_a_stationary_start() {
        let out = ProjectedGradient::default()
            .search(&Tilted, &[1.0, 0.0], 0)
            .unwrap();
        assert_eq!(out.best_unit, vec![1.0, 0.0]);
    }
}
