//! Step 2 of the loop: search the parameters on the surrogate against the measurements.
//!
//! Searchers minimise an [`Objective`] over the unit box `[0, 1]^d` and never leave it.
//! (The calibration loop clamps a point returned outside the box onto it, coordinate by
//! coordinate, so rounding past a face is harmless; a point of the wrong length or not
//! finite is an error.)
//! They are argmin solvers ([`DifferentialEvolution`], [`Adam`]) driven by argmin's
//! `Executor`; [`Hybrid`] runs differential evolution, then Adam from its best point,
//! as the paper does.

mod adam;
mod correction;
mod de;
mod hybrid;
mod kernels;
mod objective;
mod problem;
mod spg;

pub use adam::{Adam, AdamBuilder, AdamSolver, MAX_ADAM_STEPS};
pub use correction::{OutputCorrection, CORRECTION_LENGTH_UNIT, CORRECTION_RIDGE_REL};
pub use de::{
    DeSolver, DifferentialEvolution, DifferentialEvolutionBuilder, PopulationEval,
    AUTO_PARALLEL_MIN_EVAL_US, MAX_GENERATIONS, MAX_POPULATION,
};
pub use hybrid::{Hybrid, HYBRID_DE_GIVE_UP_AFTER};
pub use objective::{Regularizer, SurrogateObjective};
pub use problem::{BoxState, UnitBoxProblem};
pub use spg::ProjectedGradient;

use serde::{Deserialize, Serialize};

use crate::Result;

/// A cost over the unit box, with its gradient. Implementations must be deterministic.
pub trait Objective: Sync {
    /// Number of coordinates.
    fn dim(&self) -> usize;
    /// Cost at a point of the unit box.
    fn cost(&self, x_unit: &[f64]) -> f64;
    /// Cost and gradient (with respect to unit coordinates) at a point of the unit box.
    fn cost_and_gradient(&self, x_unit: &[f64]) -> (f64, Vec<f64>);
}

/// One point of a search's trace, for convergence plots (the paper's Fig. 8).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TracePoint {
    /// Searcher iteration (DE generation or Adam step), counted across phases.
    pub iteration: usize,
    /// The searcher's phase: `de`, `adam` or `spg` for the built-in searchers; a
    /// searcher of your own names its own.
    pub phase: String,
    /// Best cost so far.
    pub best_cost: f64,
    /// Cost at this iteration (DE: population mean; Adam: current point).
    pub cost: f64,
    /// Gradient norm at this iteration, when the phase computes it.
    pub grad_norm: Option<f64>,
}

/// What a search returns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchOutcome {
    /// The best point found, in the unit box.
    pub best_unit: Vec<f64>,
    /// Its cost.
    pub best_cost: f64,
    /// Objective evaluations (cost or cost-and-gradient calls).
    pub evaluations: usize,
    /// Per-iteration trace.
    pub trace: Vec<TracePoint>,
    /// The deadline ([`Searcher::search_until`]) ended the search before its own stop
    /// rule: `best_unit` is the best point found by then.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub timed_out: bool,
}

impl SearchOutcome {
    /// The outcome, or [`crate::Error::Search`] when the objective was evaluated and
    /// not finite at any point: its best point would be the start, scored infinite, and
    /// a caller would take it for a result. A searcher of your own ends with it, as the
    /// built-in ones do (`searcher` names it in the error).
    pub fn found_finite(self, searcher: &str) -> Result<Self> {
        if self.evaluations > 0 && !self.best_cost.is_finite() {
            return Err(crate::Error::Search(format!(
                "{searcher}: the objective was not finite (NaN or infinite) at any of the {} \
                 points evaluated",
                self.evaluations
            )));
        }
        Ok(self)
    }
}

/// Minimises an objective in the unit box, starting from (or seeded with) `start`.
///
/// Step 2 of the loop; `Calibrator::with_searcher` plugs one in. `start` is the best
/// point the model has run so far: a searcher that proposes a point already run ends
/// the calibration (`converged`). A searcher of your own:
///
/// ```
/// use kalibre_core::{Objective, Result, SearchOutcome, Searcher};
///
/// /// Tries `points + 1` points along the box's diagonal, and the start.
/// struct DiagonalSearch {
///     points: usize,
/// }
///
/// impl Searcher for DiagonalSearch {
///     fn search(&self, objective: &dyn Objective, start: &[f64], _seed: u64) -> Result<SearchOutcome> {
///         let (mut best_unit, mut best_cost) = (start.to_vec(), objective.cost(start));
///         for i in 0..=self.points {
///             let x = vec![i as f64 / self.points as f64; objective.dim()];
///             let cost = objective.cost(&x);
///             if cost < best_cost {
///                 (best_unit, best_cost) = (x, cost);
///             }
///         }
///         let outcome = SearchOutcome {
///             best_unit,
///             best_cost,
///             evaluations: self.points + 2,
///             trace: Vec::new(),
///             timed_out: false,
///         };
///         // An error, not a result, when no cost seen was finite.
///         outcome.found_finite("diagonal search")
///     }
/// }
///
/// /// A bowl with its bottom at (0.3, 0.3).
/// struct Bowl;
///
/// impl Objective for Bowl {
///     fn dim(&self) -> usize {
///         2
///     }
///     fn cost(&self, x: &[f64]) -> f64 {
///         x.iter().map(|v| (v - 0.3).powi(2)).sum()
///     }
///     fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
///         (self.cost(x), x.iter().map(|v| 2.0 * (v - 0.3)).collect())
///     }
/// }
///
/// let found = DiagonalSearch { points: 10 }.search(&Bowl, &[0.9, 0.9], 1)?;
/// assert_eq!(found.best_unit, [0.3, 0.3]);
/// assert!(found.best_cost < 1e-30);
/// # Ok::<(), kalibre_core::Error>(())
/// ```
pub trait Searcher: Sync {
    /// Runs the search. Deterministic for a given `seed`, at any thread count.
    fn search(&self, objective: &dyn Objective, start: &[f64], seed: u64) -> Result<SearchOutcome>;

    /// [`Self::search`] that stops at `deadline`, checked once per generation or step,
    /// with the best point so far and [`SearchOutcome::timed_out`] set; a wall-clock
    /// budget (`Settings::max_wall_s`) reaches inside the search this way. Without a
    /// deadline it is `search`, bit for bit. The default ignores the deadline: a
    /// searcher that can run long should override it.
    fn search_until(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        seed: u64,
        deadline: Option<std::time::Instant>,
    ) -> Result<SearchOutcome> {
        let _ = deadline;
        self.search(objective, start, seed)
    }
}
