//! The loop's polish stage: Levenberg-Marquardt steps on the model itself after the
//! four-step iterations. It closes the gap a surrogate leaves, counts and journals its
//! runs like the loop's, stays within the run budget, and replays from the journal.

mod common;

use common::*;
use kalibre_core::calibrate::{UncertaintySlopes, REPEATED_RESIDUAL_ICC};
use kalibre_core::{
    Calibrator, Objective, Observations, OutputInfo, ParamSpace, Report, Result, RunStore, Scale,
    SearchOutcome, Searcher, Settings, Snapshot, StopReason,
};

fn run(polish: usize, budget: Option<usize>, store: Option<RunStore>) -> (Report, usize) {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let settings = Settings {
        seed: 5,
        max_iterations: 1,
        polish_iterations: polish,
        max_model_runs: budget,
        ..Settings::default()
    };
    let mut cal =
        Calibrator::new(&model, QuadSurface::default(), &obs, &space).with_settings(settings);
    if let Some(s) = store {
        cal = cal.with_store(s);
    }
    let report = cal.run().unwrap();
    (report, model.calls())
}

#[test]
fn polish_reaches_the_least_squares_optimum_the_loop_stopped_short_of() {
    let (loop_only, _) = run(0, None, None);
    let (polished, calls) = run(10, None, None);
    assert!(
        loop_only.best.mae_c > 1e-3,
        "loop alone {}",
        loop_only.best.mae_c
    );
    // Forward differences make the Jacobian inexact, so convergence is linear: ten steps
    // take the error down by two orders of magnitude or more, not to round-off.
    assert!(
        polished.best.mae_c < 1e-5 && polished.best.mae_c < loop_only.best.mae_c / 100.0,
        "polished {} from {}",
        polished.best.mae_c,
        loop_only.best.mae_c
    );
    for (name, truth) in ["a", "b"].iter().zip(TRUTH) {
        let got = polished.best.params.get(name).unwrap();
        assert!((got - truth).abs() < 1e-4, "{name}: {got} vs {truth}");
    }
    // Every run counted, polish records numbered after the loop's, no surrogate fit.
    assert_eq!(calls, polished.runs.total);
    assert_eq!(polished.history[0].iteration, 1);
    let steps = &polished.history[1..];
    assert!(!steps.is_empty());
    for (k, h) in steps.iter().enumerate() {
        assert!(
            h.iteration > 1 + k,
            "iterations increase: {:?}",
            h.iteration
        );
        assert_eq!(h.training_samples, 0);
        assert!(h.fit_mse.is_nan());
    }
    // Each best-so-far never rises.
    let best: Vec<f64> = polished
        .history
        .iter()
        .filter_map(|h| h.best_mae_c)
        .collect();
    assert!(best.windows(2).all(|w| w[1] <= w[0]), "{best:?}");
    // The summary's "found in": a polish record, or a point the polish ran between its
    // records (a finite-difference probe, numbered but with no record of its own).
    let said = |iteration: usize| {
        let mut r = polished.clone();
        r.best.iteration = iteration;
        r.best_found_in()
    };
    let loop_said = "the polish, after the loop's 1 iteration";
    assert_eq!(said(steps[0].iteration), loop_said);
    let gap = (2..).find(|i| polished.history.iter().all(|h| h.iteration != *i));
    assert_eq!(said(gap.unwrap()), loop_said);
    assert_eq!(said(1), "iteration 1");
    assert_eq!(said(0), "the initial design");
}

#[test]
fn polish_stays_within_the_run_budget() {
    // Design 8 + loop 2 = 10 runs; a Jacobian needs (2 + 1) x 2 = 6 more, a step 2.
    for budget in [10, 15, 16, 18, 23] {
        let (r, calls) = run(10, Some(budget), None);
        assert!(
            r.runs.total <= budget,
            "budget {budget}: {} runs",
            r.runs.total
        );
        assert_eq!(calls, r.runs.total);
    }
    let (r, _) = run(10, Some(15), None);
    assert_eq!(r.history.len(), 1, "no room for a Jacobian: no polish step");
    // The loop stopped at its iteration limit, but the budget is why the calibration
    // stopped where it did: the report says so (it said MaxIterations).
    assert_eq!(r.stop_reason, StopReason::ModelRunBudget);
    // With room for every step the loop's own reason stands.
    let (r, _) = run(3, None, None);
    assert_eq!(r.stop_reason, StopReason::MaxIterations);
}

#[test]
fn polish_runs_replay_from_the_journal() {
    let dir = temp_dir("polish-journal");
    let path = dir.join("runs.jsonl");
    let (first, calls) = run(6, None, Some(RunStore::open(&path, "poly-v1").unwrap()));
    assert_eq!(calls, first.runs.total);
    let (second, calls) = run(6, None, Some(RunStore::open(&path, "poly-v1").unwrap()));
    assert_eq!(calls, 0, "every run replayed");
    assert_eq!(second.runs.cached, second.runs.total);
    assert_eq!(best_bits(&first), best_bits(&second));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_uncertainty_takes_the_models_own_slopes_where_its_runs_measure_them() {
    // Measurements with +-0.05 of noise, so that the spread is not zero.
    let noisy = observations_with(&[1.0, 2.0], |id, k, y| {
        let e = if (id + k) % 2 == 0 { 0.05 } else { -0.05 };
        (!(id == 1 && k == 3)).then_some(y + e)
    });
    let (model, space) = (Poly::new(), space());
    let report = |polish| {
        Calibrator::new(&model, QuadSurface::default(), &noisy, &space)
            .with_settings(Settings {
                seed: 5,
                max_iterations: 1,
                polish_iterations: polish,
                ..Settings::default()
            })
            .run()
            .unwrap()
    };
    let polished = report(10);
    assert_eq!(
        polished.uncertainty_slopes,
        Some(UncertaintySlopes::ModelFiniteDifferences)
    );
    // The Gauss-Newton spread from the model's exact Jacobian at the best run (unit box:
    // a spans 4, b 2.5; the box as a unit prior).
    let (a, b) = (
        polished.best.params.get("a").unwrap(),
        polished.best.params.get("b").unwrap(),
    );
    let (mut jtj, mut rss, mut m) = ([[0.0; 2]; 2], 0.0, 0);
    for snap in noisy.snapshots() {
        let load = snap.scenario.load;
        let y = poly_outputs(load, &[a, b]);
        let slopes = [[load, 1.0], [b, a], [-1.0, 2.0 * load * b], [a, 0.0]];
        for ((meas, y), g) in snap.measured.iter().zip(&y).zip(slopes) {
            let Some(meas) = meas else { continue };
            let g = [g[0] * 4.0, g[1] * 2.5];
            for i in 0..2 {
                for j in 0..2 {
                    jtj[i][j] += g[i] * g[j];
                }
            }
            rss += (y - meas).powi(2);
            m += 1;
        }
    }
    let s2 = rss / (m - 2) as f64;
    let f = [
        [jtj[0][0] / s2 + 1.0, jtj[0][1] / s2],
        [jtj[1][0] / s2, jtj[1][1] / s2 + 1.0],
    ];
    let det = f[0][0] * f[1][1] - f[0][1] * f[1][0];
    let want = [(f[1][1] / det).sqrt() * 4.0, (f[0][0] / det).sqrt() * 2.5];
    for (u, w) in polished.uncertainty.iter().zip(want) {
        let got = u.std.unwrap();
        assert!((got - w).abs() <= 0.03 * w, "{}: {got} vs {w}", u.name);
    }
    // One loop iteration and no polish: five points, too few for a local fit of the
    // model's runs, so the surrogate's slopes.
    assert_eq!(
        report(0).uncertainty_slopes,
        Some(UncertaintySlopes::Surrogate)
    );
}

#[test]
fn the_report_says_when_the_residual_repeats_at_the_same_outputs() {
    let (model, space) = (Poly::new(), space());
    let icc = |obs: &kalibre_core::Observations<Scen>| {
        Calibrator::new(&model, QuadSurface::default(), obs, &space)
            .with_settings(Settings {
                seed: 5,
                max_iterations: 2,
                polish_iterations: 10,
                ..Settings::default()
            })
            .run()
            .unwrap()
            .residual_icc
            .expect("two snapshots")
    };
    // Each output off by its own amount in both snapshots: a model error.
    let repeated = observations_with(&[1.0, 2.0], |id, k, y| {
        (!(id == 1 && k == 3)).then_some(y + [0.3, -0.2, 0.25, -0.3][k])
    });
    let r = icc(&repeated);
    assert!(r > REPEATED_RESIDUAL_ICC, "{r}");
    // Errors that change sign between the snapshots: noise.
    let noisy = observations_with(&[1.0, 2.0], |id, k, y| {
        let e = if (id + k) % 2 == 0 { 0.05 } else { -0.05 };
        (!(id == 1 && k == 3)).then_some(y + e)
    });
    let r = icc(&noisy);
    assert!(r < REPEATED_RESIDUAL_ICC, "{r}");
}

/// A model that fails just beyond the truth (`a > 1.75`, truth 1.7): once the best point
/// is within a difference step of the edge, the forward difference in `a` fails. The
/// polish takes it on the other side instead of leaving `a` where it is, and reaches the
/// truth (it stalled at a = 1.718, MAE 0.023, taking a zero slope for `a`).
#[test]
fn a_difference_that_fails_is_taken_on_the_other_side() {
    let model = Poly::failing(FailZone {
        a_err: 1.75,
        b_nan: f64::NEG_INFINITY,
    });
    let (obs, space) = (observations(), space());
    let settings = Settings {
        seed: 5,
        max_iterations: 1,
        polish_iterations: 10,
        ..Settings::default()
    };
    let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_settings(settings)
        .run()
        .unwrap();
    assert!(
        report.runs.failed > 0,
        "the edge was reached: {:?}",
        report.runs
    );
    assert!(report.best.mae_c < 1e-4, "best MAE {}", report.best.mae_c);
    for (name, truth) in ["a", "b"].iter().zip(TRUTH) {
        let got = report.best.params.get(name).unwrap();
        assert!((got - truth).abs() < 1e-3, "{name}: {got} vs {truth}");
    }
}

/// Proposes the point it starts from: the loop converges at once, and the polish
/// linearises at the design's best.
struct StayPut;

impl Searcher for StayPut {
    fn search(&self, objective: &dyn Objective, start: &[f64], _: u64) -> Result<SearchOutcome> {
        Ok(SearchOutcome {
            best_unit: start.to_vec(),
            best_cost: objective.cost(start),
            evaluations: 1,
            trace: Vec::new(),
            timed_out: false,
        })
    }
}

/// `best.iteration` is 0 (the design) or the number of the history record of the best
/// point itself.
fn assert_best_has_its_record(r: &Report) {
    let its = r.history.iter().find(|h| h.iteration == r.best.iteration);
    assert!(
        r.best.iteration == 0
            || its.is_some_and(|h| h.params == r.best.params && h.mae_c == Some(r.best.mae_c)),
        "best at {} ({:?}) has no record of its own: {:?}",
        r.best.iteration,
        r.best.params,
        r.history.iter().map(|h| h.iteration).collect::<Vec<_>>()
    );
    let numbers: Vec<usize> = r.history.iter().map(|h| h.iteration).collect();
    assert!(numbers.windows(2).all(|w| w[0] < w[1]), "{numbers:?}");
}

/// The truth one finite-difference step (0.01 of the box in `a`) from the design's
/// midpoint, where the polish linearises first: its first Jacobian run is the best
/// point, exactly, and the report names it by a record of its own (it named an
/// iteration without one).
#[test]
fn the_best_iteration_names_a_record_even_for_a_difference_run() {
    let model = Poly::new();
    let space = ParamSpace::new()
        .with("a", 0.0, 4.0, 2.0, Scale::Linear)
        .unwrap()
        .with("b", 0.5, 3.0, 1.75, Scale::Linear)
        .unwrap();
    let truth = space.from_unit(&[0.5 + 0.01, 0.5]).unwrap();
    let outputs = (0..4)
        .map(|k| OutputInfo {
            name: format!("s{k}"),
            group: "cold".into(),
        })
        .collect();
    let snaps = [1.0, 2.0]
        .iter()
        .enumerate()
        .map(|(id, &load)| Snapshot {
            label: format!("t{id}"),
            scenario: Scen { id, load },
            measured: poly_outputs(load, &truth).into_iter().map(Some).collect(),
        })
        .collect();
    let obs = Observations::new(outputs, snaps).unwrap();
    let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_searcher(StayPut)
        .with_settings(Settings {
            seed: 5,
            max_iterations: 1,
            polish_iterations: 3,
            ..Settings::default()
        })
        .run()
        .unwrap();
    assert_eq!(report.best.mae_c, 0.0, "the difference run hit the truth");
    assert_eq!(report.best.params.values(), truth);
    assert_best_has_its_record(&report);
    let rec = (report.history.iter())
        .find(|h| h.iteration == report.best.iteration)
        .unwrap();
    assert_eq!(rec.training_samples, 0, "a polish record");
    assert!(report.best_found_in().starts_with("the polish"));
    // And in the ordinary polish too.
    let (polished, _) = run(10, None, None);
    assert_best_has_its_record(&polished);
}
