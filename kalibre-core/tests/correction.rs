//! The search's output correction: the linear term's gradient against finite
//! differences, its interpolation of nearby runs, what it buys the loop over the
//! zero-order correction when the surrogate's form is wrong, and its settings' checks.

mod common;

use common::*;
use kalibre_core::search::{Hybrid, Objective, OutputCorrection, ProjectedGradient, Searcher};
use kalibre_core::{
    Calibrator, Error, FitSummary, Settings, Surrogate, SurrogateObjective, TrainingSet,
};

/// A surrogate of the wrong form: linear in the parameters (the model has `a b`, `b²`
/// and `a²` terms), fitted by least squares per snapshot and output.
#[derive(Debug, Clone, Default)]
struct Plane {
    coef: Vec<Vec<[f64; 3]>>,
}

impl Surrogate for Plane {
    type Scenario = Scen;

    fn fit(&mut self, data: TrainingSet<'_, Scen>, _seed: u64) -> kalibre_core::Result<FitSummary> {
        let n_out = data.samples[0].outputs.len();
        self.coef = vec![vec![[0.0; 3]; n_out]; data.scenarios.len()];
        for (s, coef) in self.coef.iter_mut().enumerate() {
            for (k, w) in coef.iter_mut().enumerate() {
                let mut m = [[0.0; 3]; 3];
                let mut r = [0.0; 3];
                for smp in data.samples.iter().filter(|x| x.snapshot == s) {
                    let f = [1.0, smp.params[0], smp.params[1]];
                    for i in 0..3 {
                        for j in 0..3 {
                            m[i][j] += smp.weight * f[i] * f[j];
                        }
                        r[i] += smp.weight * f[i] * smp.outputs[k];
                    }
                }
                for (i, row) in m.iter_mut().enumerate() {
                    row[i] += 1e-6;
                }
                *w = solve3(m, r);
            }
        }
        Ok(FitSummary {
            timed_out: false,
            train_mse: 0.0,
            epochs: 1,
        })
    }

    fn predict(&self, scenario: &Scen, params: &[f64]) -> Vec<f64> {
        self.coef[scenario.id]
            .iter()
            .map(|w| w[0] + w[1] * params[0] + w[2] * params[1])
            .collect()
    }

    fn vjp(&self, scenario: &Scen, _params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        let mut g = vec![0.0; 2];
        for (w, c) in self.coef[scenario.id].iter().zip(cotangent) {
            g[0] += c * w[1];
            g[1] += c * w[2];
        }
        g
    }
}

fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> [f64; 3] {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    let mut x = [0.0; 3];
    for (c, xc) in x.iter_mut().enumerate() {
        let mut mc = m;
        for i in 0..3 {
            mc[i][c] = r[i];
        }
        *xc = det(mc) / d;
    }
    x
}

/// Model minus surrogate per snapshot and output at a unit point.
fn discrepancy(sur: &Plane, u: &[f64]) -> Vec<Vec<f64>> {
    let (obs, space) = (observations(), space());
    let p = space.from_unit(u).unwrap();
    obs.snapshots()
        .iter()
        .map(|s| {
            let m = poly_outputs(s.scenario.load, &p);
            let su = sur.predict(&s.scenario, &p);
            m.iter().zip(su).map(|(a, b)| a - b).collect()
        })
        .collect()
}

fn fitted_plane() -> Plane {
    let (obs, space) = (observations(), space());
    let scenarios: Vec<Scen> = obs.snapshots().iter().map(|s| s.scenario.clone()).collect();
    let mut samples = Vec::new();
    for u in [[0.1, 0.1], [0.9, 0.2], [0.3, 0.8], [0.6, 0.6]] {
        let p = space.from_unit(&u).unwrap();
        for (i, s) in scenarios.iter().enumerate() {
            samples.push(kalibre_core::Sample {
                snapshot: i,
                params: p.clone(),
                outputs: poly_outputs(s.load, &p),
                weight: 1.0,
            });
        }
    }
    let mut sur = Plane::default();
    sur.fit(
        TrainingSet {
            scenarios: &scenarios,
            samples: &samples,
        },
        0,
    )
    .unwrap();
    sur
}

fn linear_correction(
    sur: &Plane,
    anchor: [f64; 2],
    others: &[[f64; 2]],
    ridge_rel: f64,
) -> OutputCorrection {
    let runs: Vec<(Vec<f64>, Vec<Vec<f64>>)> = others
        .iter()
        .map(|u| (u.to_vec(), discrepancy(sur, u)))
        .collect();
    OutputCorrection::fit(&anchor, discrepancy(sur, &anchor), &runs, 0.05, ridge_rel)
}

#[test]
fn corrected_objective_gradient_matches_finite_differences() {
    let (obs, space) = (observations(), space());
    let sur = fitted_plane();
    let corr = linear_correction(&sur, [0.4, 0.5], &[[0.43, 0.5], [0.41, 0.47]], 1e-2);
    assert_eq!(corr.directions(), 2);
    let objective = SurrogateObjective::new(&sur, &obs, &space).with_correction(corr);
    for x in [[0.4, 0.5], [0.2, 0.7], [0.75, 0.35]] {
        let (c, g) = objective.cost_and_gradient(&x);
        assert!((c - objective.cost(&x)).abs() <= 1e-12 * c.abs().max(1.0));
        for i in 0..2 {
            let h = 1e-6;
            let (mut p, mut m) = (x, x);
            p[i] += h;
            m[i] -= h;
            let fd = (objective.cost(&p) - objective.cost(&m)) / (2.0 * h);
            assert!(
                (fd - g[i]).abs() <= 1e-5 * fd.abs().max(1.0),
                "at {x:?}, coordinate {i}: finite difference {fd}, gradient {}",
                g[i]
            );
        }
    }
}

#[test]
fn the_corrected_surrogate_matches_the_model_at_the_anchor_and_near_runs() {
    let sur = fitted_plane();
    let anchor = [0.4, 0.5];
    let near = [[0.43, 0.5], [0.41, 0.47]];
    // With two runs in two dimensions and a negligible ridge the fit interpolates them.
    let corr = linear_correction(&sur, anchor, &near, 1e-10);
    let obs = observations();
    let space = space();
    for u in std::iter::once(anchor).chain(near) {
        let p = space.from_unit(&u).unwrap();
        let e = discrepancy(&sur, &u);
        let e0 = discrepancy(&sur, &anchor);
        for (s, snap) in obs.snapshots().iter().enumerate() {
            let model = poly_outputs(snap.scenario.load, &p);
            let pred = sur.predict(&snap.scenario, &p);
            for k in 0..model.len() {
                let corrected = pred[k] + corr.value(s, k, &u);
                let tol = 1e-9 + 1e-6 * (e[s][k] - e0[s][k]).abs();
                assert!(
                    (corrected - model[k]).abs() <= tol,
                    "run {u:?}, snapshot {s}, output {k}: corrected {corrected} vs model {}",
                    model[k]
                );
            }
        }
    }
}

fn calibrate(settings: Settings) -> f64 {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let mut cal = Calibrator::new(&model, Plane::default(), &obs, &space).with_settings(settings);
    cal.run().unwrap().best.mae_c
}

#[test]
fn with_a_surrogate_of_the_wrong_form_the_linear_term_gets_closer_than_the_offsets() {
    let base = Settings {
        seed: 3,
        max_iterations: 8,
        output_correction: true,
        trust_region: Some(0.1),
        ..Settings::default()
    };
    let zero_order = calibrate(base.clone());
    let first_order = calibrate(Settings {
        linear_correction: true,
        stall_step: Some(0.01),
        ..base
    });
    assert!(
        first_order < 0.5 * zero_order,
        "MAE with the linear term {first_order}, offsets only {zero_order}"
    );
}

#[test]
fn correction_settings_are_checked() {
    let name = |s: Settings| match s.check() {
        Err(Error::InvalidSetting { name, .. }) => name,
        other => panic!("expected an invalid setting, got {other:?}"),
    };
    let ok = Settings {
        output_correction: true,
        linear_correction: true,
        stall_step: Some(0.01),
        ..Settings::default()
    };
    assert!(ok.check().is_ok());
    assert_eq!(
        name(Settings {
            output_correction: false,
            stall_step: None,
            ..ok.clone()
        }),
        "linear_correction"
    );
    assert_eq!(
        name(Settings {
            linear_correction: false,
            ..ok.clone()
        }),
        "stall_step"
    );
    for bad in [0.0, -0.1, 1.5, f64::NAN] {
        assert_eq!(
            name(Settings {
                stall_step: Some(bad),
                ..ok.clone()
            }),
            "stall_step"
        );
    }
    // Older reports have none of the three fields: they read as off.
    let mut json = serde_json::to_value(Settings::default()).unwrap();
    let map = json.as_object_mut().unwrap();
    map.remove("linear_correction");
    map.remove("stall_step");
    let back: Settings = serde_json::from_value(json).unwrap();
    assert!(!back.linear_correction && back.stall_step.is_none());
}

/// A narrow valley near its minimum: Adam's first steps overshoot it.
struct Valley;
impl Objective for Valley {
    fn dim(&self) -> usize {
        3
    }
    fn cost(&self, x: &[f64]) -> f64 {
        (x[0] - 0.5).powi(2) + 1e4 * (x[1] - 0.5 - 0.1 * x[0]).powi(2) + 30.0 * (x[2] - 0.4).powi(2)
    }
    fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
        let v = x[1] - 0.5 - 0.1 * x[0];
        (
            self.cost(x),
            vec![2.0 * (x[0] - 0.5) - 0.2e4 * v, 2e4 * v, 60.0 * (x[2] - 0.4)],
        )
    }
}

#[test]
fn the_hybrid_local_phase_takes_the_descent_adam_leaves() {
    let start = [0.45, 0.545, 0.41];
    let paper = Hybrid::default().with_local(ProjectedGradient::with_steps(0).unwrap());
    let two_phase = paper.search(&Valley, &start, 1).unwrap();
    let three_phase = Hybrid::default().search(&Valley, &start, 1).unwrap();
    // Measured (seed 1): two phases 1.3e-3, three phases 5.8e-4.
    assert!(
        three_phase.best_cost < 0.5 * two_phase.best_cost,
        "three phases {} (two phases {})",
        three_phase.best_cost,
        two_phase.best_cost
    );
    assert!(three_phase.trace.iter().any(|t| t.phase == "spg"));
    assert!(two_phase.trace.iter().all(|t| t.phase != "spg"));
}
