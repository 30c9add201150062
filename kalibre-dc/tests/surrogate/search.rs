//! Alpha recovery by a local search on the fitted surrogate, with the rise penalty.

use kalibre_core::search::Objective;
use kalibre_core::{Observations, OutputInfo, Snapshot, Surrogate, TrainingSet};
use kalibre_dc::hall::AlphaMode;
use kalibre_dc::surrogate::*;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::{design, graph, planted, samples};
use crate::surrogate_fixture::{hall, state, HALL_A};

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
