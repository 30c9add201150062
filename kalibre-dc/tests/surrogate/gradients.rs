//! Property tests of the hand-written gradients against central finite differences (the
//! predictions' VJP, the training loss, the rise penalty), and of the specialised
//! objective against the generic one.

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
use rand_xoshiro::Xoshiro256PlusPlus;

use super::{design, graph, planted, random_unit, samples};
use crate::surrogate_fixture::{hall, state, SMALL};

fn rel_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
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
