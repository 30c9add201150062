//! Fitting the surrogate: recovery of a planted truth, accuracy on held-out simulator
//! runs, and the hall-wide terms leaving the local slopes to the local weights.

use kalibre_core::{Sample, Surrogate, TrainingSet};
use kalibre_dc::hall::AlphaMode;
use kalibre_dc::surrogate::*;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

use super::{design, graph, planted, random_unit, samples};
use crate::surrogate_fixture::{hall, state, SMALL};

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
            extra: None,
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

/// A deadline already past stops Adam before its first epoch: the least-squares start
/// stands (a usable surrogate), `timed_out` says so; without one, every epoch runs.
#[test]
fn a_passed_deadline_keeps_the_least_squares_start() {
    let mode = AlphaMode::PerType;
    let h = hall(SMALL, mode);
    let scenarios: Vec<_> = (0..2)
        .map(|i| state(&h, &format!("t{i}"), 20 + i))
        .collect();
    let truth = planted(&h, mode, &scenarios, 3);
    let settings = ThermalGraphSettings::default()
        .with_trainable_adjacency(true)
        .with_epochs(100_000);
    let mut learner = graph(&h, mode, settings);
    let train = samples(&truth, &scenarios, &design(&learner, 12, 5));
    let data = || TrainingSet {
        scenarios: &scenarios,
        samples: &train,
    };
    let cut = learner
        .fit_until(data(), 0, Some(std::time::Instant::now()))
        .unwrap();
    assert!(cut.timed_out);
    assert_eq!(cut.epochs, 0);
    assert!(cut.train_mse.is_finite() && cut.train_mse < 1.0, "{cut:?}");
    let p = learner.layout().space().initial();
    assert!(learner
        .predict(&scenarios[0], &p)
        .iter()
        .all(|v| v.is_finite()));

    let mut short = graph(&h, mode, settings.with_epochs(20));
    let full = short.fit_until(data(), 0, None).unwrap();
    assert!(!full.timed_out);
    assert_eq!(full.epochs, 20);
}
