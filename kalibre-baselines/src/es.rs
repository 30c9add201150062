//! The paper's "heuristic" baseline: a (1+1) evolution strategy over the model itself,
//! with Rechenberg's 1/5 success rule, as an argmin solver.
//!
//! Every iteration mutates the parent with isotropic Gaussian noise in the unit box,
//! runs the model at the child (one run per snapshot) and keeps the child when its MAE
//! is lower. Coordinates that leave `[0, 1]` are folded back by reflection, so the
//! model never sees a value out of bounds and mutations do not pile up on a bound.
//!
//! # The step size
//!
//! The paper sets `sigma = 5` without saying in which units. It cannot be cfm/W (the
//! alpha bounds are `[0.01, 3]`), nor the unit box (a standard deviation of five box
//! widths, reflected, is a uniform random draw: the search would be random sampling
//! until the 1/5 rule had shrunk sigma by a factor of 25, about 40 failures later). We
//! read it as "a broad first step" and take `sigma0 = 0.2` of each coordinate's range in
//! the unit box (alpha is on a log scale: one sigma is a factor of about 3 in alpha);
//! the 1/5 rule then adapts it. `with_sigma0(5.0)` runs the literal reading.
//!
//! # The 1/5 rule
//!
//! Per iteration (Kern et al. 2004): sigma grows by `expand` after a success and shrinks
//! by `expand^(-1/4)` after a failure, so it is stationary at a success rate of 1/5.

use std::time::Instant;

use argmin::core::{
    CostFunction, Executor, Problem, Solver, State, TerminationReason, TerminationStatus, KV,
};
use kalibre_core::search::BoxState;
use kalibre_core::{Model, Observations, ParamSpace, RunStore};
use ndarray::Array1;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::error::require;
use crate::runner::{BaselineReport, HistoryPoint, ModelMae};
use crate::Result;

/// The largest initial mutation standard deviation taken (unit box).
pub const MAX_SIGMA0: f64 = 1000.0;

/// Settings of the (1+1)-ES, checked by [`OnePlusOneEs::check`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `seed` | 0 | seeds the mutations | any |
/// | `sigma0` | 0.2 | initial mutation standard deviation, unit box (see the module docs) | (0, 1000] |
/// | `expand` | 1.5 | sigma factor after a success (failure: `expand^(-1/4)`) | > 1 |
/// | `min_sigma` | 1e-3 | sigma never falls below this | (0, sigma0] |
/// | `max_iterations` | 150 | mutations (each one model run per snapshot) | >= 1 |
/// | `target_mae_c` | none | stop once the best MAE is at most this | >= 0 |
#[derive(Debug, Clone, PartialEq)]
pub struct OnePlusOneEs {
    seed: u64,
    sigma0: f64,
    expand: f64,
    min_sigma: f64,
    max_iterations: usize,
    target_mae_c: Option<f64>,
}

impl Default for OnePlusOneEs {
    fn default() -> Self {
        OnePlusOneEs {
            seed: 0,
            sigma0: 0.2,
            expand: 1.5,
            min_sigma: 1e-3,
            max_iterations: 150,
            target_mae_c: None,
        }
    }
}

impl OnePlusOneEs {
    /// Seed of the mutations.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Initial mutation standard deviation in the unit box.
    pub fn with_sigma0(mut self, sigma0: f64) -> Self {
        self.sigma0 = sigma0;
        self
    }
    /// Sigma factor after a success.
    pub fn with_expand(mut self, expand: f64) -> Self {
        self.expand = expand;
        self
    }
    /// Lower limit of sigma.
    pub fn with_min_sigma(mut self, min_sigma: f64) -> Self {
        self.min_sigma = min_sigma;
        self
    }
    /// Number of mutations.
    pub fn with_max_iterations(mut self, n: usize) -> Self {
        self.max_iterations = n;
        self
    }
    /// Stop once the best MAE is at most this.
    pub fn with_target_mae_c(mut self, target: f64) -> Self {
        self.target_mae_c = Some(target);
        self
    }
    /// The seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }
    /// Number of mutations.
    pub fn max_iterations(&self) -> usize {
        self.max_iterations
    }

    /// Checks every setting, naming the first one out of range.
    pub fn check(&self) -> Result<()> {
        // Past a few box widths a mutation is already uniform after reflection (the
        // literal sigma 5 is); far past it, the step overflows to a NaN coordinate.
        require(
            self.sigma0 > 0.0 && self.sigma0 <= MAX_SIGMA0,
            "sigma0",
            || format!("must be in (0, {MAX_SIGMA0}], got {}", self.sigma0),
        )?;
        require(
            self.expand.is_finite() && self.expand > 1.0,
            "expand",
            || format!("must be finite and > 1, got {}", self.expand),
        )?;
        require(
            self.min_sigma > 0.0 && self.min_sigma <= self.sigma0,
            "min_sigma",
            || format!("must be in (0, sigma0], got {}", self.min_sigma),
        )?;
        require(self.max_iterations >= 1, "max_iterations", || {
            "must be at least 1".into()
        })?;
        if let Some(t) = self.target_mae_c {
            require(t.is_finite() && t >= 0.0, "target_mae_c", || {
                format!("must be finite and >= 0, got {t}")
            })?;
        }
        Ok(())
    }

    /// The argmin solver; `runs_per_point` scales the history's model-run counts (the
    /// number of snapshots one cost evaluation runs).
    pub fn solver(&self, runs_per_point: usize) -> EsSolver {
        EsSolver {
            settings: self.clone(),
            rng: Xoshiro256PlusPlus::seed_from_u64(self.seed),
            sigma: self.sigma0,
            parent: Vec::new(),
            parent_cost: f64::INFINITY,
            runs_per_point,
            evaluations: 0,
            history: Vec::new(),
        }
    }
}

/// The running (1+1)-ES over any cost on the unit box. Made by [`OnePlusOneEs::solver`].
pub struct EsSolver {
    settings: OnePlusOneEs,
    rng: Xoshiro256PlusPlus,
    sigma: f64,
    parent: Vec<f64>,
    parent_cost: f64,
    runs_per_point: usize,
    evaluations: usize,
    history: Vec<HistoryPoint>,
}

impl EsSolver {
    /// One point per evaluation (the start point is iteration 0).
    pub fn history(&self) -> &[HistoryPoint] {
        &self.history
    }
    /// The current mutation standard deviation (unit box).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    fn evaluate<P>(
        &mut self,
        problem: &mut Problem<P>,
        x: &Array1<f64>,
    ) -> std::result::Result<f64, argmin::core::Error>
    where
        P: CostFunction<Param = Array1<f64>, Output = f64>,
    {
        let c = problem.cost(x)?;
        let c = if c.is_finite() { c } else { f64::INFINITY };
        self.evaluations += 1;
        let best = self.parent_cost.min(c);
        self.history.push(HistoryPoint {
            iteration: self.evaluations - 1,
            model_runs: self.evaluations * self.runs_per_point,
            mae_c: c,
            best_mae_c: best,
        });
        Ok(c)
    }
}

/// Folds `u` back into `[0, 1]` by reflection at the bounds (any distance out). A
/// non-finite `u` has no reflection and gives NaN (the ES's steps are finite: sigma is
/// capped).
pub fn reflect_unit(u: f64) -> f64 {
    let r = u.rem_euclid(2.0);
    let v = if r > 1.0 { 2.0 - r } else { r };
    v.clamp(0.0, 1.0)
}

impl<P> Solver<P, BoxState> for EsSolver
where
    P: CostFunction<Param = Array1<f64>, Output = f64>,
{
    fn name(&self) -> &str {
        "(1+1)-ES with the 1/5 success rule"
    }

    fn init(
        &mut self,
        problem: &mut Problem<P>,
        mut state: BoxState,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let x = state
            .take_param()
            .ok_or_else(|| argmin::core::Error::msg("the ES needs a start point"))?;
        if let Some(v) = x.iter().find(|v| !(0.0..=1.0).contains(*v)) {
            return Err(argmin::core::Error::msg(format!(
                "start coordinate {v} is outside the unit box"
            )));
        }
        let c = self.evaluate(problem, &x)?;
        self.parent = x.to_vec();
        self.parent_cost = c;
        Ok((state.param(x).cost(c), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<P>,
        state: BoxState,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let child: Array1<f64> = self
            .parent
            .iter()
            .map(|&p| {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                reflect_unit(p + self.sigma * z)
            })
            .collect();
        let c = self.evaluate(problem, &child)?;
        let success = c < self.parent_cost;
        if success {
            self.parent = child.to_vec();
            self.parent_cost = c;
            self.sigma *= self.settings.expand;
        } else {
            self.sigma *= self.settings.expand.powf(-0.25);
        }
        // Growth beyond a box width (or sigma0 when it is larger) only randomises further.
        self.sigma = self
            .sigma
            .clamp(self.settings.min_sigma, self.settings.sigma0.max(1.0));
        let kv = argmin::kv!("sigma" => self.sigma; "success" => success;);
        Ok((state.param(child).cost(c), Some(kv)))
    }

    fn terminate(&mut self, state: &BoxState) -> TerminationStatus {
        match self.settings.target_mae_c {
            Some(t) if state.get_best_cost() <= t => {
                TerminationStatus::Terminated(TerminationReason::TargetCostReached)
            }
            _ => TerminationStatus::NotTerminated,
        }
    }
}

/// The model's MAE over the unit box as an argmin cost (one run per snapshot).
struct UnitMae<'r, 'a, M: Model> {
    mae: &'r ModelMae<'a, M>,
    /// The start point in the unit box and in physical values: the start runs at the
    /// exact initial values (a unit-box round trip can move them by an ulp).
    start: (Vec<f64>, Vec<f64>),
}

impl<M: Model> CostFunction for UnitMae<'_, '_, M> {
    type Param = Array1<f64>;
    type Output = f64;

    fn cost(&self, u: &Array1<f64>) -> std::result::Result<f64, argmin::core::Error> {
        let u = u.to_vec();
        let x = if u == self.start.0 {
            self.start.1.clone()
        } else {
            self.mae
                .space()
                .from_unit(&u)
                .map_err(argmin::core::Error::new)?
        };
        Ok(self.mae.run(&x).map_err(argmin::core::Error::new)?.mae_c)
    }
}

/// Runs the (1+1)-ES on the model from the space's initial values, journaling every run
/// in `store` when given (journaled runs are replayed, not repeated).
pub fn run_es<M: Model>(
    model: &M,
    observations: &Observations<M::Scenario>,
    space: &ParamSpace,
    settings: &OnePlusOneEs,
    store: Option<&RunStore>,
) -> Result<BaselineReport> {
    settings.check()?;
    let t0 = Instant::now();
    let mae = ModelMae::new(model, observations, space, store)?;
    let start = space.to_unit(&space.initial())?;
    let cost_start = start.clone();
    let solver = settings.solver(mae.runs_per_point());
    let cost = UnitMae {
        mae: &mae,
        start: (start.clone(), space.initial()),
    };
    let result = Executor::new(cost, solver)
        .configure(|s| {
            s.param(Array1::from(start))
                .max_iters(settings.max_iterations as u64)
        })
        .ctrlc(false)
        .run()
        .map_err(|e| kalibre_core::Error::Argmin(format!("{e:#}")))?;
    let history = result.solver.history;
    let runs = history.last().map_or(0, |h| h.model_runs);
    if !result.state.get_best_cost().is_finite() {
        // Every point failed at some snapshot: there is no best point to report.
        return Err(kalibre_core::Error::NoSuccessfulRun(format!(
            "no parameter point ran successfully at every snapshot in {runs} model runs of \
             the (1+1)-ES (each failed run's reason is in the run journal, when one is kept)"
        ))
        .into());
    }
    let best_unit = result
        .state
        .get_best_param()
        .map(|p| p.to_vec())
        .ok_or_else(|| crate::Error::Mismatch("the ES evaluated no point".into()))?;
    let best_params = if best_unit == cost_start {
        space.initial()
    } else {
        space.from_unit(&best_unit)?
    };
    Ok(BaselineReport {
        method: "one_plus_one_es".into(),
        param_names: space.names(),
        best_params,
        best_mae_c: result.state.get_best_cost(),
        initial_mae_c: history.first().map_or(f64::INFINITY, |h| h.mae_c),
        model_runs: runs,
        history,
        wall_s: t0.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflection_folds_any_distance_into_the_box() {
        assert_eq!(reflect_unit(0.3), 0.3);
        assert!((reflect_unit(1.2) - 0.8).abs() < 1e-12);
        assert!((reflect_unit(-0.25) - 0.25).abs() < 1e-12);
        assert!((reflect_unit(2.3) - 0.3).abs() < 1e-12);
        assert!((reflect_unit(-7.6) - 0.4).abs() < 1e-12);
        assert!(reflect_unit(f64::NAN).is_nan() && reflect_unit(f64::INFINITY).is_nan());
    }

    #[test]
    fn bad_settings_are_named() {
        let e = OnePlusOneEs::default()
            .with_sigma0(0.0)
            .check()
            .unwrap_err();
        assert!(e.to_string().contains("sigma0"));
        let e = OnePlusOneEs::default()
            .with_sigma0(f64::MAX)
            .check()
            .unwrap_err();
        assert!(e.to_string().contains("sigma0"), "{e}");
        OnePlusOneEs::default()
            .with_sigma0(5.0)
            .check()
            .expect("the literal sigma");
        let e = OnePlusOneEs::default()
            .with_expand(1.0)
            .check()
            .unwrap_err();
        assert!(e.to_string().contains("expand"));
    }
}
