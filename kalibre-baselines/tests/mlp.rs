//! The MLP's hand-written gradients against finite differences, and the MLP in the
//! four-step calibration loop.

mod support;

use kalibre_baselines::{
    flatten, loss_and_gradients, Activation, InputLevel, Mlp, MlpSettings, Network,
};
use kalibre_core::{Calibrator, Sample, Settings, Surrogate, TrainingSet};
use kalibre_dc::hall::AlphaMode;
use kalibre_dc::ParamLayout;
use ndarray::Array2;
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

fn random_matrix(rng: &mut Xoshiro256PlusPlus, rows: usize, cols: usize) -> Array2<f64> {
    Array2::from_shape_simple_fn((rows, cols), || rng.random_range(-1.5..1.5))
}

/// Central differences of the training loss over every weight and bias.
fn check_weight_gradients(activation: Activation, seed: u64) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut net = Network::new(&[5, 7, 4, 3], activation, &mut rng);
    // Non-zero biases so that the bias gradients are exercised away from the start.
    let mut flat = net.to_flat();
    for v in flat.iter_mut() {
        *v += rng.random_range(-0.3..0.3);
    }
    net.set_flat(&flat);
    let (x, y) = (random_matrix(&mut rng, 6, 5), random_matrix(&mut rng, 6, 3));
    let w: Vec<f64> = (0..6).map(|_| rng.random_range(0.2..2.0)).collect();
    let idx = [0, 2, 3, 5];
    let (base_loss, grads) = loss_and_gradients(&net, &x, &y, &w, &idx);
    let analytic = flatten(&grads);
    assert_eq!(analytic.len(), net.parameter_count());
    let h = 1e-6;
    for i in 0..flat.len() {
        let mut p = flat.clone();
        p[i] += h;
        net.set_flat(&p);
        let up = loss_and_gradients(&net, &x, &y, &w, &idx).0;
        p[i] -= 2.0 * h;
        net.set_flat(&p);
        let down = loss_and_gradients(&net, &x, &y, &w, &idx).0;
        let fd = (up - down) / (2.0 * h);
        // A ReLU kink inside [w - h, w + h] makes the two one-sided slopes differ; there
        // the backprop value (a one-sided derivative) must lie between them instead.
        let (right, left) = ((up - base_loss) / h, (base_loss - down) / h);
        let tol = 1e-6 * (1.0 + fd.abs());
        if (right - left).abs() > 1e-3 * (1.0 + fd.abs()) {
            let (lo, hi) = (right.min(left), right.max(left));
            assert!(
                analytic[i] >= lo - 1e-3 && analytic[i] <= hi + 1e-3,
                "{activation:?} weight {i} at a kink: slopes {left}..{right}, backprop {}",
                analytic[i]
            );
            continue;
        }
        assert!(
            (fd - analytic[i]).abs() <= tol,
            "{activation:?} weight {i}: finite difference {fd}, backprop {}",
            analytic[i]
        );
    }
    net.set_flat(&flat);
}

/// Central differences of `sum_k g_k f_k(x)` over every input.
fn check_input_gradients(activation: Activation, seed: u64) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let net = Network::new(&[6, 9, 5, 4], activation, &mut rng);
    let x = random_matrix(&mut rng, 3, 6);
    let g = random_matrix(&mut rng, 3, 4);
    let tape = net.forward(x.view());
    let (_, dx) = net.backward(&tape, g.clone());
    let h = 1e-6;
    let f = |x: &Array2<f64>| (net.forward(x.view()).outputs() * &g).sum();
    for r in 0..3 {
        for c in 0..6 {
            let mut xp = x.clone();
            xp[[r, c]] += h;
            let mut xm = x.clone();
            xm[[r, c]] -= h;
            let fd = (f(&xp) - f(&xm)) / (2.0 * h);
            assert!(
                (fd - dx[[r, c]]).abs() <= 1e-6 * (1.0 + fd.abs()),
                "{activation:?} input ({r}, {c}): finite difference {fd}, backprop {}",
                dx[[r, c]]
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 12,
        rng_seed: RngSeed::Fixed(7),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]
    #[test]
    fn weight_gradients_match_finite_differences(seed in any::<u64>(), relu in any::<bool>()) {
        let act = if relu { Activation::Relu } else { Activation::Tanh };
        check_weight_gradients(act, seed);
    }

    #[test]
    fn input_gradients_match_finite_differences(seed in any::<u64>(), relu in any::<bool>()) {
        let act = if relu { Activation::Relu } else { Activation::Tanh };
        check_input_gradients(act, seed);
    }
}

/// A fitted MLP on the hall's snapshots, trained on smooth synthetic outputs (the test
/// is about the chain from parameters through standardisation and alpha expansion).
fn fitted_mlp(mode: AlphaMode, seed: u64) -> (support::Setup, Mlp) {
    fitted_mlp_at(mode, InputLevel::Server, seed)
}

fn fitted_mlp_at(mode: AlphaMode, inputs: InputLevel, seed: u64) -> (support::Setup, Mlp) {
    let s = support::setup(mode);
    let layout = ParamLayout::with_mode(&s.hall, mode, &[]).unwrap();
    let space = layout.space().clone();
    let mut mlp = Mlp::new(
        &s.hall,
        layout,
        MlpSettings::default()
            .with_inputs(inputs)
            .with_hidden(vec![16, 8])
            .with_epochs(20),
    )
    .unwrap();
    let scenarios: Vec<_> = s.snaps.iter().map(|x| x.state.clone()).collect();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let n_out = s.hall.sensors.len();
    let samples: Vec<Sample> = (0..40)
        .map(|i| {
            let u: Vec<f64> = (0..space.dim())
                .map(|_| rng.random_range(0.0..1.0))
                .collect();
            let params = space.from_unit(&u).unwrap();
            let m = params.iter().sum::<f64>() / params.len() as f64;
            Sample {
                snapshot: i % scenarios.len(),
                outputs: (0..n_out)
                    .map(|k| 20.0 + k as f64 * 0.3 + 2.0 / m)
                    .collect(),
                params,
                weight: 1.0,
            }
        })
        .collect();
    mlp.fit(
        TrainingSet {
            scenarios: &scenarios,
            samples: &samples,
        },
        seed,
    )
    .unwrap();
    (s, mlp)
}

#[test]
fn vjp_matches_finite_differences_per_type_and_per_server() {
    let cases = [
        (AlphaMode::PerType, InputLevel::Server),
        (AlphaMode::PerServer, InputLevel::Server),
        (AlphaMode::PerServer, InputLevel::Rack),
    ];
    for (mode, inputs) in cases {
        let (s, mlp) = fitted_mlp_at(mode, inputs, 3);
        let units = match inputs {
            InputLevel::Server => s.hall.server_count(),
            InputLevel::Rack => s.hall.racks.len(),
        };
        assert_eq!(mlp.input_count(), 2 * s.hall.cracs.len() + 2 * units);
        let space = ParamLayout::with_mode(&s.hall, mode, &[])
            .unwrap()
            .space()
            .clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
        let scen = &s.snaps[1].state;
        let u: Vec<f64> = (0..space.dim())
            .map(|_| rng.random_range(0.2..0.8))
            .collect();
        let p = space.from_unit(&u).unwrap();
        let g: Vec<f64> = (0..s.hall.sensors.len())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let grad = mlp.vjp(scen, &p, &g);
        assert_eq!(grad.len(), space.dim());
        let f = |p: &[f64]| -> f64 {
            mlp.predict(scen, p)
                .iter()
                .zip(&g)
                .map(|(a, b)| a * b)
                .sum()
        };
        for i in 0..space.dim() {
            let h = 1e-6 * p[i];
            let (mut pp, mut pm) = (p.clone(), p.clone());
            pp[i] += h;
            pm[i] -= h;
            let fd = (f(&pp) - f(&pm)) / (2.0 * h);
            assert!(
                (fd - grad[i]).abs() <= 1e-5 * (1.0 + fd.abs()),
                "{mode:?} param {i}: finite difference {fd}, vjp {}",
                grad[i]
            );
        }
        // The synthetic outputs fall with alpha: the fitted MLP's gradient must say so.
        let ones = vec![1.0; s.hall.sensors.len()];
        let total: f64 = mlp.vjp(scen, &p, &ones).iter().sum();
        assert!(
            total < 0.0,
            "{mode:?}: d(sum T)/d alpha = {total}, expected < 0"
        );
    }
}

#[test]
fn predicts_nan_before_fitting_and_for_misfit_inputs() {
    let (s, mlp) = fitted_mlp(AlphaMode::PerType, 1);
    let unfitted = Mlp::new(&s.hall, s.model.layout().clone(), MlpSettings::default()).unwrap();
    let p = s.model.layout().space().initial();
    assert!(unfitted
        .predict(&s.snaps[0].state, &p)
        .iter()
        .all(|v| v.is_nan()));
    assert!(mlp
        .predict(&s.snaps[0].state, &p[..2])
        .iter()
        .all(|v| v.is_nan()));
    assert!(mlp
        .predict(&s.snaps[0].state, &p)
        .iter()
        .all(|v| v.is_finite()));
    let e = MlpSettings::default()
        .with_batch_size(0)
        .check()
        .unwrap_err();
    assert!(e.to_string().contains("batch_size"));
}

#[test]
fn fit_is_deterministic_per_seed() {
    let (s, a) = fitted_mlp(AlphaMode::PerType, 5);
    let (_, b) = fitted_mlp(AlphaMode::PerType, 5);
    let (_, c) = fitted_mlp(AlphaMode::PerType, 6);
    let p = s.model.layout().space().initial();
    let st = &s.snaps[0].state;
    assert_eq!(a.predict(st, &p), b.predict(st, &p));
    assert_ne!(a.predict(st, &p), c.predict(st, &p));
}

#[test]
fn mlp_in_the_calibration_loop_improves_on_the_initial_mae() {
    let s = support::setup(AlphaMode::PerType);
    let space = s.model.layout().space().clone();
    let run = |seed: u64| {
        let mlp = Mlp::new(&s.hall, s.model.layout().clone(), MlpSettings::default()).unwrap();
        // The core settings `calibrate_hall` gives the thermal graph: the same loop.
        let settings = Settings {
            seed,
            max_iterations: 12,
            focus: Some(1.0),
            explore_on_repeat: Some(0.015),
            ..Settings::default()
        };
        Calibrator::new(&s.model, mlp, &s.obs, &space)
            .with_settings(settings)
            .run()
            .unwrap()
    };
    let t = std::time::Instant::now();
    let r = run(1);
    let initial = r.initial.mae_c.unwrap();
    eprintln!(
        "MLP loop: initial MAE {initial:.3} C, best {:.3} C after {} runs ({:.1} s)",
        r.best.mae_c,
        r.runs.total,
        t.elapsed().as_secs_f64()
    );
    for h in &r.history {
        eprintln!(
            "it {} runs {} mae {:?} best {:?}",
            h.iteration, h.model_runs, h.mae_c, h.best_mae_c
        );
    }
    eprintln!("{:?}", r.stop_reason);
    assert!(
        r.best.mae_c < 0.5 * initial,
        "best MAE {} is not below half the initial {initial}",
        r.best.mae_c
    );
    let again = run(1);
    assert_eq!(again.best.mae_c, r.best.mae_c);
    assert_eq!(again.best.params, r.best.params);
}

/// The case CI once drew: a weight whose finite-difference interval straddles a ReLU kink.
#[test]
fn relu_weight_gradient_at_a_kink() {
    check_weight_gradients(Activation::Relu, 3_729_338_369_254_490_304);
}
