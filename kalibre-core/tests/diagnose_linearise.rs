//! `diagnose::linearise`: a model's residuals, Jacobian and candidate hypotheses from its
//! own runs, through the journal; the slopes against the model's exact ones, scales, and
//! failed steps.

use kalibre_core::diagnose::{
    diagnose, linearise, run_fitted, CandidateEffect, CandidateParam, DiagnoseSettings, Diagnosis,
    FittedRun, LineariseSettings, Linearised,
};
use kalibre_core::{
    Model, ModelError, Observations, OutputInfo, Outputs, Param, ParamSpace, RunStore, Scale,
    Snapshot,
};

/// `y = a x + leak x^2` seen at `x` and `x + 3`; fails for `a` above `a_fails` or `leak`
/// above `leak_fails`.
struct Curve {
    a_fails: f64,
    leak_fails: f64,
}

impl Model for Curve {
    type Scenario = f64;
    fn fingerprint(&self) -> String {
        "curve".into()
    }
    fn evaluate(&self, x: &f64, p: &[f64]) -> Result<Outputs, ModelError> {
        if p[0] > self.a_fails {
            return Err(ModelError::failed("a too large"));
        }
        if p[1] > self.leak_fails {
            return Err(ModelError::failed("the leak solver diverged"));
        }
        let y = |x: f64| p[0] * x + p[1] * x * x;
        Ok(Outputs::from(vec![y(*x), y(x + 3.0)]))
    }
}

const WORKS: Curve = Curve {
    a_fails: f64::INFINITY,
    leak_fails: f64::INFINITY,
};

fn observations() -> Observations<f64> {
    let truth = |x: f64| 2.0 * x + 0.3 * x * x;
    let snaps = (1..=3)
        .map(|i| {
            let x = i as f64;
            Snapshot {
                label: format!("x{i}"),
                scenario: x,
                measured: vec![Some(truth(x)), Some(truth(x + 3.0))],
            }
        })
        .collect();
    let sensor = |name: &str| OutputInfo {
        name: name.into(),
        group: String::new(),
    };
    Observations::new(vec![sensor("near"), sensor("far")], snaps).unwrap()
}

/// `a` in [0, 10] (log scale when `log`), the leak held at 0 as a candidate in [0, 1].
fn space_and_leak(log: bool) -> (ParamSpace, CandidateEffect) {
    let mut space = ParamSpace::new();
    let (lower, scale) = if log {
        (0.1, Scale::Log)
    } else {
        (0.0, Scale::Linear)
    };
    space
        .push(Param::new("a", lower, 10.0, 1.0, scale).unwrap())
        .unwrap();
    space
        .push(Param::new("leak", 0.0, 0.0, 0.0, Scale::Linear).unwrap())
        .unwrap();
    let leak = CandidateEffect {
        name: "leak".into(),
        params: vec![CandidateParam {
            name: "leak".into(),
            index: 1,
            absent: 0.0,
            lower: 0.0,
            upper: 1.0,
        }],
    };
    (space, leak)
}

/// Linearised at a = 3.5 with the leak absent, default steps.
fn at_3_5<M: Model<Scenario = f64>>(
    model: &M,
    obs: &Observations<f64>,
    space: &ParamSpace,
    leak: &CandidateEffect,
    store: &RunStore,
) -> kalibre_core::Result<Linearised> {
    let settings = LineariseSettings::default();
    linearise(
        model,
        obs,
        space,
        &[3.5, 0.0],
        std::slice::from_ref(leak),
        store,
        &settings,
    )
}

#[test]
fn slopes_are_the_models_and_the_journal_answers_a_second_time() {
    let (space, leak) = space_and_leak(true);
    let obs = observations();
    let store = RunStore::in_memory("curve");
    let lin = at_3_5(&WORKS, &obs, &space, &leak, &store).unwrap();
    // The model is linear in both: the slopes are x (and x + 3), and x^2 (and (x + 3)^2).
    let j = lin.residuals.jacobian();
    let h = &lin.hypotheses[0].jacobian;
    for (row, x) in [1.0, 4.0, 2.0, 5.0, 3.0, 6.0].iter().enumerate() {
        assert!(
            (j[[row, 0]] - x).abs() < 1e-9,
            "d/da row {row}: {}",
            j[[row, 0]]
        );
        assert!(
            (h[[row, 0]] - x * x).abs() < 1e-9,
            "d/dleak row {row}: {}",
            h[[row, 0]]
        );
        let r = lin.residuals.residuals()[row];
        assert!(
            (r - (1.5 * x - 0.3 * x * x)).abs() < 1e-12,
            "residual {row}: {r}"
        );
    }
    assert_eq!(lin.residuals.params(), ["a".to_string()]);
    assert_eq!((lin.runs, lin.cached), (9, 0));
    assert_eq!(lin.predicted[0], vec![3.5, 14.0]);
    let again = at_3_5(&WORKS, &obs, &space, &leak, &store).unwrap();
    assert_eq!((again.runs, again.cached), (0, 9));
}

#[test]
fn scales_divide_residuals_and_slopes_but_not_the_fit() {
    let (space, leak) = space_and_leak(false);
    let plain = observations();
    let scaled = observations().with_scales(vec![vec![0.5, 4.0]; 3]).unwrap();
    let run = |obs: &Observations<f64>| {
        let store = RunStore::in_memory("curve");
        at_3_5(&WORKS, obs, &space, &leak, &store).unwrap()
    };
    let (a, b) = (run(&plain), run(&scaled));
    for row in 0..6 {
        let scale = if row % 2 == 0 { 0.5 } else { 4.0 };
        let (ra, rb) = (a.residuals.residuals()[row], b.residuals.residuals()[row]);
        assert!(
            (ra / scale - rb).abs() < 1e-12,
            "row {row}: {ra} / {scale} vs {rb}"
        );
        let (ja, jb) = (
            a.residuals.jacobian()[[row, 0]],
            b.residuals.jacobian()[[row, 0]],
        );
        assert!(
            (ja / scale - jb).abs() < 1e-9,
            "row {row}: {ja} / {scale} vs {jb}"
        );
    }
    // The outputs themselves, in their own units.
    assert_eq!(a.predicted, b.predicted);
    // The model is exact at leak 0.3: weighed either way, the fit finds it.
    let sigma = DiagnoseSettings::new().with_noise_sigma(0.01);
    for lin in [&a, &b] {
        let d = diagnose(&lin.residuals, &lin.hypotheses, &sigma).unwrap();
        let fitted = d.hypotheses[0].fitted.get("leak").unwrap();
        assert!((fitted - 0.3).abs() < 1e-6, "fitted leak {fitted}");
    }
}

#[test]
fn failed_steps_are_named_and_a_failed_candidate_is_left_out() {
    let (space, leak) = space_and_leak(false);
    let obs = observations();
    // The leak's step (0.05 of its range) fails: not tried, with the model's reason.
    let store = RunStore::in_memory("curve");
    let leaky = Curve {
        a_fails: f64::INFINITY,
        leak_fails: 0.01,
    };
    let lin = at_3_5(&leaky, &obs, &space, &leak, &store).unwrap();
    assert!(lin.hypotheses.is_empty());
    let (name, why) = &lin.not_tried[0];
    assert_eq!(name, "leak");
    assert!(
        why.contains("`leak` at 0.05 (`x1`)") && why.contains("the leak solver diverged"),
        "{why}"
    );
    // A forward step of `a` that fails is taken backwards instead.
    let store = RunStore::in_memory("curve");
    let edge = Curve {
        a_fails: 3.55,
        leak_fails: f64::INFINITY,
    };
    let lin = at_3_5(&edge, &obs, &space, &leak, &store).unwrap();
    assert!((lin.residuals.jacobian()[[1, 0]] - 4.0).abs() < 1e-9);
    // At the upper bound the step goes backwards; when that fails there is no other
    // side to take: said, not a 0 / 0.
    struct OnlyAt(f64);
    impl Model for OnlyAt {
        type Scenario = f64;
        fn fingerprint(&self) -> String {
            "only-at".into()
        }
        fn evaluate(&self, x: &f64, p: &[f64]) -> Result<Outputs, ModelError> {
            if p[0] != self.0 {
                return Err(ModelError::failed("off the one point that runs"));
            }
            Ok(Outputs::from(vec![p[0] * x, p[0] * (x + 3.0)]))
        }
    }
    let mut bounded = ParamSpace::new();
    bounded
        .push(Param::new("a", 0.0, 3.5, 1.0, Scale::Linear).unwrap())
        .unwrap();
    bounded
        .push(Param::new("leak", 0.0, 0.0, 0.0, Scale::Linear).unwrap())
        .unwrap();
    let store = RunStore::in_memory("only-at");
    let e = at_3_5(&OnlyAt(3.5), &obs, &bounded, &leak, &store)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("a step of `a`") && e.contains("the other side is beyond its bounds"),
        "{e}"
    );
    // A failure at the point itself: nothing to diagnose.
    let store = RunStore::in_memory("only-at");
    let (space, leak) = space_and_leak(false);
    let e = at_3_5(&OnlyAt(9.0), &obs, &space, &leak, &store)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("failed at the calibrated parameters (`x1`)"),
        "{e}"
    );
}

/// `y = a x + (leak - 8 leak^2) x^2`: a leak that first warms, then cools, so its slope
/// at a small step overstates what a larger leak does.
struct Turning;

impl Model for Turning {
    type Scenario = f64;
    fn fingerprint(&self) -> String {
        "turning".into()
    }
    fn evaluate(&self, x: &f64, p: &[f64]) -> Result<Outputs, ModelError> {
        let y = |x: f64| p[0] * x + (p[1] - 8.0 * p[1] * p[1]) * x * x;
        Ok(Outputs::from(vec![y(*x), y(x + 3.0)]))
    }
}

/// Linearised at a = 3.5 and ranked, then run where the leading hypothesis was fitted.
fn fit_and_run<M: Model<Scenario = f64>>(
    model: &M,
    obs: &Observations<f64>,
    space: &ParamSpace,
    leak: &CandidateEffect,
) -> (Linearised, Diagnosis, FittedRun) {
    let store = RunStore::in_memory("fit");
    let lin = at_3_5(model, obs, space, leak, &store).unwrap();
    let sigma = DiagnoseSettings::new().with_noise_sigma(0.01);
    let d = diagnose(&lin.residuals, &lin.hypotheses, &sigma).unwrap();
    let run = run_fitted(
        model,
        obs,
        space,
        &[3.5, 0.0],
        leak,
        &d.hypotheses[0],
        &store,
    );
    (lin, d, run.unwrap())
}

#[test]
fn the_model_run_at_the_fit_confirms_or_refutes_it() {
    let (space, leak) = space_and_leak(false);
    let obs = observations();
    // Linear in the leak: the fitted point is the truth, where the model is exact.
    let (_, _, run) = fit_and_run(&WORKS, &obs, &space, &leak);
    assert!((run.params[0] - 2.0).abs() < 1e-6 && (run.params[1] - 0.3).abs() < 1e-6);
    assert!(run.mae.unwrap() < 1e-6, "the model at the fit");
    assert_eq!(run.runs, 3);
    // Turning: the step's slope (0.6 x^2) leads the fit to a leak where the model cools.
    let (lin, d, run) = fit_and_run(&Turning, &obs, &space, &leak);
    let mae = run.mae.unwrap();
    assert!(mae > d.mae, "MAE {mae} at the fit against {} now", d.mae);
    // Refuted, the hypothesis is never significant.
    let sigma = DiagnoseSettings::new().with_noise_sigma(0.01);
    let mut refuted = lin.hypotheses.clone();
    refuted[0].refuted = true;
    let again = diagnose(&lin.residuals, &refuted, &sigma).unwrap();
    assert!(!again.hypotheses[0].significant);
}
