//! `diagnose::refit_leading`: the leading candidates refit with the model's own runs
//! (secant steps from the linearisation), through the journal; an effect that saturates
//! is refit to its size, one that turns is refuted, and a calibration that stopped short
//! of its own floor credits no candidate with the way there.

use kalibre_core::diagnose::{
    diagnose, linearise, refit_leading, run_fitted, Calibrated, CandidateEffect, CandidateParam,
    DiagnoseSettings, LineariseSettings, Linearised, RefitSettings, Refitted,
};
use kalibre_core::{
    Model, ModelError, Observations, OutputInfo, Outputs, Param, ParamSpace, RunStore, Scale,
    Snapshot,
};

/// `y = a x + g(q1) x^2 + g(q2) (x + 1)` seen at `x` and `x + 3`, with the effect's
/// footprint `g(q) = q / (1 + saturation q) - turning q^2`: linear when both are 0. The
/// model fails for `q1` above `fails_above`.
struct Bent {
    saturation: f64,
    turning: f64,
    fails_above: f64,
}

/// A [`Bent`] that always runs.
fn bent(saturation: f64, turning: f64) -> Bent {
    Bent {
        saturation,
        turning,
        fails_above: f64::INFINITY,
    }
}

impl Bent {
    fn g(&self, q: f64) -> f64 {
        q / (1.0 + self.saturation * q) - self.turning * q * q
    }
}

impl Model for Bent {
    type Scenario = f64;
    fn fingerprint(&self) -> String {
        format!("bent {} {}", self.saturation, self.turning)
    }
    fn evaluate(&self, x: &f64, p: &[f64]) -> Result<Outputs, ModelError> {
        if p[1] > self.fails_above {
            return Err(ModelError::failed("the effect's solver diverged"));
        }
        let y = |x: f64| p[0] * x + self.g(p[1]) * x * x + self.g(p[2]) * (x + 1.0);
        Ok(Outputs::from(vec![y(*x), y(x + 3.0)]))
    }
}

/// Four snapshots of `truth` (a model and its parameters).
fn observations(truth: &Bent, params: [f64; 3]) -> Observations<f64> {
    let snaps = (1..=4)
        .map(|i| {
            let x = i as f64;
            let y = truth.evaluate(&x, &params).unwrap().values;
            Snapshot {
                label: format!("x{i}"),
                scenario: x,
                measured: y.into_iter().map(Some).collect(),
            }
        })
        .collect();
    let sensor = |name: &str| OutputInfo {
        name: name.into(),
        group: String::new(),
    };
    Observations::new(vec![sensor("near"), sensor("far")], snaps).unwrap()
}

fn candidate(name: &str, index: usize) -> CandidateParam {
    CandidateParam {
        name: name.into(),
        index,
        absent: 0.0,
        lower: 0.0,
        upper: 1.0,
    }
}

/// `a` in [0, 10], both candidates held at 0: one effect of `q1` alone, or one of both.
fn space(effect_of_both: bool) -> (ParamSpace, Vec<CandidateEffect>) {
    let mut space = ParamSpace::new();
    space
        .push(Param::new("a", 0.0, 10.0, 1.0, Scale::Linear).unwrap())
        .unwrap();
    for name in ["q1", "q2"] {
        space
            .push(Param::new(name, 0.0, 0.0, 0.0, Scale::Linear).unwrap())
            .unwrap();
    }
    let effects = if effect_of_both {
        vec![CandidateEffect {
            name: "curve".into(),
            params: vec![candidate("q1", 1), candidate("q2", 2)],
        }]
    } else {
        vec![CandidateEffect {
            name: "q1".into(),
            params: vec![candidate("q1", 1)],
        }]
    };
    (space, effects)
}

fn sigma() -> DiagnoseSettings {
    DiagnoseSettings::new().with_noise_sigma(0.01)
}

/// Linearised at `a` (the candidates absent), then refit with `iterations` runs.
fn refit(
    model: &Bent,
    obs: &Observations<f64>,
    (space, effects): &(ParamSpace, Vec<CandidateEffect>),
    a: f64,
    iterations: usize,
    store: &RunStore,
) -> (Linearised, Refitted) {
    let params = [a, 0.0, 0.0];
    let lin = linearise(
        model,
        obs,
        space,
        &params,
        effects,
        store,
        &LineariseSettings::default(),
    )
    .unwrap();
    let d = diagnose(&lin.residuals, &lin.hypotheses, &sigma()).unwrap();
    let at = Calibrated {
        model,
        obs,
        space,
        params: &params,
        store,
    };
    let how = RefitSettings {
        iterations,
        ..RefitSettings::default()
    };
    let r = refit_leading(
        &at,
        &lin.residuals,
        effects,
        lin.hypotheses.clone(),
        d.mae,
        &sigma(),
        &how,
    )
    .unwrap();
    (lin, r)
}

#[test]
fn a_saturating_effect_is_refit_to_its_size() {
    let model = bent(4.0, 0.0);
    let obs = observations(&model, [2.0, 0.5, 0.0]);
    let store = RunStore::in_memory("bent");
    let setup = space(false);
    let (lin, r) = refit(&model, &obs, &setup, 2.5, 8, &store);
    // The step's slope at 0.05 (0.83) is more than twice the secant's to 0.5 (0.33), so
    // the linearised fit falls far short.
    let linearised = diagnose(&lin.residuals, &lin.hypotheses, &sigma()).unwrap();
    let q_lin = linearised.hypotheses[0].fitted.get("q1").unwrap();
    assert!((q_lin - 0.5).abs() > 0.2, "linearised q1 {q_lin}");
    let h = &r.diagnosis.hypotheses[0];
    assert!(h.significant, "{h:?}");
    let q = h.fitted.get("q1").unwrap();
    assert!((q - 0.5).abs() < 0.01, "refit q1 {q}");
    let a = 2.5 + h.current_change.get("a").unwrap();
    assert!((a - 2.0).abs() < 0.01, "refit a {a}");
    // Each accepted run reads better than the one before, down to the model's exactness.
    let steps = &r.refits[0].steps;
    let accepted: Vec<f64> = steps
        .iter()
        .filter(|s| s.accepted)
        .filter_map(|s| s.mae)
        .collect();
    assert!(accepted.windows(2).all(|w| w[1] < w[0]), "{steps:?}");
    let best = r.refits[0].best().unwrap().mae.unwrap();
    assert!(best < 1e-3 * linearised.mae, "best {best}, {steps:?}");
    assert_eq!(r.runs, 4 * steps.len());
    // The journal answers every run a second time.
    let (_, again) = refit(&model, &obs, &setup, 2.5, 8, &store);
    assert_eq!((again.runs, again.cached), (0, r.runs));
    assert_eq!(again.refits, r.refits);
}

#[test]
fn an_effect_of_two_parameters_is_refit_jointly() {
    let model = bent(4.0, 0.0);
    let obs = observations(&model, [2.0, 0.5, 0.2]);
    let store = RunStore::in_memory("bent2");
    let (lin, r) = refit(&model, &obs, &space(true), 2.5, 10, &store);
    let before = diagnose(&lin.residuals, &lin.hypotheses, &sigma()).unwrap();
    let h = &r.diagnosis.hypotheses[0];
    let (q1, q2) = (h.fitted.get("q1").unwrap(), h.fitted.get("q2").unwrap());
    let (l1, l2) = (
        before.hypotheses[0].fitted.get("q1").unwrap(),
        before.hypotheses[0].fitted.get("q2").unwrap(),
    );
    let off = |a: f64, b: f64| (a - 0.5).abs() + (b - 0.2).abs();
    assert!(off(l1, l2) > 0.2, "linearised {l1}, {l2}");
    assert!(off(q1, q2) < 0.02, "refit {q1}, {q2}: {:?}", r.refits);
    let best = r.refits[0].best().unwrap().mae.unwrap();
    assert!(best < 1e-2 * before.mae, "{:?}", r.refits);
}

#[test]
fn an_effect_that_turns_is_refuted_by_its_runs() {
    // The data are the linear effect's; the model's first warms, then cools (g turns at
    // q = 0.15), so its small step's slope sends the fit where the model reads worse.
    let linear = bent(0.0, 0.0);
    let obs = observations(&linear, [2.0, 0.3, 0.0]);
    let model = bent(0.0, 10.0 / 3.0);
    let store = RunStore::in_memory("turning");
    let (lin, r) = refit(&model, &obs, &space(false), 2.0, 4, &store);
    let before = diagnose(&lin.residuals, &lin.hypotheses, &sigma()).unwrap();
    assert!(
        before.hypotheses[0].significant,
        "{:?}",
        before.hypotheses[0]
    );
    let refit = &r.refits[0];
    assert!(refit.best().is_none(), "{refit:?}");
    assert!(
        (refit.steps.iter()).all(|s| s.mae.is_some_and(|m| m >= before.mae)),
        "{refit:?}"
    );
    assert_eq!(
        refit.stopped.as_deref(),
        Some("its fit points back to absent, or beyond"),
        "{refit:?}"
    );
    let h = &r.diagnosis.hypotheses[0];
    assert!(h.refuted && !h.significant, "{h:?}");
}

#[test]
fn a_run_that_fails_halves_the_next_step() {
    // Growing faster than linearly, the effect's small step undersells it, so its fit
    // (0.32) lies where the model fails (above 0.3); halfway there it runs.
    let model = Bent {
        saturation: -1.0,
        turning: 0.0,
        fails_above: 0.3,
    };
    let truth = bent(model.saturation, model.turning);
    let obs = observations(&truth, [2.0, 0.25, 0.0]);
    let store = RunStore::in_memory("fails");
    let (_, r) = refit(&model, &obs, &space(false), 2.5, 8, &store);
    let steps = &r.refits[0].steps;
    let first = &steps[0];
    assert!(
        first
            .failed
            .as_deref()
            .is_some_and(|f| f.contains("diverged")),
        "{steps:?}"
    );
    assert!(first.mae.is_none() && !first.accepted);
    let q_failed = first.values.get("q1").unwrap();
    let q_next = steps[1].values.get("q1").unwrap();
    assert!(
        q_failed > 0.3 && (q_next - q_failed / 2.0).abs() < 0.02,
        "{steps:?}"
    );
    let h = &r.diagnosis.hypotheses[0];
    assert!(h.significant && !h.refuted, "{h:?}");
    let best = r.refits[0].best().unwrap();
    let q = best.values.get("q1").unwrap();
    assert!((q - 0.25).abs() < 0.01, "best run at q1 {q}: {steps:?}");
}

#[test]
fn a_calibration_short_of_its_floor_credits_no_candidate_with_the_way_there() {
    // The data are a straight line with a little curvature that the candidate's footprint
    // (g turning at q = 0.15, back to nothing at 0.3) promises to explain. Calibrated at
    // a = 8, far from the line's best a, the run at the candidate's fit reads better than
    // the calibrated point only because `a` moves with it; the calibrated parameters'
    // own refit, run by the model, reads better still.
    let linear = bent(0.0, 0.0);
    let obs = observations(&linear, [2.0, 0.3, 0.0]);
    let model = bent(0.0, 10.0 / 3.0);
    let (space, effects) = space(false);
    let params = [8.0, 0.0, 0.0];
    let store = RunStore::in_memory("short");
    let lin = linearise(
        &model,
        &obs,
        &space,
        &params,
        &effects,
        &store,
        &LineariseSettings::default(),
    )
    .unwrap();
    let d = diagnose(&lin.residuals, &lin.hypotheses, &sigma()).unwrap();
    assert!(
        d.refit_mae < 0.9 * d.mae,
        "{} against {}",
        d.refit_mae,
        d.mae
    );
    let leading = &d.hypotheses[0];
    assert!(leading.significant, "{leading:?}");
    let at_fit = run_fitted(&model, &obs, &space, &params, &effects[0], leading, &store)
        .unwrap()
        .mae
        .unwrap();
    let at = Calibrated {
        model: &model,
        obs: &obs,
        space: &space,
        params: &params,
        store: &store,
    };
    let floor = at.run_refit_alone(&d).unwrap();
    let floor_mae = floor.mae().unwrap();
    assert!((floor.params[0] - 8.0 - d.refit_change.get("a").unwrap()).abs() < 1e-12);
    assert!(
        floor_mae < at_fit && at_fit < d.mae,
        "floor {floor_mae}, at the fit {at_fit}, calibrated {}",
        d.mae
    );
    // Against the floor, the candidate's refit finds no run better: refuted.
    let r = refit_leading(
        &at,
        &lin.residuals,
        &effects,
        lin.hypotheses.clone(),
        floor_mae,
        &sigma(),
        &RefitSettings::default(),
    )
    .unwrap();
    let h = &r.diagnosis.hypotheses[0];
    assert!(h.refuted && !h.significant, "{h:?} {:?}", r.refits);
}
