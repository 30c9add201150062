//! The baselines that run the model every iteration: the (1+1)-ES and the expert's
//! procedure, on the small OpenFOAM hall.

mod support;

use std::sync::Mutex;

use kalibre_baselines::{
    run_es, BaselineReport, ManualHeuristic, ManualSettings, Neighbourhood, OnePlusOneEs,
};
use kalibre_core::{Model, ModelError, Outputs, ParamSpace, RunStore};
use kalibre_dc::hall::AlphaMode;
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::HallModel;

/// The hall model, recording every parameter vector it is run at.
struct Recording<'a> {
    inner: &'a HallModel,
    seen: Mutex<Vec<Vec<f64>>>,
}

impl<'a> Recording<'a> {
    fn new(inner: &'a HallModel) -> Self {
        Recording {
            inner,
            seen: Mutex::new(Vec::new()),
        }
    }
    fn runs(&self) -> Vec<Vec<f64>> {
        self.seen.lock().unwrap().clone()
    }
}

impl Model for Recording<'_> {
    type Scenario = OperatingState;
    fn fingerprint(&self) -> String {
        self.inner.fingerprint()
    }
    fn evaluate(&self, s: &OperatingState, p: &[f64]) -> Result<Outputs, ModelError> {
        self.seen.lock().unwrap().push(p.to_vec());
        self.inner.evaluate(s, p)
    }
}

fn assert_in_bounds(space: &ParamSpace, runs: &[Vec<f64>]) {
    assert!(!runs.is_empty());
    for p in runs {
        space.check_physical(p).unwrap();
    }
}

fn assert_consistent(r: &BaselineReport, runs_per_point: usize) {
    assert_eq!(r.history[0].iteration, 0);
    assert_eq!(r.model_runs, r.history.len() * runs_per_point);
    let best = r
        .history
        .iter()
        .map(|h| h.mae_c)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(r.best_mae_c, best);
    for w in r.history.windows(2) {
        assert!(w[1].best_mae_c <= w[0].best_mae_c);
        assert_eq!(w[1].model_runs, w[0].model_runs + runs_per_point);
    }
}

#[test]
fn es_improves_on_the_initial_mae_deterministically_within_bounds() {
    let s = support::setup(AlphaMode::PerType);
    let space = s.model.layout().space();
    let es = OnePlusOneEs::default().with_seed(7).with_max_iterations(40);
    let rec = Recording::new(&s.model);
    let a = run_es(&rec, &s.obs, space, &es, None).unwrap();
    eprintln!(
        "ES: initial MAE {:.3} C, best {:.3} C after {} runs",
        a.initial_mae_c, a.best_mae_c, a.model_runs
    );
    assert!(
        a.best_mae_c < 0.5 * a.initial_mae_c,
        "best {} vs initial {}",
        a.best_mae_c,
        a.initial_mae_c
    );
    assert_consistent(&a, 3);
    assert_eq!(rec.runs().len(), a.model_runs);
    assert_in_bounds(space, &rec.runs());
    space.check_physical(&a.best_params).unwrap();

    let b = run_es(&s.model, &s.obs, space, &es, None).unwrap();
    assert_eq!(a.history, b.history);
    assert_eq!(a.best_params, b.best_params);
    let c = run_es(&s.model, &s.obs, space, &es.clone().with_seed(8), None).unwrap();
    assert_ne!(a.history, c.history);
}

#[test]
fn es_with_the_literal_sigma_stays_in_bounds_per_server() {
    // Sigma 5 box widths: every mutation leaves the box and is reflected back.
    let s = support::setup(AlphaMode::PerServer);
    let space = s.model.layout().space();
    assert_eq!(space.dim(), 20);
    let rec = Recording::new(&s.model);
    let es = OnePlusOneEs::default()
        .with_seed(3)
        .with_sigma0(5.0)
        .with_max_iterations(15);
    let r = run_es(&rec, &s.obs, space, &es, None).unwrap();
    assert_in_bounds(space, &rec.runs());
    assert_consistent(&r, 3);
}

#[test]
fn es_replays_its_journal_instead_of_rerunning() {
    let s = support::setup(AlphaMode::PerType);
    let space = s.model.layout().space();
    let es = OnePlusOneEs::default().with_seed(2).with_max_iterations(8);
    let store = RunStore::in_memory(s.model.fingerprint());
    let first = Recording::new(&s.model);
    let a = run_es(&first, &s.obs, space, &es, Some(&store)).unwrap();
    assert_eq!(store.len(), a.model_runs);
    let second = Recording::new(&s.model);
    let b = run_es(&second, &s.obs, space, &es, Some(&store)).unwrap();
    assert!(
        second.runs().is_empty(),
        "a replayed run was computed again"
    );
    assert_eq!(a.history, b.history);
    let wrong = RunStore::in_memory("another model");
    assert!(run_es(&s.model, &s.obs, space, &es, Some(&wrong)).is_err());
}

#[test]
fn manual_heuristic_improves_per_type_and_per_server() {
    for (mode, dim) in [(AlphaMode::PerType, 3), (AlphaMode::PerServer, 20)] {
        let s = support::setup(mode);
        let space = s.model.layout().space();
        assert_eq!(space.dim(), dim);
        let m = ManualHeuristic::new(
            &s.hall,
            s.model.layout().clone(),
            ManualSettings::default().with_max_iterations(15),
        )
        .unwrap();
        // Every hot-aisle sensor guides its 4 nearest servers; cold-aisle ones do not.
        for (sensor, near) in s.hall.sensors.iter().zip(m.neighbours()) {
            let hot = sensor.aisle == kalibre_dc::hall::Aisle::Hot;
            assert_eq!(near.len(), if hot { 4 } else { 0 });
        }
        let rec = Recording::new(&s.model);
        let a = m.run(&rec, &s.obs, None).unwrap();
        eprintln!(
            "manual {mode:?}: initial MAE {:.3} C, best {:.3} C after {} runs",
            a.initial_mae_c, a.best_mae_c, a.model_runs
        );
        assert!(
            a.best_mae_c < 0.5 * a.initial_mae_c,
            "{mode:?}: best {} vs initial {}",
            a.best_mae_c,
            a.initial_mae_c
        );
        assert_consistent(&a, 3);
        assert_in_bounds(space, &rec.runs());
        // The initial alpha (0.25 cfm/W) is above the truth (0.12-0.17): the expert lowers it.
        let mean = a.best_params.iter().sum::<f64>() / dim as f64;
        assert!(mean < 0.25, "{mode:?}: mean alpha {mean}");
        if mode == AlphaMode::PerType {
            assert!(a.best_params.iter().all(|&x| x < 0.25));
        }
        let b = m.run(&s.model, &s.obs, None).unwrap();
        assert_eq!(a.history, b.history);
        assert_eq!(a.best_params, b.best_params);
    }
}

#[test]
fn manual_settings_are_checked() {
    let s = support::setup(AlphaMode::PerType);
    let bad = ManualSettings::default().with_neighbourhood(Neighbourhood::RadiusM(-1.0));
    let e = ManualHeuristic::new(&s.hall, s.model.layout().clone(), bad).unwrap_err();
    assert!(e.to_string().contains("neighbourhood"), "{e}");
    let e = ManualSettings::default()
        .with_step(0.0)
        .check()
        .unwrap_err();
    assert!(e.to_string().contains("step"), "{e}");
    // A radius neighbourhood attributes each sensor to the servers within it.
    let m = ManualHeuristic::new(
        &s.hall,
        s.model.layout().clone(),
        ManualSettings::default().with_neighbourhood(Neighbourhood::RadiusM(1.5)),
    )
    .unwrap();
    assert!(m.neighbours().iter().any(|n| !n.is_empty()));
    // A neighbourhood no server lies in leaves the expert nothing to read: refused
    // rather than a run that stops after its first point.
    let e = ManualHeuristic::new(
        &s.hall,
        s.model.layout().clone(),
        ManualSettings::default().with_neighbourhood(Neighbourhood::RadiusM(1e-6)),
    )
    .unwrap_err();
    assert!(e.to_string().contains("no guiding sensor"), "{e}");
    // Outputs that are not the hall's sensors are refused, not read past their end.
    let outputs: Vec<Vec<f64>> = s.obs.snapshots().iter().map(|_| vec![25.0; 1]).collect();
    let e = m.suggestion(&s.obs, &outputs).unwrap_err();
    assert!(
        e.to_string().contains("model outputs for the hall's"),
        "{e}"
    );
    let e = m.suggestion(&s.obs, &outputs[..0]).unwrap_err();
    assert!(e.to_string().contains("the expert reads"), "{e}");
}

#[test]
fn es_without_one_successful_point_is_an_error() {
    struct Failing;
    impl Model for Failing {
        type Scenario = OperatingState;
        fn fingerprint(&self) -> String {
            "failing".into()
        }
        fn evaluate(&self, _: &OperatingState, _: &[f64]) -> Result<Outputs, ModelError> {
            Err(ModelError::failed("the solver diverged"))
        }
    }
    let s = support::setup(AlphaMode::PerType);
    let es = OnePlusOneEs::default().with_max_iterations(3);
    match run_es(&Failing, &s.obs, s.model.layout().space(), &es, None) {
        Err(kalibre_baselines::Error::Core(kalibre_core::Error::NoSuccessfulRun(m))) => {
            assert!(m.contains("(1+1)-ES"), "{m}")
        }
        other => panic!("expected NoSuccessfulRun, got {other:?}"),
    }
}
