//! The loop end to end on a cheap analytic model: it finds the truth, counts its runs,
//! tells its observers, respects its budgets, rejects bad settings, and its report
//! round-trips through JSON with the contract's keys.

mod common;

use std::sync::atomic::{AtomicUsize, Ordering};

use common::*;
use kalibre_core::{Calibrator, Error, Event, Report, RunStore, Settings, StopReason};

fn calibrate(seed: u64) -> (Report, usize) {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_seed(seed)
        .with_max_iterations(10)
        .with_target_score(1e-3)
        .run()
        .unwrap();
    (report, model.calls())
}

#[test]
fn finds_the_truth_and_counts_runs() {
    let (r, calls) = calibrate(3);
    assert_eq!(r.stop_reason, StopReason::TargetError);
    for (name, truth) in ["a", "b"].iter().zip(TRUTH) {
        let got = r.best.params.get(name).unwrap();
        assert!((got - truth).abs() < 2e-3, "{name}: {got} vs {truth}");
    }
    assert!(r.best.mae_c <= 1e-3);
    assert!(r.best.iteration >= 1);
    // 4 design points (lower, upper, midpoint, initial) x 2 snapshots, then 2 per iteration.
    assert_eq!(r.initial.design_runs, 8);
    assert_eq!(r.runs.total, 8 + 2 * r.history.len());
    assert_eq!(
        (r.runs.new, r.runs.cached, r.runs.failed),
        (r.runs.total, 0, 0)
    );
    assert_eq!(calls, r.runs.total);
    for (i, h) in r.history.iter().enumerate() {
        assert_eq!(h.iteration, i + 1);
        assert_eq!(h.model_runs, 8 + 2 * (i + 1));
        assert_eq!(h.per_snapshot.len(), 2);
        assert_eq!(h.per_group.len(), 2);
    }
    // The first fit trains on 16 samples per design run, later ones on real runs only.
    assert_eq!(r.history[0].training_samples, 8 * 16);
    if r.history.len() > 1 {
        assert_eq!(r.history[1].training_samples, 10);
    }
    // The initial values are (1, 2): the model there is far off.
    assert!(r.initial.mae_c.unwrap() > 0.5);
    // Residuals of the best model: every measured value (4 + 3).
    assert_eq!(r.residuals.len(), 7);
    assert!(r
        .residuals
        .iter()
        .all(|x| (x.measured_c - x.predicted_c).abs() < 1e-2));
}

#[test]
fn observers_see_every_run_and_step() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let started = AtomicUsize::new(0);
    let finished = AtomicUsize::new(0);
    let fits = AtomicUsize::new(0);
    let searches = AtomicUsize::new(0);
    let iterations = AtomicUsize::new(0);
    let stopped = AtomicUsize::new(0);
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_max_iterations(3)
        .with_max_parallel_runs(2)
        .with_observer(|e: &Event<'_>| {
            let c = match e {
                Event::RunStarted { .. } => &started,
                Event::RunFinished { .. } => &finished,
                Event::FitDone { .. } => &fits,
                Event::SearchDone { .. } => &searches,
                Event::IterationDone { .. } => &iterations,
                Event::Stopped { .. } => &stopped,
                _ => return,
            };
            c.fetch_add(1, Ordering::SeqCst);
        })
        .run()
        .unwrap();
    assert_eq!(started.load(Ordering::SeqCst), r.runs.total);
    assert_eq!(finished.load(Ordering::SeqCst), r.runs.total);
    assert_eq!(iterations.load(Ordering::SeqCst), r.history.len());
    assert!(fits.load(Ordering::SeqCst) >= r.history.len());
    assert!(searches.load(Ordering::SeqCst) >= r.history.len());
    assert_eq!(stopped.load(Ordering::SeqCst), 1);
}

#[test]
fn stops_within_the_model_run_budget() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_max_iterations(50)
        .with_max_model_runs(13)
        .run()
        .unwrap();
    // Design 8, then two iterations of 2 runs; a third would need 14.
    assert_eq!(r.stop_reason, StopReason::ModelRunBudget);
    assert_eq!(r.runs.total, 12);
    assert_eq!(model.calls(), 12);
}

#[test]
fn report_round_trips_with_the_contract_keys() {
    let (r, _) = calibrate(5);
    let text = serde_json::to_string_pretty(&r).unwrap();
    let back: Report = serde_json::from_str(&text).unwrap();
    assert_eq!(back, r);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["schema"], "kalibre.report/1");
    assert!(v["best"]["iteration"].is_u64());
    assert!(v["best"]["mae_c"].is_f64());
    assert_eq!(v["best"]["params"]["a"].as_f64(), r.best.params.get("a"));
    assert!(v["initial"]["mae_c"].is_f64());
    let h = &v["history"][0];
    for key in ["iteration", "model_runs", "mae_c", "rmse_c", "max_abs_c"] {
        assert!(h[key].is_number(), "history key {key}");
    }
    assert!(h["per_snapshot"][0]["mae_c"].is_f64());
    assert!(h["per_group"]["hot"]["max_abs_c"].is_f64());
    let res = &v["residuals"][0];
    assert_eq!(res["snapshot"], "t0");
    assert_eq!(res["sensor"], "s0");
    assert!(res["measured_c"].is_f64() && res["predicted_c"].is_f64());
    assert_eq!(v["stop_reason"], "target_error");
    // A diverged fit writes null and still loads, as NaN.
    let mut diverged = r.clone();
    diverged.history[0].fit_mse = f64::NAN;
    let text2 = serde_json::to_string(&diverged).unwrap();
    assert!(text2.contains("\"fit_mse\":null"));
    let back2: Report = serde_json::from_str(&text2).unwrap();
    assert!(back2.history[0].fit_mse.is_nan());
    // Unknown keys are an error (a typo must not vanish).
    let typo = text.replacen("\"stop_reason\"", "\"stop_reasn\"", 1);
    assert!(serde_json::from_str::<Report>(&typo).is_err());
    // Parameters keep their order in the JSON object.
    let best = text.find("\"best\"").unwrap();
    assert!(text[best..].find("\"a\"").unwrap() < text[best..].find("\"b\"").unwrap());
}

fn setting_error(settings: Settings) -> String {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let err = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_settings(settings)
        .run()
        .unwrap_err();
    assert_eq!(
        model.calls(),
        0,
        "no model run before the settings are checked"
    );
    match err {
        Error::InvalidSetting { name, .. } => name,
        other => panic!("expected InvalidSetting, got {other}"),
    }
}

#[test]
fn bad_settings_are_rejected_by_name() {
    let d = Settings::default;
    let cases: Vec<(Settings, &str)> = vec![
        (
            Settings {
                max_iterations: 0,
                ..d()
            },
            "max_iterations",
        ),
        (
            Settings {
                target_score: Some(f64::NAN),
                ..d()
            },
            "target_score",
        ),
        (
            Settings {
                target_score: Some(-1.0),
                ..d()
            },
            "target_score",
        ),
        (
            Settings {
                max_model_runs: Some(0),
                ..d()
            },
            "max_model_runs",
        ),
        (
            Settings {
                max_model_runs: Some(7),
                ..d()
            },
            "max_model_runs",
        ),
        (
            Settings {
                max_wall_s: Some(0.0),
                ..d()
            },
            "max_wall_s",
        ),
        (
            Settings {
                max_parallel_runs: Some(0),
                ..d()
            },
            "max_parallel_runs",
        ),
        (
            Settings {
                augment_copies: 0,
                ..d()
            },
            "augment_copies",
        ),
        (
            Settings {
                augment_sigma: -0.1,
                ..d()
            },
            "augment_sigma",
        ),
        (
            Settings {
                regularizer_weight: f64::INFINITY,
                ..d()
            },
            "regularizer_weight",
        ),
        (
            Settings {
                duplicate_tol: f64::NAN,
                ..d()
            },
            "duplicate_tol",
        ),
        (
            Settings {
                perturb_sigma: 0.0,
                ..d()
            },
            "perturb_sigma",
        ),
    ];
    for (settings, expected) in cases {
        assert_eq!(setting_error(settings), expected);
    }
    assert!(Settings::default().check().is_ok());
}

#[test]
fn a_journal_of_another_model_is_refused() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let err = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_store(RunStore::in_memory("another-model"))
        .run()
        .unwrap_err();
    assert!(
        matches!(err, Error::Mismatch(ref m) if m.contains("another-model")),
        "{err}"
    );
    assert_eq!(model.calls(), 0);
}

/// Equal bounds everywhere leave nothing to calibrate: refused before any run, where
/// the loop used to run one point over and over from its store.
#[test]
fn a_space_with_every_parameter_fixed_is_refused() {
    let (model, obs) = (Poly::new(), observations());
    let space = kalibre_core::ParamSpace::new()
        .with("a", 1.0, 1.0, 1.0, kalibre_core::Scale::Linear)
        .unwrap()
        .with("b", 2.0, 2.0, 2.0, kalibre_core::Scale::Linear)
        .unwrap();
    let err = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .run()
        .unwrap_err();
    assert!(
        matches!(err, Error::Mismatch(ref m) if m == "every parameter has equal bounds (a, b): nothing to calibrate"),
        "{err}"
    );
    assert_eq!(model.calls(), 0);
}

/// Poly, naming its parameters and outputs as an external command does.
struct NamedPoly {
    params: [&'static str; 2],
    outputs: Vec<String>,
}

impl kalibre_core::Model for NamedPoly {
    type Scenario = Scen;

    fn fingerprint(&self) -> String {
        "poly-v1".into()
    }

    fn evaluate(
        &self,
        scenario: &Scen,
        params: &[f64],
    ) -> Result<kalibre_core::Outputs, kalibre_core::ModelError> {
        Poly::new().evaluate(scenario, params)
    }

    fn param_names(&self) -> Option<Vec<String>> {
        Some(self.params.iter().map(|s| s.to_string()).collect())
    }

    fn output_names(&self) -> Option<Vec<String>> {
        Some(self.outputs.clone())
    }
}

/// A model that names its parameters or outputs in another order than the space or the
/// observations is refused before any run: the values would reach it swapped.
#[test]
fn a_model_naming_its_parameters_or_outputs_otherwise_is_refused() {
    let (obs, space) = (observations(), space());
    let outputs = obs.output_names();
    let refusal = |model: NamedPoly| {
        Calibrator::new(&model, QuadSurface::default(), &obs, &space)
            .with_max_iterations(1)
            .run()
            .map(|_| ())
    };
    let swapped = NamedPoly {
        params: ["b", "a"],
        outputs: outputs.clone(),
    };
    let err = refusal(swapped).unwrap_err().to_string();
    assert!(
        err.contains("the model's parameters are [b, a], the parameter space's [a, b]"),
        "{err}"
    );
    let mut reversed = outputs.clone();
    reversed.reverse();
    let err = refusal(NamedPoly {
        params: ["a", "b"],
        outputs: reversed,
    })
    .unwrap_err()
    .to_string();
    assert!(err.contains("the model's outputs are ["), "{err}");
    assert!(refusal(NamedPoly {
        params: ["a", "b"],
        outputs
    })
    .is_ok());
}

#[test]
fn stops_on_the_wall_clock_budget_and_on_convergence() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_max_wall_s(1e-9)
        .run()
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::WallClockBudget);
    assert!(r.history.is_empty());
    assert_eq!(model.calls(), 8, "the design always runs");

    // A search of a million Adam steps (0.8 s here, 15 s over the 20 iterations) is cut
    // at the budget, inside the first iteration's search, and the model does not run at
    // its proposal: checked between steps only, that iteration would finish and run.
    let model = Poly::new();
    let adam = kalibre_core::Adam::builder()
        .with_steps(1_000_000)
        .build()
        .unwrap();
    let started = std::time::Instant::now();
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_searcher(adam)
        .with_max_wall_s(0.5)
        .run()
        .unwrap();
    let took = started.elapsed().as_secs_f64();
    assert_eq!(r.stop_reason, StopReason::WallClockBudget);
    assert!(took < 30.0, "{took:.1} s against a 0.5 s budget");
    assert!(r.history.is_empty(), "{} iterations ran", r.history.len());
    assert_eq!(model.calls(), 8);

    // On an exact surrogate the search lands on the same point twice: converged.
    let model = Poly::new();
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_seed(42)
        .with_max_iterations(20)
        .run()
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::Converged);
    assert!(r.history.len() < 20);
    assert_eq!(model.calls(), 8 + 2 * r.history.len());
    assert!(r.best.mae_c < 1e-3);
}

/// [`QuadSurface`] that records the sample weights of every fit.
#[derive(Default)]
struct WeightRecorder {
    inner: QuadSurface,
    fits: std::sync::Mutex<Vec<Vec<f64>>>,
}

impl kalibre_core::Surrogate for WeightRecorder {
    type Scenario = Scen;

    fn fit(
        &mut self,
        data: kalibre_core::TrainingSet<'_, Scen>,
        seed: u64,
    ) -> kalibre_core::Result<kalibre_core::FitSummary> {
        let weights = data.samples.iter().map(|s| s.weight).collect();
        self.fits.lock().unwrap().push(weights);
        self.inner.fit(data, seed)
    }

    fn predict(&self, scenario: &Scen, params: &[f64]) -> Vec<f64> {
        self.inner.predict(scenario, params)
    }

    fn vjp(&self, scenario: &Scen, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        self.inner.vjp(scenario, params, cotangent)
    }
}

#[test]
fn the_first_fit_learns_the_whole_design_and_later_fits_are_focused() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let mut cal =
        Calibrator::new(&model, WeightRecorder::default(), &obs, &space).with_settings(Settings {
            seed: 3,
            max_iterations: 3,
            focus: Some(0.5),
            ..Settings::default()
        });
    cal.run().unwrap();
    let fits = cal.surrogate().fits.lock().unwrap().clone();
    assert_eq!(fits.len(), 3);
    // The design spans the box: focusing its fit would leave one design point to learn.
    assert!(
        fits[0].iter().all(|&w| w == 1.0),
        "first fit: {:?}",
        fits[0]
    );
    // From the second fit on, runs far from the measurements weigh less.
    for f in &fits[1..] {
        assert!(f.iter().any(|&w| w < 0.5), "later fit not focused: {f:?}");
        assert!(f.contains(&1.0));
    }
}

#[test]
fn the_report_says_which_parameters_the_measurements_pin_down() {
    // A third parameter that neither the model nor the surrogate reads, and a fourth
    // that equal bounds fix: given, so not listed with a spread (it used to be "free").
    let model = Poly::new();
    let obs = observations();
    let space = space()
        .with("unused", 0.0, 1.0, 0.5, kalibre_core::Scale::Linear)
        .unwrap()
        .with("given", 0.7, 0.7, 0.7, kalibre_core::Scale::Linear)
        .unwrap();
    let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_seed(2)
        .with_max_iterations(6)
        .run()
        .unwrap();
    let u = &report.uncertainty;
    assert_eq!(u.len(), 3);
    for (p, name) in u.iter().zip(["a", "b", "unused"]) {
        assert_eq!(p.name, name);
        assert_eq!(p.value, report.best.params.get(name).unwrap());
    }
    assert!(u[0].identified && u[1].identified, "{u:?}");
    assert!(u[0].rel_std.unwrap() < 0.01 && u[1].rel_std.unwrap() < 0.01);
    assert!(!u[2].identified && u[2].std.is_none(), "{:?}", u[2]);
    assert_eq!(report.best.params.get("given"), Some(0.7));
    // The field round-trips, and reports without it still load.
    let text = serde_json::to_string(&report).unwrap();
    let back: Report = serde_json::from_str(&text).unwrap();
    assert_eq!(back.uncertainty, report.uncertainty);
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value.as_object_mut().unwrap().remove("uncertainty");
    let old: Report = serde_json::from_value(value).unwrap();
    assert!(old.uncertainty.is_empty());
}
