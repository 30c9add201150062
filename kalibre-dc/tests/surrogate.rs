//! The thermal graph surrogate: gradients against finite differences, recovery of a
//! planted truth, alpha recovery by search, adjacency structure, the rise penalty and the
//! specialised objective against the generic one.

mod surrogate_fixture;

use kalibre_core::search::Objective;
use kalibre_core::{
    Observations, OutputInfo, Regularizer, Sample, Snapshot, Surrogate, SurrogateObjective,
    TrainingSet,
};
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::surrogate::*;
use kalibre_dc::ParamLayout;
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;
use surrogate_fixture::{hall, state, HALL_A, SMALL};

fn graph(hall: &Hall, mode: AlphaMode, settings: ThermalGraphSettings) -> ThermalGraph {
    let layout = ParamLayout::with_mode(hall, mode, &[]).unwrap();
    ThermalGraph::new(hall, layout, settings).unwrap()
}

/// The paper's initial design in the unit box (lower, upper, midpoint of every
/// parameter), each with `copies` Gaussian-jittered copies (sd 0.05 in unit coordinates).
fn design(g: &ThermalGraph, copies: usize, seed: u64) -> Vec<Vec<f64>> {
    let space = g.layout().space();
    let d = space.dim();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.05).unwrap();
    let mut out = Vec::new();
    for base in [0.0, 1.0, 0.5] {
        out.push(space.from_unit(&vec![base; d]).unwrap());
        for _ in 1..copies {
            let u: Vec<f64> = (0..d)
                .map(|_| (base + noise.sample(&mut rng)).clamp(0.0, 1.0))
                .collect();
            out.push(space.from_unit(&u).unwrap());
        }
    }
    out
}

fn samples(truth: &ThermalGraph, scenarios: &[OperatingState], params: &[Vec<f64>]) -> Vec<Sample> {
    let mut out = Vec::new();
    for (s, scen) in scenarios.iter().enumerate() {
        for p in params {
            out.push(Sample {
                snapshot: s,
                params: p.clone(),
                outputs: truth.predict(scen, p),
                weight: 1.0,
            });
        }
    }
    out
}

/// A graph with known weights: the least-squares fit (no Adam) to physically shaped
/// outputs, `T = a X_cold + b` plus, in the hot aisle, `g X_hot + d` with `g` close to
/// `K / mean power` (so that a server's rise is about `1.76 / alpha` K), which the graph
/// represents exactly.
fn planted(hall: &Hall, mode: AlphaMode, scenarios: &[OperatingState], seed: u64) -> ThermalGraph {
    let mut g = graph(
        hall,
        mode,
        ThermalGraphSettings::default()
            .with_epochs(0)
            .with_ridge(0.0),
    );
    let n = g.sensor_count();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x5eed);
    let coef: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            [
                rng.random_range(0.8..1.2),
                rng.random_range(-1.0..1.0),
                1.757 / 300.0 * rng.random_range(0.6..1.0),
                rng.random_range(-1.0..1.0),
            ]
        })
        .collect();
    let d = design(&g, 4, seed);
    let mut train = Vec::new();
    for (si, scen) in scenarios.iter().enumerate() {
        for p in &d {
            let (xc, xh) = g.hidden(scen, p).unwrap();
            let outputs = (0..n)
                .map(|k| {
                    let c = coef[k];
                    let cold = c[0] * xc[k] + c[1];
                    if g.hot_mask()[k] {
                        cold + c[2] * xh[k] + c[3]
                    } else {
                        cold
                    }
                })
                .collect();
            train.push(Sample {
                snapshot: si,
                params: p.clone(),
                outputs,
                weight: 1.0,
            });
        }
    }
    g.fit(
        TrainingSet {
            scenarios,
            samples: &train,
        },
        0,
    )
    .unwrap();
    g
}

fn random_unit(d: usize, rng: &mut Xoshiro256PlusPlus) -> Vec<f64> {
    (0..d).map(|_| rng.random_range(0.05..0.95)).collect()
}

fn rel_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn adjacency_is_sparse_cut_and_normalised_at_hall_a_size() {
    let h = hall(HALL_A, AlphaMode::PerServer);
    assert_eq!(h.server_count(), 2240);
    let settings = AdjacencySettings::default();
    let adj = Adjacency::from_hall(&h, &settings).unwrap();
    let m = h.server_count();
    let mut hot_rows = 0;
    for (k, sensor) in h.sensors.iter().enumerate() {
        // Wcs: nearest CRAC has weight one, every kept entry is at or above the cut.
        let cs = adj.cs.range(k);
        let max = adj.cs.val[cs.clone()].iter().copied().fold(0.0, f64::max);
        assert!((max - 1.0).abs() < 1e-12);
        assert!(adj.cs.val[cs].iter().all(|&w| w >= settings.crac_threshold));
        let ss = adj.ss.range(k);
        if sensor.aisle == kalibre_dc::hall::Aisle::Cold {
            assert!(ss.is_empty(), "cold sensor {} has server edges", sensor.id);
            continue;
        }
        hot_rows += 1;
        let row = &adj.ss.val[ss.clone()];
        assert!(
            (row.iter().sum::<f64>() - 1.0).abs() < 1e-12,
            "row {k} not normalised"
        );
        // Relative weights: the kept ones reach the cut, the cut ones are zero.
        let recip: Vec<f64> = h
            .servers()
            .map(|s| {
                1.0 / kalibre_dc::hall::distance(s.exhaust_centre(), sensor.position_m)
                    .max(settings.min_distance_m)
            })
            .collect();
        let rmax = recip.iter().copied().fold(0.0, f64::max);
        for (j, r) in recip.iter().enumerate() {
            let kept = adj.ss.get(k, j) != 0.0;
            assert_eq!(
                kept,
                r / rmax >= settings.server_threshold,
                "sensor {k}, server {j}"
            );
        }
        assert!(
            row.len() < m / 4,
            "row {k} keeps {} of {m} servers",
            row.len()
        );
    }
    assert_eq!(hot_rows, 32);
    // A higher threshold keeps fewer edges.
    let tight = Adjacency::from_hall(&h, &settings.with_server_threshold(0.9)).unwrap();
    assert!(tight.ss.nnz() < adj.ss.nnz());
}

#[test]
fn fit_recovers_a_planted_truth() {
    for mode in [AlphaMode::PerType, AlphaMode::PerServer] {
        let h = hall(SMALL, mode);
        let scenarios: Vec<_> = (0..3)
            .map(|i| state(&h, &format!("t{i}"), 10 + i))
            .collect();
        let truth = planted(&h, mode, &scenarios, 7);
        // Without the ridges in Adam's loss: they are a prior toward no rise response,
        // which biases planted weights (train MSE 0.0015 with them); this checks the fit.
        let mut learner = graph(
            &h,
            mode,
            ThermalGraphSettings::default().with_adam_ridge(false),
        );
        let train = samples(&truth, &scenarios, &design(&learner, 16, 3));
        let summary = learner
            .fit(
                TrainingSet {
                    scenarios: &scenarios,
                    samples: &train,
                },
                0,
            )
            .unwrap();
        assert!(
            summary.train_mse < 1e-4,
            "{mode:?}: train mse {}",
            summary.train_mse
        );
        // Held out: new parameters inside the training range.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(99);
        let space = learner.layout().space().clone();
        let mut worst: f64 = 0.0;
        for _ in 0..20 {
            let p = space
                .from_unit(&random_unit(space.dim(), &mut rng))
                .unwrap();
            for s in &scenarios {
                for (a, b) in learner.predict(s, &p).iter().zip(truth.predict(s, &p)) {
                    worst = worst.max((a - b).abs());
                }
            }
        }
        assert!(worst < 0.05, "{mode:?}: held-out max error {worst} C");
    }
}

/// Minimises an objective in the unit box with projected Adam (a plain local search),
/// halving the step every `steps / 6` steps.
fn descend(obj: &dyn Objective, start: &[f64], steps: usize, lr0: f64) -> Vec<f64> {
    let mut x = start.to_vec();
    let (mut m, mut v) = (vec![0.0; x.len()], vec![0.0; x.len()]);
    for t in 1..=steps {
        let lr = lr0 * 0.5f64.powi((6 * t / steps) as i32);
        let (_, g) = obj.cost_and_gradient(&x);
        for i in 0..x.len() {
            m[i] = 0.9 * m[i] + 0.1 * g[i];
            v[i] = 0.999 * v[i] + 0.001 * g[i] * g[i];
            let mh = m[i] / (1.0 - 0.9f64.powi(t as i32));
            let vh = v[i] / (1.0 - 0.999f64.powi(t as i32));
            x[i] = (x[i] - lr * mh / (vh.sqrt() + 1e-12)).clamp(0.0, 1.0);
        }
    }
    x
}

#[test]
fn search_on_the_fitted_surrogate_recovers_per_type_alpha() {
    let mode = AlphaMode::PerType;
    let h = hall(HALL_A, mode);
    let scenarios: Vec<_> = (0..2)
        .map(|i| state(&h, &format!("t{i}"), 20 + i))
        .collect();
    let truth = planted(&h, mode, &scenarios, 11);
    let space = truth.layout().space().clone();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
    let alpha_true: Vec<f64> = (0..space.dim())
        .map(|_| rng.random_range(0.13..0.3))
        .collect();
    let outputs: Vec<OutputInfo> = h
        .sensors
        .iter()
        .map(|s| OutputInfo {
            name: s.id.clone(),
            group: s.aisle.as_str().into(),
        })
        .collect();
    let obs = Observations::new(
        outputs,
        scenarios
            .iter()
            .map(|s| Snapshot {
                label: s.label.clone(),
                scenario: s.clone(),
                measured: truth
                    .predict(s, &alpha_true)
                    .into_iter()
                    .map(Some)
                    .collect(),
            })
            .collect(),
    )
    .unwrap();
    let mut learner = graph(&h, mode, ThermalGraphSettings::default());
    let train = samples(&truth, &scenarios, &design(&learner, 16, 4));
    learner
        .fit(
            TrainingSet {
                scenarios: &scenarios,
                samples: &train,
            },
            0,
        )
        .unwrap();
    let penalty =
        TemperatureRisePenalty::new(&h, learner.layout(), &scenarios, PenaltySettings::default())
            .unwrap();
    let obj = ThermalGraphObjective::new(&learner, &obs)
        .unwrap()
        .with_penalty(&penalty);
    let start = space.to_unit(&space.initial()).unwrap();
    let best_u = descend(&obj, &start, 3000, 0.05);
    let best = space.from_unit(&best_u).unwrap();
    // Measured: within 0.9% for every type (the search stops short of the exact optimum).
    for (t, (b, a)) in best.iter().zip(&alpha_true).enumerate() {
        assert!((b / a - 1.0).abs() < 0.02, "type {t}: found {b}, truth {a}");
    }
    assert!(!penalty.report(&best).binds);
}

#[test]
fn penalty_reports_where_it_binds() {
    let mode = AlphaMode::PerType;
    let h = hall(SMALL, mode);
    let layout = ParamLayout::with_mode(&h, mode, &[]).unwrap();
    let scen = vec![state(&h, "t0", 1)];
    let pen = TemperatureRisePenalty::new(&h, &layout, &scen, PenaltySettings::default()).unwrap();
    // K = 1 / (4.71947e-4 * 1.2 * 1005) = 1.757 K cfm/W.
    assert!((pen.rise_c(1.0) - 1.7570).abs() < 1e-3);
    // Rises 8.8 K (alpha 0.2) are inside [5, 20]: no penalty.
    let inside = vec![0.2; layout.space().dim()];
    let rep = pen.report(&inside);
    assert!(!rep.binds && rep.value == 0.0 && rep.violations.is_empty());
    // Type 1 at alpha 0.08 (rise 22 K) binds from above; type 2 at 0.5 (3.5 K) from below.
    let mut p = inside.clone();
    p[1] = 0.08;
    p[2] = 0.5;
    let rep = pen.report(&p);
    assert!(rep.binds);
    assert_eq!(rep.violations.len(), 2);
    assert_eq!(rep.violations[0].source, "alpha/type-1");
    assert_eq!(rep.violations[0].bound, RiseBound::Above);
    assert_eq!(rep.violations[1].bound, RiseBound::Below);
    assert!(rep.servers_above > 0 && rep.servers_below > 0);
    assert!(rep.weight_fraction_outside > 0.0 && rep.weight_fraction_outside < 1.0);
    // The value is the power-weighted mean violation: below the largest violation (K).
    let (v, _) = pen.value_and_gradient(&p);
    assert!((v - rep.value).abs() < 1e-12);
    assert!(v > 0.0 && v < pen.rise_c(0.08) - pen.settings().upper_c);
    assert!(PenaltySettings::default()
        .with_range_c(10.0, 5.0)
        .check()
        .is_err());
}

#[test]
fn bad_training_data_is_a_clear_error() {
    let h = hall(SMALL, AlphaMode::PerType);
    let mut g = graph(&h, AlphaMode::PerType, ThermalGraphSettings::default());
    let scen = vec![state(&h, "t0", 1)];
    let p = g.layout().space().initial();
    let bad = vec![Sample {
        snapshot: 0,
        params: p.clone(),
        outputs: vec![20.0; 3],
        weight: 1.0,
    }];
    let err = g
        .fit(
            TrainingSet {
                scenarios: &scen,
                samples: &bad,
            },
            0,
        )
        .unwrap_err();
    assert!(err.to_string().contains("training sample 0"), "{err}");
    let bad = vec![Sample {
        snapshot: 4,
        params: p,
        outputs: vec![],
        weight: 1.0,
    }];
    assert!(g
        .fit(
            TrainingSet {
                scenarios: &scen,
                samples: &bad
            },
            0
        )
        .is_err());
    assert!(ThermalGraphSettings::default()
        .with_decay(0.0, 10)
        .check()
        .is_err());

    // Bad inputs to a prediction: the error names them, and `predict` gives NaN.
    let mut p = g.layout().space().initial();
    let last_alpha = g.layout().alpha_params().end - 1;
    assert_eq!(g.layout().alpha_params(), 0..p.len());
    p[last_alpha] = -0.1;
    let err = g.hidden(&scen[0], &p).unwrap_err().to_string();
    assert!(err.contains("alpha must be positive, got -0.1"), "{err}");
    assert!(g.predict(&scen[0], &p).iter().all(|t| t.is_nan()));
    p[last_alpha] = f64::NAN;
    let err = g.hidden(&scen[0], &p).unwrap_err().to_string();
    assert!(
        err.contains(&format!("parameter {last_alpha} is not finite")),
        "{err}"
    );
    let mut hot = scen[0].clone();
    hot.power_w[3] = f64::INFINITY;
    let err = g
        .hidden(&hot, &g.layout().space().initial())
        .unwrap_err()
        .to_string();
    assert!(err.contains("non-finite input value"), "{err}");
    // A fixed alpha is checked when the layout is built (predictions check only the
    // calibrated ones).
    let mut unchecked = h.clone();
    unchecked.server_types[0].alpha_cfm_per_w.initial = 0.0;
    let err = ParamLayout::with_mode(&unchecked, AlphaMode::Fixed, &[])
        .unwrap_err()
        .to_string();
    let id = &unchecked.server_types[0].id;
    assert!(
        err.contains(&format!(
            "server type `{id}`: alpha_cfm_per_w.initial must be positive"
        )),
        "{err}"
    );
}

fn fd_check(
    f: impl Fn(&[f64]) -> f64,
    x: &[f64],
    grad: &[f64],
    rel: f64,
) -> Result<(), TestCaseError> {
    for i in 0..x.len() {
        let h = 1e-6 * x[i].abs().max(1e-3);
        let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
        xp[i] += h;
        xm[i] -= h;
        let fd = (f(&xp) - f(&xm)) / (2.0 * h);
        prop_assert!(
            rel_close(fd, grad[i], rel),
            "coordinate {i}: fd {fd}, analytic {}",
            grad[i]
        );
    }
    Ok(())
}

fn fitted_small(
    mode: AlphaMode,
    trainable: bool,
    seed: u64,
) -> (Hall, Vec<OperatingState>, ThermalGraph, Vec<Sample>) {
    let h = hall(SMALL, mode);
    let scenarios: Vec<_> = (0..2)
        .map(|i| state(&h, &format!("t{i}"), seed + i))
        .collect();
    let truth = planted(&h, mode, &scenarios, seed);
    let settings = ThermalGraphSettings::default()
        .with_epochs(3)
        .with_trainable_adjacency(trainable);
    let mut g = graph(&h, mode, settings);
    let train = samples(&truth, &scenarios, &design(&g, 2, seed));
    g.fit(
        TrainingSet {
            scenarios: &scenarios,
            samples: &train,
        },
        0,
    )
    .unwrap();
    // Move the weights off the fit so every gradient entry is exercised.
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let theta: Vec<f64> = g
        .weights_vector()
        .iter()
        .map(|t| t + rng.random_range(-0.3..0.3))
        .collect();
    g.set_weights_vector(&theta).unwrap();
    (h, scenarios, g, train)
}

fn mode_of(per_server: bool) -> AlphaMode {
    if per_server {
        AlphaMode::PerServer
    } else {
        AlphaMode::PerType
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 12,
        rng_seed: RngSeed::Fixed(12),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn vjp_matches_finite_differences(seed in 0u64..1000, per_server in any::<bool>()) {
        let (_, scenarios, g, _) = fitted_small(mode_of(per_server), false, seed);
        let space = g.layout().space().clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed + 1);
        let p = space.from_unit(&random_unit(space.dim(), &mut rng)).unwrap();
        let ct: Vec<f64> = (0..g.sensor_count()).map(|_| rng.random_range(-1.0..1.0)).collect();
        let s = &scenarios[0];
        let grad = g.vjp(s, &p, &ct);
        fd_check(|x| g.predict(s, x).iter().zip(&ct).map(|(o, c)| o * c).sum(), &p, &grad, 1e-5)?;
    }

    #[test]
    fn weight_gradient_matches_finite_differences(seed in 0u64..1000, per_server in any::<bool>(), trainable in any::<bool>()) {
        let (_, scenarios, g, train) = fitted_small(mode_of(per_server), trainable, seed);
        let data = || TrainingSet { scenarios: &scenarios, samples: &train };
        let (_, grad) = g.training_loss_and_gradient(data()).unwrap();
        let theta = g.weights_vector();
        let probe = std::cell::RefCell::new(fitted_small(mode_of(per_server), trainable, seed).2);
        fd_check(|t| {
            let mut p = probe.borrow_mut();
            p.set_weights_vector(t).unwrap();
            p.training_loss_and_gradient(data()).unwrap().0
        }, &theta, &grad, 1e-5)?;
    }

    #[test]
    fn penalty_gradient_matches_finite_differences(seed in 0u64..1000, per_server in any::<bool>()) {
        let mode = mode_of(per_server);
        let h = hall(SMALL, mode);
        let layout = ParamLayout::with_mode(&h, mode, &[]).unwrap();
        let scen = vec![state(&h, "t0", seed), state(&h, "t1", seed + 1)];
        let pen = TemperatureRisePenalty::new(&h, &layout, &scen, PenaltySettings::default()).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        // Alphas straddling the range (rises from 3.5 to 29 K), away from the kinks.
        let p: Vec<f64> = (0..layout.space().dim()).map(|_| rng.random_range(0.06..0.5)).collect();
        for a in &p {
            let r = pen.rise_c(*a);
            prop_assume!((r - 5.0).abs() > 1e-3 && (r - 15.0).abs() > 1e-3);
        }
        let (value, grad) = pen.value_and_gradient(&p);
        fd_check(|x| pen.value_and_gradient(x).0, &p, &grad, 1e-5)?;
        // The value-only path the searchers take is the same sum, bit for bit.
        prop_assert_eq!(pen.value(&p).to_bits(), value.to_bits());
    }

    #[test]
    fn specialised_objective_equals_the_generic_one(seed in 0u64..1000, per_server in any::<bool>()) {
        let mode = mode_of(per_server);
        let (h, scenarios, g, _) = fitted_small(mode, false, seed);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed + 2);
        let outputs: Vec<OutputInfo> = h.sensors.iter()
            .map(|s| OutputInfo { name: s.id.clone(), group: s.aisle.as_str().into() }).collect();
        let obs = Observations::new(outputs, scenarios.iter().map(|s| Snapshot {
            label: s.label.clone(),
            scenario: s.clone(),
            // One dead sensor per snapshot.
            measured: (0..h.sensors.len()).map(|k| (k != 1).then(|| rng.random_range(18.0..40.0))).collect(),
        }).collect()).unwrap();
        let pen = TemperatureRisePenalty::new(&h, g.layout(), &scenarios, PenaltySettings::default().with_weight(0.7)).unwrap();
        let space = g.layout().space();
        let generic = SurrogateObjective::new(&g, &obs, space).with_regularizer(&pen, 0.7);
        let fast = ThermalGraphObjective::new(&g, &obs).unwrap().with_penalty(&pen);
        let u: Vec<f64> = (0..space.dim()).map(|_| rng.random_range(0.0..1.0)).collect();
        prop_assert!(rel_close(fast.cost(&u), generic.cost(&u), 1e-10));
        let (c1, g1) = fast.cost_and_gradient(&u);
        let (c2, g2) = generic.cost_and_gradient(&u);
        prop_assert!(rel_close(c1, c2, 1e-10));
        for (a, b) in g1.iter().zip(&g2) {
            prop_assert!(rel_close(*a, *b, 1e-9), "{a} vs {b}");
        }
    }
}

/// Trained on runs of the built-in simulator, the surrogate predicts held-out runs of the
/// same hall (alpha per type, two operating states).
#[test]
fn predicts_held_out_simulator_runs() {
    use kalibre_core::Model;
    use kalibre_dc::sim::SimConfig;
    use kalibre_dc::HallModel;
    let mode = AlphaMode::PerType;
    let mut h = hall(SMALL, mode);
    for t in &mut h.server_types {
        t.alpha_cfm_per_w = kalibre_dc::hall::AlphaBounds {
            initial: 0.12,
            min: 0.06,
            max: 0.4,
        };
    }
    let model = HallModel::new(&h, SimConfig::default()).unwrap();
    let scenarios: Vec<_> = (0..2)
        .map(|i| state(&h, &format!("t{i}"), 40 + i))
        .collect();
    let mut g = graph(&h, mode, ThermalGraphSettings::default());
    let space = g.layout().space().clone();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(8);
    let run = |p: &[f64], s: usize| Sample {
        snapshot: s,
        params: p.to_vec(),
        outputs: model.evaluate(&scenarios[s], p).unwrap().values,
        weight: 1.0,
    };
    let mut train = Vec::new();
    let mut held_out = Vec::new();
    for s in 0..scenarios.len() {
        for base in [0.0, 1.0, 0.5] {
            train.push(run(&space.from_unit(&vec![base; space.dim()]).unwrap(), s));
        }
        for _ in 0..3 {
            train.push(run(
                &space
                    .from_unit(&random_unit(space.dim(), &mut rng))
                    .unwrap(),
                s,
            ));
        }
        for _ in 0..2 {
            held_out.push(run(
                &space
                    .from_unit(&random_unit(space.dim(), &mut rng))
                    .unwrap(),
                s,
            ));
        }
    }
    let fit = g
        .fit(
            TrainingSet {
                scenarios: &scenarios,
                samples: &train,
            },
            0,
        )
        .unwrap();
    let (mut sum, mut count, mut worst) = ([0.0; 2], [0.0; 2], 0.0f64);
    for s in &held_out {
        let pred = g.predict(&scenarios[s.snapshot], &s.params);
        for (k, (p, m)) in pred.iter().zip(&s.outputs).enumerate() {
            let hot = usize::from(g.hot_mask()[k]);
            sum[hot] += (p - m).abs();
            count[hot] += 1.0;
            worst = worst.max((p - m).abs());
        }
    }
    let mae = (sum[0] + sum[1]) / (count[0] + count[1]);
    eprintln!(
        "train mse {}, held-out mae {mae} (cold {}, hot {}), max {worst}",
        fit.train_mse,
        sum[0] / count[0],
        sum[1] / count[1]
    );
    // Measured (SimConfig::default, this seed): held-out MAE 0.94 C, max 2.9 C, over
    // alphas spanning rises of 4-29 K; the graph's heating block is linear in P / alpha,
    // while the simulated exhaust mixing is flow-weighted, so errors grow far from the
    // training runs. A trainable adjacency fits the training runs better (mse 0.52 against
    // 2.49 K^2) but not the held-out ones (MAE 0.96 C), as the paper's Fig. 7 found.
    assert!(mae < 1.0, "held-out MAE {mae} C");
}

/// The hall-wide mass-balance terms must not take the response that belongs to the
/// servers next to each sensor. The truth is a term-free graph (every sensor answers only
/// the servers its adjacency names); the learners carry the recirculation and bypass terms
/// and learn from the paper's design, where every alpha moves together, so the terms'
/// features are nearly collinear with the local ones. The slopes per server type at a
/// held-out point must follow the truth's more closely with the default ridge on the
/// hall-wide weights than with those weights ridged like the rest.
#[test]
fn hall_wide_terms_do_not_take_the_local_slopes() {
    let h = hall(SMALL, AlphaMode::PerType);
    let scenarios: Vec<_> = (0..3)
        .map(|i| state(&h, &format!("t{i}"), 20 + i))
        .collect();
    let truth = planted(&h, AlphaMode::PerType, &scenarios, 11);
    let layout = truth.layout().clone();
    let with_terms = |settings: ThermalGraphSettings| {
        let mut g = graph(&h, AlphaMode::PerType, settings);
        for kind in [FlowBalance::Recirculation, FlowBalance::Bypass] {
            g = g.with_term(Box::new(FlowBalanceTerm::new(&h, &layout, kind)));
        }
        g
    };
    let space = layout.space().clone();
    let train = samples(&truth, &scenarios, &design(&truth, 2, 5));
    let slope_error = |settings: ThermalGraphSettings| {
        let mut g = with_terms(settings);
        g.fit(
            TrainingSet {
                scenarios: &scenarios,
                samples: &train,
            },
            0,
        )
        .unwrap();
        let centre = vec![0.45; space.dim()];
        let (mut err, mut norm) = (0.0, 0.0);
        for p in 0..space.dim() {
            let (mut lo, mut hi) = (centre.clone(), centre.clone());
            lo[p] -= 0.01;
            hi[p] += 0.01;
            let (lo, hi) = (space.from_unit(&lo).unwrap(), space.from_unit(&hi).unwrap());
            for s in &scenarios {
                let (tl, th) = (truth.predict(s, &lo), truth.predict(s, &hi));
                let (gl, gh) = (g.predict(s, &lo), g.predict(s, &hi));
                for k in 0..tl.len() {
                    let (t, y) = (th[k] - tl[k], gh[k] - gl[k]);
                    err += (y - t) * (y - t);
                    norm += t * t;
                }
            }
        }
        (err / norm).sqrt()
    };
    let default = slope_error(ThermalGraphSettings::default());
    let plain = slope_error(
        ThermalGraphSettings::default()
            .with_adam_ridge(false)
            .with_hall_wide_ridge(1e-3),
    );
    let adam_only = slope_error(ThermalGraphSettings::default().with_hall_wide_ridge(1e-3));
    // Measured: 0.008 against 0.060 and 0.064; the ridge in Adam's loss alone does not help.
    assert!(default < 0.5 * plain, "default {default} against {plain}");
    assert!(
        default < 0.5 * adam_only,
        "default {default} against {adam_only} with the ridge in Adam only"
    );
}
