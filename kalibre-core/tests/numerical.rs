//! The model's numerical variants (`Calibrator::with_numerical_variant`): run once per
//! snapshot at the best parameters, their change of the outputs becomes each parameter's
//! numerical uncertainty, a failed variant is recorded rather than fatal, and the report
//! round-trips through JSON.

mod common;

use common::*;
use kalibre_core::{Calibrator, Model, ModelError, Outputs, Report, Settings};

/// The analytic model with `a` read `da` too high: a variant whose numerics move `a`
/// alone, by `da`.
struct Shifted {
    da: f64,
}

impl Model for Shifted {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        format!("poly-shifted-{}", self.da)
    }
    fn evaluate(&self, scenario: &Scen, params: &[f64]) -> Result<Outputs, ModelError> {
        Ok(poly_outputs(scenario.load, &[params[0] + self.da, params[1]]).into())
    }
}

fn calibrate(variants: &[(&str, &Shifted)]) -> Report {
    let (model, obs, space) = (Shifted { da: 0.0 }, observations(), space());
    let settings = Settings {
        seed: 5,
        max_iterations: 1,
        polish_iterations: 10,
        ..Settings::default()
    };
    let mut cal =
        Calibrator::new(&model, QuadSurface::default(), &obs, &space).with_settings(settings);
    for (name, v) in variants {
        cal = cal.with_numerical_variant(*name, *v);
    }
    cal.run().unwrap()
}

#[test]
fn a_variant_that_reads_a_higher_moves_a_by_as_much_and_b_not_at_all() {
    let plain = calibrate(&[]);
    assert!(plain.numerical_checks.is_empty());
    assert!(plain.uncertainty.iter().all(|u| u.numerical.is_none()));
    assert!(
        plain.uncertainty.iter().all(|u| u.identified),
        "{:?}",
        plain.uncertainty
    );

    // Reading a 0.1 higher is what a 0.1 lower a gives: a moves by about 0.1 (6% of
    // 1.7, still identified); 0.3 (18%) is too far to claim a.
    let small = Shifted { da: 0.1 };
    let large = Shifted { da: -0.3 };
    let r = calibrate(&[("small", &small), ("large", &large)]);
    assert_eq!(
        r.best.params, plain.best.params,
        "the variants change no run"
    );
    let (a, b) = (&r.uncertainty[0], &r.uncertainty[1]);
    assert!((a.numerical.unwrap() - 0.3).abs() < 0.03, "{a:?}");
    assert!(b.numerical.unwrap() < 0.03, "{b:?}");
    assert!(!a.identified && b.identified, "{:?}", r.uncertainty);
    let r_small = calibrate(&[("small", &small)]);
    let a_small = &r_small.uncertainty[0];
    assert!(
        (a_small.numerical.unwrap() - 0.1).abs() < 0.01,
        "{a_small:?}"
    );
    assert!(a_small.identified, "{a_small:?}");
    // What each variant changed, over the measured outputs.
    assert_eq!(r.numerical_checks.len(), 2);
    assert_eq!(r.numerical_checks[0].variant, "small");
    let change = r.numerical_checks[0].mean_abs_change.unwrap();
    assert!(change > 0.01 && change < 1.0, "{change}");
    assert!(r.numerical_checks.iter().all(|c| c.error.is_none()));

    // The report round-trips with its checks.
    let json = serde_json::to_string(&r).unwrap();
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back.numerical_checks, r.numerical_checks);
    assert_eq!(back.uncertainty, r.uncertainty);
}

/// A variant that fails on every run.
struct Broken;

impl Model for Broken {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        "broken".into()
    }
    fn evaluate(&self, _: &Scen, _: &[f64]) -> Result<Outputs, ModelError> {
        Err(ModelError::failed("out of memory on the finer grid"))
    }
}

#[test]
fn a_failed_variant_is_recorded_and_the_calibration_stands() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let settings = Settings {
        seed: 5,
        max_iterations: 1,
        polish_iterations: 10,
        ..Settings::default()
    };
    // `with_numerical_variant` takes the model's own type; a failing one through an enum.
    enum Either {
        Good(Poly),
        Bad(Broken),
    }
    impl Model for Either {
        type Scenario = Scen;
        fn fingerprint(&self) -> String {
            match self {
                Either::Good(m) => m.fingerprint(),
                Either::Bad(m) => m.fingerprint(),
            }
        }
        fn evaluate(&self, s: &Scen, p: &[f64]) -> Result<Outputs, ModelError> {
            match self {
                Either::Good(m) => m.evaluate(s, p),
                Either::Bad(m) => m.evaluate(s, p),
            }
        }
    }
    let (good, bad) = (Either::Good(model), Either::Bad(Broken));
    let r = Calibrator::new(&good, QuadSurface::default(), &obs, &space)
        .with_settings(settings)
        .with_numerical_variant("finer grid", &bad)
        .with_unavailable_numerical_variant("grid 0.16 m", "a tile lies under a rack")
        .run()
        .unwrap();
    assert_eq!(r.numerical_checks.len(), 2);
    let c = &r.numerical_checks[0];
    assert_eq!(c.mean_abs_change, None);
    let e = c.error.as_deref().unwrap();
    assert!(e.contains("out of memory") && e.contains("snapshot"), "{e}");
    let c = &r.numerical_checks[1];
    assert_eq!(c.variant, "grid 0.16 m");
    assert_eq!(
        c.error.as_deref(),
        Some("not set up: a tile lies under a rack")
    );
    assert!(r.uncertainty.iter().all(|u| u.numerical.is_none()));
    assert!(r.best.mae_c < 1e-4);
}

/// The analytic model reading output `s0` `bias` higher: a finer grid that sees what the
/// measurements see there.
struct Biased {
    bias: f64,
}

impl Model for Biased {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        format!("poly-biased-{}", self.bias)
    }
    fn evaluate(&self, scenario: &Scen, params: &[f64]) -> Result<Outputs, ModelError> {
        let mut y = poly_outputs(scenario.load, params);
        y[0] += self.bias;
        Ok(y.into())
    }
}

/// Calibrates the unbiased model against readings 0.6 higher at `s0` (and a little
/// noise), with the biased model as its numerical variant.
fn calibrate_against_biased_readings(weighting: bool) -> Report {
    let obs = observations_with(&[1.0, 2.0, 3.0], |id, k, y| {
        let noise = 0.01 * if (id + k) % 2 == 0 { 1.0 } else { -1.0 };
        Some(y + noise + if k == 0 { 0.6 } else { 0.0 })
    });
    let (coarse, fine, space) = (Biased { bias: 0.0 }, Biased { bias: 0.6 }, space());
    let settings = Settings {
        seed: 5,
        max_iterations: 2,
        polish_iterations: 10,
        numerical_weighting: weighting,
        ..Settings::default()
    };
    let mut cal = Calibrator::new(&coarse, QuadSurface::default(), &obs, &space)
        .with_settings(settings)
        .with_numerical_variant("finer grid", &fine);
    cal.run().unwrap()
}

#[test]
fn weighing_outputs_by_their_numerics_keeps_a_grid_error_out_of_the_parameters() {
    let plain = calibrate_against_biased_readings(false);
    let weighted = calibrate_against_biased_readings(true);
    let err = |r: &Report| -> f64 {
        ["a", "b"]
            .iter()
            .zip(TRUTH)
            .map(|(n, t)| (r.best.params.get(n).unwrap() - t).abs())
            .fold(0.0, f64::max)
    };
    // Least squares spreads the grid's 0.6 at s0 over both parameters; weighted, s0
    // counts for little and the rest of the outputs set them.
    assert!(err(&plain) > 0.05, "plain {:?}", plain.best.params);
    assert!(err(&weighted) < 0.02, "weighted {:?}", weighted.best.params);
    // Weighted, the grid's error stays in the residuals at s0, where it belongs.
    for r in weighted.residuals.iter().filter(|r| r.sensor == "s0") {
        let left = r.measured_c - r.predicted_c;
        assert!((left - 0.6).abs() < 0.05, "{r:?}");
    }
    // The same variant ran once (at the loop's best, before the polish) or again at the
    // polished point: either way the report lists it once.
    assert_eq!(weighted.numerical_checks.len(), 1);
    assert!(weighted.numerical_checks[0].error.is_none());
}

/// Poly that counts its runs and sleeps `sleep_ms` in each one after the first
/// `fast_runs`.
struct Timed {
    fast_runs: usize,
    sleep_ms: u64,
    calls: std::sync::atomic::AtomicUsize,
}

impl Timed {
    fn new(fast_runs: usize, sleep_ms: u64) -> Self {
        let calls = std::sync::atomic::AtomicUsize::new(0);
        Timed {
            fast_runs,
            sleep_ms,
            calls,
        }
    }

    fn calls(&self) -> usize {
        self.calls.load(std::sync::atomic::Ordering::SeqCst)
    }
}

impl Model for Timed {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        "poly-timed".into()
    }
    fn evaluate(&self, s: &Scen, p: &[f64]) -> Result<Outputs, ModelError> {
        let k = self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        if k >= self.fast_runs {
            std::thread::sleep(std::time::Duration::from_millis(self.sleep_ms));
        }
        Poly::new().evaluate(s, p)
    }
}

/// Past the wall budget the variants (a finer grid's runs, the costliest of all) are not
/// run, and the report says why: they used to run whatever the budget.
#[test]
fn variants_are_not_run_past_the_wall_budget() {
    let (obs, space) = (observations(), space());
    let settings = |max_wall_s| Settings {
        seed: 5,
        max_iterations: 3,
        polish_iterations: 0,
        max_wall_s,
        ..Settings::default()
    };
    // The design's runs are fast; the first iteration's take 1 s each, past the budget.
    let design_runs = Calibrator::new(&Poly::new(), QuadSurface::default(), &obs, &space)
        .with_settings(settings(None))
        .run()
        .unwrap()
        .initial
        .design_runs;
    let (model, variant) = (Timed::new(design_runs, 1000), Timed::new(usize::MAX, 0));
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_settings(settings(Some(0.5)))
        .with_numerical_variant("finer grid", &variant)
        .run()
        .unwrap();
    assert_eq!(r.history.len(), 1, "one iteration, then the budget");
    assert_eq!(variant.calls(), 0);
    let check = &r.numerical_checks[0];
    assert_eq!(
        check.error.as_deref(),
        Some(kalibre_core::calibrate::SKIPPED_PAST_WALL)
    );
    assert_eq!(
        check.describe(),
        "finer grid: not run: the wall-time budget (max_wall_s) had passed"
    );
    // With time to spare they run, once per snapshot.
    let (model, variant) = (Timed::new(usize::MAX, 0), Timed::new(usize::MAX, 0));
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_settings(settings(Some(600.0)))
        .with_numerical_variant("finer grid", &variant)
        .run()
        .unwrap();
    assert_eq!(variant.calls(), obs.snapshots().len());
    assert!(r.numerical_checks[0].error.is_none());
}

/// A prior that costs 10 per unit of `a` above `limit`.
struct AtMost {
    limit: f64,
}

impl kalibre_core::Regularizer for AtMost {
    fn value_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
        let over = (p[0] - self.limit).max(0.0);
        (10.0 * over, vec![if over > 0.0 { 10.0 } else { 0.0 }, 0.0])
    }
}

/// The weighted polish accepts a step by its weighted misfit plus the prior, as every
/// other run is judged: with a prior that rules out `a` above 1.5 (truth 1.7), the
/// polish does not carry the best point to the truth past it, where the misfit alone
/// would take it.
#[test]
fn the_weighted_polish_is_judged_with_the_prior_too() {
    let obs = observations_with(&[1.0, 2.0, 3.0], |id, k, y| {
        let noise = 0.01 * if (id + k) % 2 == 0 { 1.0 } else { -1.0 };
        Some(y + noise + if k == 0 { 0.6 } else { 0.0 })
    });
    let (coarse, fine, space) = (Biased { bias: 0.0 }, Biased { bias: 0.6 }, space());
    let prior = AtMost { limit: 1.5 };
    let settings = Settings {
        seed: 5,
        max_iterations: 2,
        polish_iterations: 10,
        numerical_weighting: true,
        prior_in_best: true,
        ..Settings::default()
    };
    let report = Calibrator::new(&coarse, QuadSurface::default(), &obs, &space)
        .with_settings(settings)
        .with_regularizer(&prior, 1.0)
        .with_numerical_variant("finer grid", &fine)
        .run()
        .unwrap();
    let a = report.best.params.get("a").unwrap();
    assert!(a < 1.55, "a = {a}: {:?}", report.best);
}
