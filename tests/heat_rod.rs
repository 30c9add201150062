//! The heat-rod domain: simulator physics, the surrogate's hand-written gradient, and the
//! calibration target (both parameters within 2% of truth within 10 runs per condition
//! after the initial design).

#[path = "../examples/heat_rod.rs"]
mod heat_rod;

use heat_rod::*;
use kalibre_core::{Model, Sample, Surrogate, TrainingSet};

fn scenario(heater_w: f64) -> RodScenario {
    RodScenario {
        heater_w,
        ambient_c: 21.0,
    }
}

#[test]
fn simulator_conserves_energy() {
    let sim = RodSimulator { cells: CELLS };
    let s = scenario(4.0);
    for &(k, h) in &[(120.0, 15.0), (20.0, 60.0), (400.0, 2.0)] {
        let t = sim.solve(&s, k, h);
        let dx = LENGTH_M / CELLS as f64;
        let p = std::f64::consts::PI * DIAMETER_M;
        let a = p * DIAMETER_M / 4.0;
        let side: f64 = t
            .iter()
            .enumerate()
            .map(|(i, ti)| {
                let w = if i == 0 || i == CELLS { 0.5 } else { 1.0 };
                h * p * dx * w * (ti - s.ambient_c)
            })
            .sum();
        let tip = h * a * (t[CELLS] - s.ambient_c);
        let rel = (side + tip - s.heater_w).abs() / s.heater_w;
        assert!(
            rel < 1e-10,
            "k {k} h {h}: heat lost {} of {} W",
            side + tip,
            s.heater_w
        );
    }
}

#[test]
fn simulator_converges_to_the_exact_fin_solution() {
    // Exact solution with a convective tip: theta(x) = Q/(k A m) *
    // (cosh m(L-x) + r sinh m(L-x)) / (sinh mL + r cosh mL), r = h / (m k).
    let (k, h, q) = (TRUE_K, TRUE_H, 4.0);
    let p = std::f64::consts::PI * DIAMETER_M;
    let a = p * DIAMETER_M / 4.0;
    let m = (h * p / (k * a)).sqrt();
    let r = h / (m * k);
    let exact = |x: f64| {
        let u = m * (LENGTH_M - x);
        q / (k * a * m) * (u.cosh() + r * u.sinh())
            / ((m * LENGTH_M).sinh() + r * (m * LENGTH_M).cosh())
    };
    let s = scenario(q);
    let mut errors = Vec::new();
    for cells in [30, 60, 120] {
        let sim = RodSimulator { cells };
        let t = sim.solve(&s, k, h);
        let err = (0..=cells)
            .map(|i| {
                let x = LENGTH_M * i as f64 / cells as f64;
                ((t[i] - s.ambient_c) - exact(x)).abs() / exact(0.0)
            })
            .fold(0.0, f64::max);
        errors.push(err);
    }
    assert!(errors[2] < 1e-4, "errors {errors:?}");
    // Second order: halving the cell size divides the error by about four.
    for w in errors.windows(2) {
        let ratio = w[0] / w[1];
        assert!((3.5..4.5).contains(&ratio), "errors {errors:?}");
    }
}

#[test]
fn surrogate_gradient_matches_finite_differences() {
    let sim = RodSimulator { cells: CELLS };
    let scenarios = vec![scenario(2.0), scenario(6.0)];
    // Fit on a few real runs so the learned correction is not trivial.
    let mut samples = Vec::new();
    for (i, s) in scenarios.iter().enumerate() {
        for &(k, h) in &[(40.0, 5.0), (150.0, 20.0), (300.0, 40.0)] {
            samples.push(Sample {
                snapshot: i,
                params: vec![k, h],
                outputs: sim.evaluate(s, &[k, h]).unwrap().values,
                weight: 1.0,
            });
        }
    }
    let mut sur = FinSurrogate::default();
    sur.fit(
        TrainingSet {
            scenarios: &scenarios,
            samples: &samples,
        },
        0,
    )
    .unwrap();
    assert!(sur.correction.iter().any(|&(c, d)| c != 0.0 || d != 0.0));
    let cot = [0.3, -1.1, 0.7, 2.0, -0.4];
    let f = |s: &RodScenario, p: &[f64]| -> f64 {
        sur.predict(s, p).iter().zip(&cot).map(|(y, c)| y * c).sum()
    };
    for s in &scenarios {
        for &(k, h) in &[(25.0, 3.0), (120.0, 15.0), (380.0, 55.0)] {
            let g = sur.vjp(s, &[k, h], &cot);
            for (i, step) in [(0, k * 1e-6), (1, h * 1e-6)] {
                let mut hi = [k, h];
                let mut lo = [k, h];
                hi[i] += step;
                lo[i] -= step;
                let fd = (f(s, &hi) - f(s, &lo)) / (2.0 * step);
                let tol = 1e-6 * fd.abs().max(1e-3);
                assert!(
                    (g[i] - fd).abs() < tol,
                    "d/dp{i} at ({k}, {h}): {} vs {fd}",
                    g[i]
                );
            }
        }
    }
}

#[test]
fn calibration_recovers_k_and_h_within_2_percent_in_10_runs() {
    for seed in 0..12 {
        let o = run(seed).unwrap();
        let k_err = (o.k_w_per_m_k - TRUE_K).abs() / TRUE_K;
        let h_err = (o.h_w_per_m2_k - TRUE_H).abs() / TRUE_H;
        eprintln!(
        "seed {seed}: k {:.3} ({:.3}%), h {:.3} ({:.3}%), runs/condition after design {}, MAE {:.4} K (initial {:.3} K)",
        o.k_w_per_m_k,
        100.0 * k_err,
        o.h_w_per_m2_k,
        100.0 * h_err,
        o.runs_after_design,
        o.mae_c,
        o.initial_mae_c
    );
        assert!(k_err < 0.02, "k {} vs {TRUE_K}", o.k_w_per_m_k);
        assert!(h_err < 0.02, "h {} vs {TRUE_H}", o.h_w_per_m2_k);
        assert!(o.runs_after_design <= 10, "{} runs", o.runs_after_design);
        // The calibrated model sits at the noise level (E|noise| = 0.8 sigma).
        assert!(o.mae_c < 1.5 * NOISE_C, "MAE {}", o.mae_c);
        assert!(o.initial_mae_c > 10.0 * o.mae_c);
    }
}
