//! The searchers (step 2 of the loop) on standard functions in the unit box: bounds,
//! optima, gradients, determinism, non-finite objectives and settings.

mod search_support;

use kalibre_core::search::{
    Adam, DifferentialEvolution, Hybrid, PopulationEval, ProjectedGradient,
};
use kalibre_core::{Error, Objective, SearchOutcome, Searcher};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use search_support::*;

fn de_small() -> DifferentialEvolution {
    DifferentialEvolution::builder()
        .with_population(5)
        .with_iterations(15)
        .build()
        .unwrap()
}

fn adam_small(lr: f64) -> Adam {
    Adam::builder()
        .with_learning_rate(lr)
        .with_steps(25)
        .build()
        .unwrap()
}

fn bits(o: &SearchOutcome) -> Vec<u64> {
    let mut v: Vec<u64> = o.best_unit.iter().map(|x| x.to_bits()).collect();
    v.push(o.best_cost.to_bits());
    v.push(o.evaluations as u64);
    for t in &o.trace {
        v.extend([
            t.iteration as u64,
            t.best_cost.to_bits(),
            t.cost.to_bits(),
            t.grad_norm.map_or(u64::MAX, f64::to_bits),
        ]);
    }
    v
}

// ---------------------------------------------------------------- gradients

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 48,
        rng_seed: RngSeed::Fixed(48),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Every hand-written gradient of the test functions against central differences.
    #[test]
    fn test_function_gradients_match_finite_differences(
        u in prop::collection::vec(0.02f64..0.98, 1..6),
        s in prop::collection::vec(-3.0f64..3.0, 6),
    ) {
        let d = u.len();
        let shift: Vec<f64> = s[..d].to_vec();
        let functions: Vec<(&str, Box<dyn Objective>)> = vec![
            ("sphere", Box::new(Sphere { centre: shift.iter().map(|v| v / 3.0).collect() })),
            ("rosenbrock", Box::new(Rosenbrock { dim: d })),
            ("ackley", Box::new(ShiftedAckley { shift: shift.clone() })),
            ("rastrigin", Box::new(ShiftedRastrigin { shift })),
        ];
        for (name, f) in &functions {
            let (c, g) = f.cost_and_gradient(&u);
            prop_assert!((c - f.cost(&u)).abs() <= 1e-12 * c.abs().max(1.0), "{name} cost");
            let fd = fd_gradient(f.as_ref(), &u, 1e-6);
            for (i, (a, b)) in g.iter().zip(&fd).enumerate() {
                prop_assert!(
                    (a - b).abs() <= 1e-5 * a.abs().max(1.0),
                    "{name} d{i}: analytic {a}, finite difference {b}"
                );
            }
        }
    }
}

// ---------------------------------------------------------------- bounds

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 24,
        rng_seed: RngSeed::Fixed(24),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Whatever the objective pulls towards (an optimum inside, outside or far outside
    /// the box), every searcher evaluates only points of the unit box, counts each
    /// evaluation, and returns a point of the box.
    #[test]
    fn every_searcher_evaluates_and_returns_only_points_in_the_box(
        centre in prop::collection::vec(-4.0f64..5.0, 1..6),
        start_raw in prop::collection::vec(0.0f64..=1.0, 6),
        seed in any::<u64>(),
        lr in 0.05f64..0.8,
        multimodal in any::<bool>(),
    ) {
        let d = centre.len();
        let start = &start_raw[..d];
        let objective: Box<dyn Objective> = if multimodal {
            Box::new(ShiftedRastrigin { shift: centre.clone() })
        } else {
            Box::new(Sphere { centre })
        };
        let searchers: Vec<(&str, Box<dyn Searcher>)> = vec![
            ("de", Box::new(de_small())),
            ("adam", Box::new(adam_small(lr))),
            ("hybrid", Box::new(Hybrid::new(de_small(), adam_small(lr)))),
        ];
        for (name, searcher) in &searchers {
            let watch = BoxWatch::new(objective.as_ref());
            let out = searcher.search(&watch, start, seed).unwrap();
            prop_assert!(!watch.left_box(), "{name} evaluated a point outside the box");
            prop_assert_eq!(out.evaluations, watch.evaluations(), "{} evaluation count", name);
            prop_assert_eq!(out.best_unit.len(), d);
            prop_assert!(out.best_unit.iter().all(|v| (0.0..=1.0).contains(v)), "{name}");
            prop_assert_eq!(out.best_cost.to_bits(), objective.cost(&out.best_unit).to_bits());
            // The start point is evaluated, so the best is never worse than it.
            prop_assert!(out.best_cost <= objective.cost(start), "{name}");
        }
    }
}

// ---------------------------------------------------------------- optima

const SEEDS: [u64; 3] = [1, 2, 3];
/// Tolerance on every unit coordinate of the returned point.
const TOL: f64 = 1e-3;

fn assert_finds(
    name: &str,
    searcher: &dyn Searcher,
    f: &dyn Objective,
    start: &[f64],
    optimum: &[f64],
) {
    for seed in SEEDS {
        let out = searcher.search(f, start, seed).unwrap();
        let err = max_abs_diff(&out.best_unit, optimum);
        assert!(
            err <= TOL,
            "{name}, seed {seed}: {:?} is {err:e} from the optimum {optimum:?} (cost {})",
            out.best_unit,
            out.best_cost
        );
    }
}

/// Adam settings for the long narrow Rosenbrock valley: a slower rate over 1,000 steps.
fn adam_valley() -> Adam {
    Adam::builder()
        .with_learning_rate(0.05)
        .with_decay_every(100)
        .with_steps(1000)
        .build()
        .unwrap()
}

#[test]
fn sphere_optimum_off_centre_found_by_every_searcher_with_defaults() {
    let f = Sphere {
        centre: vec![0.15, 0.35, 0.6, 0.85],
    };
    let start = [0.5; 4];
    assert_finds(
        "de",
        &DifferentialEvolution::default(),
        &f,
        &start,
        &f.centre,
    );
    assert_finds("adam", &Adam::default(), &f, &start, &f.centre);
    assert_finds("hybrid", &Hybrid::default(), &f, &start, &f.centre);
}

#[test]
fn rosenbrock_optimum_found() {
    let f = Rosenbrock { dim: 2 };
    let start = [0.5; 2];
    // Population 10 and 100 generations (1,010 evaluations) stop short in the valley
    // (about 0.13 away); 20 x 200 gets there.
    let de = DifferentialEvolution::builder()
        .with_population(20)
        .with_iterations(200)
        .build()
        .unwrap();
    assert_finds("de", &de, &f, &start, &f.optimum());
    assert_finds("adam", &adam_valley(), &f, &start, &f.optimum());
    let hybrid = Hybrid::default().with_adam(adam_valley());
    assert_finds("hybrid", &hybrid, &f, &start, &f.optimum());
}

#[test]
fn shifted_multimodal_optima_found() {
    // Global optima away from the box centre, among many local minima.
    let ackley = ShiftedAckley {
        shift: vec![1.3, -2.1],
    };
    let rastrigin = ShiftedRastrigin {
        shift: vec![1.3, -2.1],
    };
    let centre = [0.5; 2];
    for (name, f, opt) in [
        ("ackley", &ackley as &dyn Objective, ackley.optimum()),
        ("rastrigin", &rastrigin, rastrigin.optimum()),
    ] {
        assert_finds(
            &format!("de {name}"),
            &DifferentialEvolution::default(),
            f,
            &centre,
            &opt,
        );
        assert_finds(
            &format!("hybrid {name}"),
            &Hybrid::default(),
            f,
            &centre,
            &opt,
        );
        // Adam is a local method: it starts in the global basin's neighbourhood (0.04 off
        // in unit coordinates: 0.4 in x), with a rate that does not jump out of it.
        let near: Vec<f64> = opt.iter().map(|u| u + 0.04).collect();
        let adam = Adam::builder()
            .with_learning_rate(0.05)
            .with_decay_every(20)
            .with_steps(200)
            .build()
            .unwrap();
        assert_finds(&format!("adam {name}"), &adam, f, &near, &opt);
    }
}

#[test]
fn at_thousands_of_coordinates_de_hands_over_and_adam_does_the_work() {
    let d = 2240;
    let f = Sphere {
        centre: (0..d)
            .map(|i| 0.2 + 0.6 * ((i as f64) * 0.618).fract())
            .collect(),
    };
    let start = vec![0.5; d];
    let start_cost = f.cost(&start);
    let out = Hybrid::default().search(&f, &start, 9).unwrap();
    let de: Vec<_> = out.trace.iter().filter(|t| t.phase == "de").collect();
    let adam: Vec<_> = out.trace.iter().filter(|t| t.phase == "adam").collect();
    // The initial population and 20 generations, none better than the start point.
    assert_eq!(de.len(), 21);
    assert_eq!(de.last().unwrap().best_cost, start_cost);
    assert_eq!(adam.len(), 101);
    // Then the local phase from Adam's best: its start, then one entry per accepted
    // step, each after at least one line-search cost and one gradient.
    let spg: Vec<_> = out.trace.iter().filter(|t| t.phase == "spg").collect();
    assert!(!spg.is_empty());
    assert!(spg.last().unwrap().best_cost <= adam.last().unwrap().best_cost);
    assert!(out.evaluations >= 10 + 20 * 10 + 101 + 2 * spg.len() - 1);
    assert!(
        out.best_cost < 0.01 * start_cost,
        "Adam reached {} from {start_cost}",
        out.best_cost
    );
}

// ---------------------------------------------------------------- trace

#[test]
fn hybrid_trace_runs_de_then_adam_then_local_with_monotone_best() {
    let f = ShiftedAckley {
        shift: vec![0.7, -1.2, 2.0],
    };
    let out = Hybrid::default().search(&f, &[0.5; 3], 4).unwrap();
    let phases: Vec<&str> = out.trace.iter().map(|t| t.phase.as_str()).collect();
    let split = phases.iter().position(|p| *p == "adam").unwrap();
    assert!(phases[..split].iter().all(|p| *p == "de") && split > 1);
    let local = split + 101;
    assert!(phases[split..local].iter().all(|p| *p == "adam"));
    assert!(phases[local..].iter().all(|p| *p == "spg") && phases.len() > local);
    for (i, w) in out.trace.windows(2).enumerate() {
        assert_eq!(w[1].iteration, w[0].iteration + 1);
        assert!(w[1].best_cost <= w[0].best_cost, "best rose at {i}");
    }
    assert!(out.trace[..split].iter().all(|t| t.grad_norm.is_none()));
    assert!(out.trace[split..].iter().all(|t| t.grad_norm.is_some()));
    assert_eq!(out.trace.last().unwrap().best_cost, out.best_cost);
    // DE population mean is never below its best.
    assert!(out.trace[..split].iter().all(|t| t.cost >= t.best_cost));
    // DE's generations, Adam's steps, then at least the local phase's start gradient.
    assert!(out.evaluations > 10 * split + 101);
}

// ---------------------------------------------------------------- determinism

#[test]
fn same_seed_gives_bit_identical_outcomes_at_one_and_two_threads() {
    let f = ShiftedRastrigin {
        shift: vec![1.1, -0.4, 2.3, 0.2],
    };
    let start = [0.3, 0.6, 0.5, 0.9];
    let parallel = DifferentialEvolution::builder()
        .with_evaluation(PopulationEval::Parallel)
        .build()
        .unwrap();
    let sequential = parallel
        .to_builder()
        .with_evaluation(PopulationEval::Sequential)
        .build()
        .unwrap();
    let searchers: Vec<(&str, Box<dyn Searcher>)> = vec![
        ("hybrid", Box::new(Hybrid::default())),
        ("de parallel", Box::new(parallel.clone())),
        (
            "hybrid parallel",
            Box::new(Hybrid::default().with_de(parallel)),
        ),
        ("adam", Box::new(Adam::default())),
    ];
    let reference = Hybrid::default()
        .with_de(sequential)
        .search(&f, &start, 11)
        .unwrap();
    for (name, s) in &searchers {
        let runs: Vec<Vec<u64>> = [1, 2, 2, 1]
            .iter()
            .map(|&n| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .unwrap();
                pool.install(|| bits(&s.search(&f, &start, 11).unwrap()))
            })
            .collect();
        assert!(
            runs.windows(2).all(|w| w[0] == w[1]),
            "{name} differs across runs"
        );
        if name.starts_with("hybrid") {
            assert_eq!(runs[0], bits(&reference), "{name} differs from sequential");
        }
    }
    // The seed matters: another one gives another population.
    let other = Hybrid::default().search(&f, &start, 12).unwrap();
    assert_ne!(bits(&other), bits(&reference));
}

// ---------------------------------------------------------------- non-finite objectives

/// A sphere around (0.5, 0.5) that is NaN for `u0 > 0.7`, -inf for `u1 < 0.2` and +inf
/// for `u0 < 0.1`: none of those may be taken as the best.
struct Holes;

impl Objective for Holes {
    fn dim(&self) -> usize {
        2
    }
    fn cost(&self, u: &[f64]) -> f64 {
        self.cost_and_gradient(u).0
    }
    fn cost_and_gradient(&self, u: &[f64]) -> (f64, Vec<f64>) {
        let bad = if u[0] > 0.7 {
            f64::NAN
        } else if u[1] < 0.2 {
            f64::NEG_INFINITY
        } else if u[0] < 0.1 {
            f64::INFINITY
        } else {
            let s = Sphere {
                centre: vec![0.5, 0.5],
            };
            return s.cost_and_gradient(u);
        };
        (bad, vec![bad; 2])
    }
}

#[test]
fn non_finite_costs_never_win_and_do_not_stop_the_search() {
    let optimum = [0.5, 0.5];
    for start in [[0.3, 0.8], [0.9, 0.9], [0.5, 0.05]] {
        let hybrid = Hybrid::default().search(&Holes, &start, 5).unwrap();
        assert!(
            max_abs_diff(&hybrid.best_unit, &optimum) <= TOL,
            "hybrid from {start:?}"
        );
        let de = DifferentialEvolution::default()
            .search(&Holes, &start, 5)
            .unwrap();
        assert!(
            max_abs_diff(&de.best_unit, &optimum) <= TOL,
            "de from {start:?}"
        );
        assert!(hybrid.trace.iter().all(|t| t.best_cost >= 0.0));
    }
    // Adam from a finite start walks into the NaN region (a large step towards u0 > 0.7
    // is possible) and back; from a non-finite start it has nothing to go on and stops.
    let adam = Adam::builder().with_learning_rate(0.3).build().unwrap();
    let out = adam.search(&Holes, &[0.65, 0.3], 0).unwrap();
    assert!(out.best_cost.is_finite() && out.best_cost >= 0.0);
    assert!(max_abs_diff(&out.best_unit, &optimum) <= 0.01);
    // Its one evaluation was NaN: no result, rather than the start scored infinite.
    match Adam::default().search(&Holes, &[0.9, 0.9], 0) {
        Err(Error::Search(m)) => assert!(m.contains("Adam") && m.contains("any of the 1 "), "{m}"),
        other => panic!("expected a search error, got {other:?}"),
    }
}

/// Not finite anywhere (`value` NaN or infinite at every point).
struct Nowhere(f64);

impl Objective for Nowhere {
    fn dim(&self) -> usize {
        3
    }
    fn cost(&self, _: &[f64]) -> f64 {
        self.0
    }
    fn cost_and_gradient(&self, _: &[f64]) -> (f64, Vec<f64>) {
        (self.0, vec![self.0; 3])
    }
}

/// A search that met no finite cost is an error naming the searcher, not an outcome
/// whose best point is the start at an infinite cost.
#[test]
fn an_objective_finite_nowhere_is_an_error_for_every_searcher() {
    let searchers: [(&str, Box<dyn Searcher>); 4] = [
        ("differential evolution", Box::new(de_small())),
        ("Adam", Box::new(adam_small(0.1))),
        ("projected gradient", Box::new(ProjectedGradient::default())),
        // The hybrid stops at its first phase.
        ("differential evolution", Box::new(Hybrid::default())),
    ];
    for value in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for (name, searcher) in &searchers {
            match searcher.search(&Nowhere(value), &[0.5; 3], 1) {
                Err(Error::Search(m)) => {
                    assert!(m.starts_with(name) && m.contains("not finite"), "{m}")
                }
                other => panic!("{name} at {value}: expected a search error, got {other:?}"),
            }
        }
    }
}

// ---------------------------------------------------------------- settings and inputs

fn setting_name<T: std::fmt::Debug>(r: Result<T, Error>) -> String {
    match r {
        Err(Error::InvalidSetting { name, reason }) => {
            assert!(!reason.is_empty());
            name
        }
        other => panic!("expected InvalidSetting, got {other:?}"),
    }
}

#[test]
fn invalid_settings_give_typed_errors_naming_the_setting() {
    let de = DifferentialEvolution::builder;
    let cases_de = [
        (de().with_population(3), "population"),
        (de().with_population(0), "population"),
        (de().with_crossover(-0.1), "crossover"),
        (de().with_crossover(1.01), "crossover"),
        (de().with_crossover(f64::NAN), "crossover"),
        (de().with_weight(0.0), "weight"),
        (de().with_weight(2.5), "weight"),
        (de().with_weight(f64::NAN), "weight"),
        (de().with_iterations(0), "iterations"),
        (de().with_give_up_after(Some(0)), "give_up_after"),
    ];
    for (b, name) in cases_de {
        assert_eq!(setting_name(b.build()), name);
    }
    let adam = Adam::builder;
    let cases_adam = [
        (adam().with_learning_rate(0.0), "learning_rate"),
        (adam().with_learning_rate(-0.1), "learning_rate"),
        (adam().with_learning_rate(f64::NAN), "learning_rate"),
        (adam().with_learning_rate(f64::INFINITY), "learning_rate"),
        (adam().with_decay(0.0), "decay"),
        (adam().with_decay(1.5), "decay"),
        (adam().with_decay(f64::NAN), "decay"),
        (adam().with_decay_every(0), "decay_every"),
        (adam().with_beta1(1.0), "beta1"),
        (adam().with_beta2(f64::NAN), "beta2"),
        (adam().with_epsilon(0.0), "epsilon"),
        (adam().with_steps(0), "steps"),
    ];
    for (b, name) in cases_adam {
        assert_eq!(setting_name(b.build()), name);
    }
    // The edges of the ranges are valid.
    assert!(de()
        .with_population(4)
        .with_crossover(0.0)
        .with_weight(2.0)
        .build()
        .is_ok());
    assert!(de().with_crossover(1.0).build().is_ok());
    assert!(adam().with_decay(1.0).with_beta1(0.0).build().is_ok());
}

#[test]
fn bad_start_points_are_rejected() {
    let f = Sphere {
        centre: vec![0.5; 3],
    };
    for s in [
        &Hybrid::default() as &dyn Searcher,
        &DifferentialEvolution::default(),
        &Adam::default(),
    ] {
        assert!(matches!(
            s.search(&f, &[0.5; 2], 0),
            Err(Error::Mismatch(_))
        ));
        match s.search(&f, &[0.5, 1.2, 0.5], 0) {
            Err(Error::InvalidParam { name, .. }) => assert_eq!(name, "#1"),
            other => panic!("expected InvalidParam, got {other:?}"),
        }
        assert!(matches!(
            s.search(&f, &[f64::NAN, 0.5, 0.5], 0),
            Err(Error::InvalidParam { .. })
        ));
    }
}

// ---------------------------------------------------------------- deadlines

/// A deadline already past stops each searcher after its first generation or step, with a
/// point in the box and `timed_out` set; without one the search is `search`, bit for bit.
#[test]
fn a_passed_deadline_stops_every_searcher_with_its_best_so_far() {
    let f = Sphere {
        centre: vec![0.2, 0.7, 0.4],
    };
    let start = [0.5; 3];
    let long_de = DifferentialEvolution::builder()
        .with_population(40)
        .with_iterations(100_000)
        .build()
        .unwrap();
    let long_adam = Adam::builder().with_steps(1_000_000).build().unwrap();
    let searchers: [(&str, Box<dyn Searcher>); 3] = [
        ("de", Box::new(long_de.clone())),
        ("adam", Box::new(long_adam.clone())),
        ("hybrid", Box::new(Hybrid::new(long_de, long_adam))),
    ];
    let past = std::time::Instant::now();
    for (name, s) in &searchers {
        let o = s.search_until(&f, &start, 7, Some(past)).unwrap();
        assert!(o.timed_out, "{name}");
        assert!(
            o.trace.len() <= 2,
            "{name}: {} iterations ran",
            o.trace.len()
        );
        assert!(
            o.best_unit.iter().all(|u| (0.0..=1.0).contains(u)),
            "{name}"
        );
        assert!(o.best_cost <= f.cost(&start), "{name}");
    }
    let de = de_small();
    let plain = de.search(&f, &start, 7).unwrap();
    let unbounded = de.search_until(&f, &start, 7, None).unwrap();
    assert!(!unbounded.timed_out);
    assert_eq!(bits(&plain), bits(&unbounded));
}
