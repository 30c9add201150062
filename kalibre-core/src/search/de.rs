//! Differential evolution (rand/1/bin) in the unit box, as an argmin solver.
//!
//! Storn and Price's classic scheme: for every member `x_i`, pick three other distinct
//! members `a, b, c`, form the mutant `a + F (b - c)`, cross it with `x_i` coordinate by
//! coordinate (probability `CR`, and always at one random coordinate), and keep the trial
//! when it costs no more than `x_i`. Generations are synchronous: all trials are built
//! from the previous population with one random stream, then evaluated (in parallel when
//! it pays), so the result does not depend on the thread count.

use std::time::Instant;

use argmin::core::{Executor, Problem, Solver, TerminationReason, TerminationStatus, KV};
use ndarray::Array1;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

use super::kernels::{bounce, crossover, fill_draws, Mutation};
use super::problem::{
    check_start, evaluations, from_argmin, require, timed_out, with_deadline, BoxState,
    UnitBoxProblem, COST_COUNT,
};
use super::{Objective, SearchOutcome, Searcher, TracePoint};
use crate::Result;

/// How a generation's trial vectors are evaluated. The result is bit-identical in every
/// mode: each evaluation is independent and results are collected in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PopulationEval {
    /// One after the other on the calling thread.
    Sequential,
    /// On the current rayon pool.
    Parallel,
    /// Parallel when the initial population took at least [`AUTO_PARALLEL_MIN_EVAL_US`]
    /// microseconds per member and the rayon pool has more than one thread; below that,
    /// waking the pool costs more than it saves.
    #[default]
    Auto,
}

/// Mean evaluation time (microseconds) above which [`PopulationEval::Auto`] goes parallel.
pub const AUTO_PARALLEL_MIN_EVAL_US: f64 = 20.0;

/// Differential evolution settings, checked by [`DifferentialEvolutionBuilder::build`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `population` | 10 | members, the start point being one of them | >= 4 |
/// | `crossover` | 0.6 | CR, probability of taking a mutant coordinate | [0, 1] |
/// | `weight` | 0.8 | F, differential weight | (0, 2] |
/// | `iterations` | 100 | generations after the initial population | >= 1 |
/// | `give_up_after` | none | stop after this many generations if none beat the initial best | >= 1 |
/// | `evaluation` | `Auto` | sequential or parallel trial evaluation | |
///
/// Population, crossover and iterations are the paper's (Table 3); `F = 0.8` is the
/// common choice for rand/1/bin. Crossover draws use 16-bit uniforms (four per 64-bit
/// draw, for speed at thousands of coordinates), so CR acts as a multiple of `2^-16`.
/// Trial coordinates that leave `[0, 1]` are bounced back to a uniform point between the
/// parent coordinate and the violated bound, so every evaluated point is inside the box.
#[derive(Debug, Clone, PartialEq)]
pub struct DifferentialEvolution {
    population: usize,
    crossover: f64,
    weight: f64,
    iterations: usize,
    give_up_after: Option<usize>,
    evaluation: PopulationEval,
}

impl Default for DifferentialEvolution {
    fn default() -> Self {
        DifferentialEvolution {
            population: 10,
            crossover: 0.6,
            weight: 0.8,
            iterations: 100,
            give_up_after: None,
            evaluation: PopulationEval::Auto,
        }
    }
}

/// The largest population a builder accepts: far beyond any useful search (the paper: 10),
/// and a bound on memory, which grows with it before any time limit is looked at.
pub const MAX_POPULATION: usize = 10_000;
/// The most generations a builder accepts (the paper: 100).
pub const MAX_GENERATIONS: usize = 100_000;

/// Unchecked [`DifferentialEvolution`] settings; [`build`](Self::build) checks them.
#[derive(Debug, Clone, PartialEq)]
pub struct DifferentialEvolutionBuilder(DifferentialEvolution);

impl DifferentialEvolutionBuilder {
    /// Population size (>= 4).
    pub fn with_population(mut self, population: usize) -> Self {
        self.0.population = population;
        self
    }
    /// Crossover probability CR in `[0, 1]`.
    pub fn with_crossover(mut self, crossover: f64) -> Self {
        self.0.crossover = crossover;
        self
    }
    /// Differential weight F in `(0, 2]`.
    pub fn with_weight(mut self, weight: f64) -> Self {
        self.0.weight = weight;
        self
    }
    /// Maximum number of generations (>= 1).
    pub fn with_iterations(mut self, iterations: usize) -> Self {
        self.0.iterations = iterations;
        self
    }
    /// Stop after `generations` generations if none of them found a point better than
    /// the initial population's best (`None`: never). This detects a population that cannot
    /// beat its start member, as at thousands of coordinates; a search that has improved
    /// once runs to the end.
    pub fn with_give_up_after(mut self, generations: Option<usize>) -> Self {
        self.0.give_up_after = generations;
        self
    }
    /// How trials are evaluated (does not change the result).
    pub fn with_evaluation(mut self, evaluation: PopulationEval) -> Self {
        self.0.evaluation = evaluation;
        self
    }
    /// Checks the settings; a bad one gives [`crate::Error::InvalidSetting`] naming it.
    pub fn build(self) -> Result<DifferentialEvolution> {
        let s = self.0;
        require(s.population >= 4, "population", || {
            format!(
                "must be at least 4 (a member and three others), got {}",
                s.population
            )
        })?;
        require((0.0..=1.0).contains(&s.crossover), "crossover", || {
            format!("must be in [0, 1], got {}", crate::number(s.crossover))
        })?;
        require(s.weight > 0.0 && s.weight <= 2.0, "weight", || {
            format!("must be in (0, 2], got {}", crate::number(s.weight))
        })?;
        require(s.population <= MAX_POPULATION, "population", || {
            format!("must be at most {MAX_POPULATION}, got {}", s.population)
        })?;
        require(
            (1..=MAX_GENERATIONS).contains(&s.iterations),
            "iterations",
            || format!("must be in 1..={MAX_GENERATIONS}, got {}", s.iterations),
        )?;
        require(s.give_up_after != Some(0), "give_up_after", || {
            "must be at least 1 generation (or none)".into()
        })?;
        Ok(s)
    }
}

impl DifferentialEvolution {
    /// A builder starting from the defaults.
    pub fn builder() -> DifferentialEvolutionBuilder {
        DifferentialEvolutionBuilder(DifferentialEvolution::default())
    }
    /// A builder starting from these settings.
    pub fn to_builder(&self) -> DifferentialEvolutionBuilder {
        DifferentialEvolutionBuilder(self.clone())
    }
    /// Population size.
    pub fn population(&self) -> usize {
        self.population
    }
    /// Crossover probability CR.
    pub fn crossover(&self) -> f64 {
        self.crossover
    }
    /// Differential weight F.
    pub fn weight(&self) -> f64 {
        self.weight
    }
    /// Maximum number of generations.
    pub fn iterations(&self) -> usize {
        self.iterations
    }
    /// Generations after which a search that never beat its initial best stops.
    pub fn give_up_after(&self) -> Option<usize> {
        self.give_up_after
    }
    /// Trial evaluation mode.
    pub fn evaluation(&self) -> PopulationEval {
        self.evaluation
    }

    /// The argmin solver for one run with this seed.
    pub fn solver(&self, seed: u64) -> DeSolver {
        DeSolver {
            settings: self.clone(),
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            dim: 0,
            pop: Vec::new(),
            costs: Vec::new(),
            trials: Vec::new(),
            trial_costs: Vec::new(),
            draws: Vec::new(),
            best: 0,
            improved: false,
            generation: 0,
            parallel: false,
            trace: Vec::new(),
        }
    }
}

impl Searcher for DifferentialEvolution {
    fn search(&self, objective: &dyn Objective, start: &[f64], seed: u64) -> Result<SearchOutcome> {
        self.search_until(objective, start, seed, None)
    }

    fn search_until(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        seed: u64,
        deadline: Option<Instant>,
    ) -> Result<SearchOutcome> {
        check_start(objective, start)?;
        let iterations = self.iterations as u64;
        let executor = Executor::new(UnitBoxProblem::new(objective), self.solver(seed))
            .configure(|state| {
                state
                    .param(Array1::from(start.to_vec()))
                    .max_iters(iterations)
            })
            .ctrlc(false);
        let result = with_deadline(executor, deadline)
            .run()
            .map_err(from_argmin)?;
        let timed_out = timed_out(&result.state);
        let solver = result.solver;
        let (best_unit, best_cost) = solver.best();
        SearchOutcome {
            best_unit: best_unit.to_vec(),
            best_cost,
            evaluations: evaluations(&result.problem),
            trace: solver.trace,
            timed_out,
        }
        .found_finite("differential evolution")
    }
}

/// The running differential evolution: population, random stream and trace.
/// Made by [`DifferentialEvolution::solver`]; the start point is the state's parameter.
pub struct DeSolver {
    settings: DifferentialEvolution,
    rng: Xoshiro256PlusPlus,
    dim: usize,
    /// Members; trials are swapped in, not copied.
    pop: Vec<Vec<f64>>,
    costs: Vec<f64>,
    trials: Vec<Vec<f64>>,
    trial_costs: Vec<f64>,
    /// Crossover draws of one trial (length rounded up to a multiple of 4).
    draws: Vec<u16>,
    best: usize,
    /// Whether any generation beat the initial population's best.
    improved: bool,
    generation: usize,
    parallel: bool,
    trace: Vec<TracePoint>,
}

impl DeSolver {
    /// The best member and its cost (the first of equal ones).
    pub fn best(&self) -> (&[f64], f64) {
        (&self.pop[self.best], self.costs[self.best])
    }

    /// One trace point per generation (the initial population is generation 0).
    pub fn trace(&self) -> &[TracePoint] {
        &self.trace
    }

    fn argbest(costs: &[f64]) -> usize {
        let mut best = 0;
        for (i, &c) in costs.iter().enumerate() {
            if c < costs[best] {
                best = i;
            }
        }
        best
    }

    fn record(&mut self) -> f64 {
        // Mean over members with a finite cost (a plot cannot show +inf); +inf if none.
        let (sum, n) = self
            .costs
            .iter()
            .filter(|c| c.is_finite())
            .fold((0.0, 0usize), |(s, n), c| (s + c, n + 1));
        let mean = if n > 0 { sum / n as f64 } else { f64::INFINITY };
        self.trace.push(TracePoint {
            iteration: self.trace.len(),
            phase: "de".into(),
            best_cost: self.costs[self.best],
            cost: mean,
            grad_norm: None,
        });
        mean
    }

    /// Builds trial `i` into `out` from the current population.
    fn build_trial(&mut self, i: usize, threshold: u32, out: &mut [f64]) {
        let (n, d) = (self.settings.population, self.dim);
        let f = self.settings.weight;
        let pick = |rng: &mut Xoshiro256PlusPlus, taken: &[usize]| loop {
            let r = rng.random_range(0..n);
            if !taken.contains(&r) {
                return r;
            }
        };
        let r1 = pick(&mut self.rng, &[i]);
        let r2 = pick(&mut self.rng, &[i, r1]);
        let r3 = pick(&mut self.rng, &[i, r1, r2]);
        let jrand = self.rng.random_range(0..d);
        let row = |k: usize| self.pop[k].as_slice();
        let (x, a, b, c) = (row(i), row(r1), row(r2), row(r3));

        // Binomial crossover with 16-bit uniforms.
        fill_draws(&mut self.rng, &mut self.draws);
        let mutation = Mutation {
            parent: x,
            a,
            b,
            c,
            weight: f,
        };
        crossover(out, &mutation, &self.draws, threshold);
        // The coordinate always taken from the mutant, repaired with its own uniform.
        let m = a[jrand] + f * (b[jrand] - c[jrand]);
        out[jrand] = bounce(m, x[jrand], self.rng.random::<f64>());
    }

    fn evaluate(
        problem: &mut Problem<UnitBoxProblem<'_>>,
        points: &[Vec<f64>],
        parallel: bool,
        out: &mut Vec<f64>,
    ) -> std::result::Result<(), argmin::core::Error> {
        problem.bulk_problem(COST_COUNT, points.len(), |p| {
            if parallel {
                points
                    .par_iter()
                    .map(|x| p.finite_cost(x))
                    .collect_into_vec(out);
            } else {
                out.clear();
                out.extend(points.iter().map(|x| p.finite_cost(x)));
            }
            Ok(())
        })
    }
}

impl Solver<UnitBoxProblem<'_>, BoxState> for DeSolver {
    fn name(&self) -> &str {
        "differential evolution (rand/1/bin)"
    }

    fn init(
        &mut self,
        problem: &mut Problem<UnitBoxProblem<'_>>,
        mut state: BoxState,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let start = state.take_param().ok_or_else(|| {
            argmin::core::Error::msg("differential evolution needs a start point")
        })?;
        let (n, d) = (self.settings.population, start.len());
        self.dim = d;
        self.pop = Vec::with_capacity(n);
        self.pop.push(start.to_vec());
        for _ in 1..n {
            let member = (0..d).map(|_| self.rng.random::<f64>()).collect();
            self.pop.push(member);
        }
        self.trials = vec![vec![0.0; d]; n];
        self.draws = vec![0; d.div_ceil(4) * 4];

        let clock = Instant::now();
        let parallel = self.settings.evaluation == PopulationEval::Parallel;
        Self::evaluate(problem, &self.pop, parallel, &mut self.costs)?;
        let per_eval_us = clock.elapsed().as_secs_f64() * 1e6 / n as f64;
        self.parallel = match self.settings.evaluation {
            PopulationEval::Sequential => false,
            PopulationEval::Parallel => true,
            PopulationEval::Auto => {
                per_eval_us >= AUTO_PARALLEL_MIN_EVAL_US && rayon::current_num_threads() > 1
            }
        };

        self.best = Self::argbest(&self.costs);
        let mean = self.record();
        let (best, cost) = self.best();
        let best = Array1::from(best.to_vec());
        Ok((
            state.param(best).cost(cost),
            Some(argmin::kv!("mean_cost" => mean;)),
        ))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<UnitBoxProblem<'_>>,
        state: BoxState,
    ) -> std::result::Result<(BoxState, Option<KV>), argmin::core::Error> {
        let n = self.settings.population;
        // CR on a 16-bit grid; CR = 1 gives 65536, above every draw.
        let threshold = (self.settings.crossover * 65536.0).round() as u32;
        let mut trials = std::mem::take(&mut self.trials);
        for (i, out) in trials.iter_mut().enumerate() {
            self.build_trial(i, threshold, out);
        }
        let mut trial_costs = std::mem::take(&mut self.trial_costs);
        Self::evaluate(problem, &trials, self.parallel, &mut trial_costs)?;

        let old_best_cost = self.costs[self.best];
        for i in 0..n {
            // `<=` lets the population drift across plateaus, as in classic DE.
            if trial_costs[i] <= self.costs[i] {
                std::mem::swap(&mut self.pop[i], &mut trials[i]);
                self.costs[i] = trial_costs[i];
            }
        }
        self.trials = trials;
        self.trial_costs = trial_costs;

        let old_best = self.best;
        self.best = Self::argbest(&self.costs);
        let best_cost = self.costs[self.best];
        self.improved |= best_cost < old_best_cost;
        self.generation += 1;
        let mean = self.record();
        let kv = argmin::kv!("mean_cost" => mean;);
        // The state holds the population's best; copy it only when it changed (moved to
        // another member, or its member took a trial: then the trial's cost equals it).
        let replaced = self.trial_costs[self.best] == best_cost;
        let state = if self.best != old_best || replaced {
            state.param(Array1::from(self.best().0.to_vec()))
        } else {
            state
        };
        Ok((state.cost(best_cost), Some(kv)))
    }

    fn terminate(&mut self, _state: &BoxState) -> TerminationStatus {
        match self.settings.give_up_after {
            Some(g) if !self.improved && self.generation >= g => {
                TerminationStatus::Terminated(TerminationReason::SolverExit(format!(
                    "no generation of {g} beat the initial best"
                )))
            }
            _ => TerminationStatus::NotTerminated,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use argmin::core::State;

    struct Slow(u64);
    impl Objective for Slow {
        fn dim(&self) -> usize {
            2
        }
        fn cost(&self, x: &[f64]) -> f64 {
            std::thread::sleep(std::time::Duration::from_micros(self.0));
            x[0] * x[0] + x[1]
        }
        fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
            (self.cost(x), vec![2.0 * x[0], 1.0])
        }
    }

    fn run_init(objective: &dyn Objective, evaluation: PopulationEval) -> DeSolver {
        let de = DifferentialEvolution::builder()
            .with_evaluation(evaluation)
            .build()
            .unwrap();
        let mut problem = Problem::new(UnitBoxProblem::new(objective));
        let mut solver = de.solver(1);
        let state = BoxState::new().param(Array1::from(vec![0.5, 0.5]));
        solver.init(&mut problem, state).unwrap();
        solver
    }

    #[test]
    fn auto_goes_parallel_only_for_slow_objectives_on_several_threads() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        pool.install(|| {
            assert!(!run_init(&Slow(0), PopulationEval::Auto).parallel);
            assert!(run_init(&Slow(100), PopulationEval::Auto).parallel);
            assert!(!run_init(&Slow(100), PopulationEval::Sequential).parallel);
            assert!(run_init(&Slow(0), PopulationEval::Parallel).parallel);
        });
        let single = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        single.install(|| assert!(!run_init(&Slow(100), PopulationEval::Auto).parallel));
    }

    #[test]
    fn start_is_a_member_and_the_rest_are_in_the_box() {
        let s = run_init(&Slow(0), PopulationEval::Sequential);
        assert_eq!(s.pop.len(), 10);
        assert_eq!(s.pop[0], vec![0.5, 0.5]);
        assert!(s.pop[1..].iter().flatten().all(|v| (0.0..1.0).contains(v)));
        assert_eq!(s.trace.len(), 1);
        assert_eq!(s.trace[0].phase, "de");
    }
}
