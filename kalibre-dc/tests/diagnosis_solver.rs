//! The diagnosis over any [`EffectSolver`]: candidates of kinds the solver cannot
//! represent are listed as not tried, a candidate whose run fails is dropped and listed,
//! a failed base run is an error, a failed refit run is recorded and leaves the ranking
//! linearised, and the built-in simulator through the trait gives the same diagnosis as
//! `diagnose_hall`.

use std::sync::atomic::{AtomicUsize, Ordering};

#[path = "support/demo_offset.rs"]
mod demo_offset;
use demo_offset::demo;

use kalibre_dc::diagnosis::{
    diagnose_hall, diagnose_hall_with, EffectSolver, HallDiagnosis, HallDiagnosisSettings,
};
use kalibre_dc::effects::{Effect, EffectRegistry};
use kalibre_dc::hall::Side;
use kalibre_dc::sim::Simulator;
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::synth::Synthesised;
use kalibre_dc::{Error, Result};

/// The built-in simulator, restricted to some kinds, failing some runs.
struct Restricted {
    sim: Simulator,
    kinds: Vec<&'static str>,
    /// Runs with a `bypass` behind this rack fail.
    fail_bypass_behind: Option<String>,
    /// Runs without any effect fail (the base and the calibrated parameters' steps).
    fail_base: bool,
    /// Every run after this many fails.
    fail_after: Option<usize>,
    /// Runs so far.
    calls: AtomicUsize,
}

impl EffectSolver for Restricted {
    fn name(&self) -> String {
        "a restricted solver".into()
    }

    fn supports(&self, kind: &str) -> bool {
        self.kinds.contains(&kind)
    }

    fn solve(
        &self,
        state: &OperatingState,
        alpha: &[f64],
        effects: &[(&dyn Effect, &[f64])],
    ) -> Result<Vec<f64>> {
        let call = self.calls.fetch_add(1, Ordering::SeqCst);
        if self.fail_after.is_some_and(|n| call >= n) {
            return Err(Error::Simulation("the refit's run diverged".into()));
        }
        if self.fail_base && effects.is_empty() {
            return Err(Error::Simulation("the base run diverged".into()));
        }
        for (e, _) in effects {
            let spec = e.to_spec();
            if spec.kind == "bypass"
                && spec.fields.get("behind_rack").and_then(|v| v.as_str())
                    == self.fail_bypass_behind.as_deref()
            {
                return Err(Error::Simulation("the candidate's run diverged".into()));
            }
        }
        EffectSolver::solve(&self.sim, state, alpha, effects)
    }

    fn refined(&self, factor: f64) -> Result<Option<Box<dyn EffectSolver>>> {
        self.sim.refined(factor)
    }
}

fn run(s: &Synthesised, params: &[f64], solver: &dyn EffectSolver) -> Result<HallDiagnosis> {
    diagnose_hall_with(
        &s.hall,
        &s.snapshots,
        params,
        &EffectRegistry::builtin(),
        &HallDiagnosisSettings::default(),
        solver,
    )
}

fn restricted(s: &Synthesised) -> Restricted {
    Restricted {
        sim: Simulator::new(&s.hall, Default::default()).unwrap(),
        kinds: vec!["crac_supply_offset", "bypass"],
        fail_bypass_behind: None,
        fail_base: false,
        fail_after: None,
        calls: AtomicUsize::new(0),
    }
}

#[test]
fn the_simulator_through_the_trait_is_the_default_diagnosis() {
    let (s, params) = demo();
    let sim = Simulator::new(&s.hall, Default::default()).unwrap();
    let a = run(&s, &params, &sim).unwrap();
    let b = diagnose_hall(
        &s.hall,
        &s.snapshots,
        &params,
        &EffectRegistry::builtin(),
        &HallDiagnosisSettings::default(),
    )
    .unwrap();
    assert_eq!(a.to_json(), b.to_json());
    assert!(a.not_tried.is_empty());
    assert!(a.to_json().get("not_tried").is_none());
}

#[test]
fn unsupported_kinds_and_failed_candidates_are_listed_not_dropped() {
    let (s, params) = demo();
    let racks = s.hall.racks.len();
    let d = run(&s, &params, &restricted(&s)).unwrap();
    let kinds: Vec<&str> = d.suggestions.iter().map(|e| e.kind.as_str()).collect();
    assert!(kinds
        .iter()
        .all(|k| *k == "crac_supply_offset" || *k == "bypass"));
    let rr = d
        .not_tried
        .iter()
        .find(|n| n.candidate == "rack_recirculation")
        .expect("rack_recirculation listed");
    assert_eq!(rr.count, racks);
    assert!(rr.reason.contains("a restricted solver"), "{}", rr.reason);
    // The offset is still found among what was tried.
    assert_eq!(
        d.diagnosis.significant().next().map(|h| h.name.as_str()),
        Some("crac_supply_offset")
    );

    let rack = s.hall.racks[0].id.clone();
    let failing = Restricted {
        fail_bypass_behind: Some(rack.clone()),
        ..restricted(&s)
    };
    let d = run(&s, &params, &failing).unwrap();
    let name = format!("bypass(behind_rack={rack})");
    assert!(d.diagnosis.hypotheses.iter().all(|h| h.name != name));
    let failed = d
        .not_tried
        .iter()
        .find(|n| n.candidate == name)
        .expect("the failed candidate listed");
    assert_eq!(failed.count, 1);
    assert!(failed.reason.contains("diverged"), "{}", failed.reason);
    let json = d.to_json();
    assert!(json["not_tried"]
        .as_array()
        .unwrap()
        .iter()
        .any(|n| n["candidate"] == name.as_str()));
}

#[test]
fn a_failed_base_run_is_an_error() {
    let (s, params) = demo();
    let failing = Restricted {
        fail_base: true,
        ..restricted(&s)
    };
    let err = run(&s, &params, &failing).unwrap_err().to_string();
    assert!(err.contains("the base run diverged"), "{err}");
}

#[test]
fn a_hall_effect_the_solver_cannot_represent_is_refused() {
    let (mut s, params) = demo();
    s.hall.effects.push(
        serde_json::from_value(serde_json::json!({
            "kind": "rack_recirculation",
            "rack": s.hall.racks[0].id,
        }))
        .unwrap(),
    );
    let mut p = params;
    p.push(0.1);
    let err = run(&s, &p, &restricted(&s)).unwrap_err().to_string();
    assert!(
        err.contains("`rack_recirculation` cannot be represented by a restricted solver"),
        "{err}"
    );
}

#[test]
fn a_failed_refit_run_is_recorded_and_the_ranking_stays_linearised() {
    let (s, params) = demo();
    let counting = restricted(&s);
    let linear = run(&s, &params, &counting).unwrap();
    // The ranking's own solves (the refined grid's are another solver's).
    let ranking_solves = counting.calls.load(Ordering::SeqCst);
    let settings = HallDiagnosisSettings {
        refit_top: 2,
        ..HallDiagnosisSettings::default()
    };
    let refit = |solver: &Restricted| {
        diagnose_hall_with(
            &s.hall,
            &s.snapshots,
            &params,
            &EffectRegistry::builtin(),
            &settings,
            solver,
        )
        .unwrap()
    };

    let failing = Restricted {
        fail_after: Some(ranking_solves),
        ..restricted(&s)
    };
    let d = refit(&failing);
    assert_eq!(d.diagnosis, linear.diagnosis);
    assert_eq!(d.refits.len(), 2);
    for r in &d.refits {
        assert!(r.steps.is_empty(), "{r:?}");
        let why = r.stopped.as_deref().unwrap_or("");
        assert!(why.contains("the refit's run diverged"), "{why}");
    }
    assert_eq!(d.to_json()["refits"].as_array().map(Vec::len), Some(2));

    // With every run succeeding, each refit runs its steps, one solve per snapshot each.
    let working = restricted(&s);
    let d = refit(&working);
    let steps: usize = d.refits.iter().map(|r| r.steps.len()).sum();
    assert!(steps >= 2, "{:?}", d.refits);
    assert_eq!(
        working.calls.load(Ordering::SeqCst),
        ranking_solves + steps * s.snapshots.len()
    );
    // The offset stays the finding, and its refit lands near the truth (-1 C).
    let top = d.diagnosis.significant().next().expect("significant");
    assert_eq!(top.name, "crac_supply_offset", "{:?}", d.refits);
    let fitted = top.fitted.values()[0];
    assert!((fitted + 1.0).abs() < 0.2, "{fitted}");
    // Fitted below its absence, the offset is run there, and the runs confirm it.
    let offset = d.refits.iter().find(|r| r.name == top.name).expect("refit");
    assert!(
        offset.steps.iter().all(|s| s.effect_value < 0.0),
        "{offset:?}"
    );
    assert!(offset.steps.iter().any(|s| s.accepted), "{offset:?}");
    assert!(!top.refuted);
}

/// A bypass candidate whose strip would overlap a bypass the hall has (a deep strip
/// behind the rack across the hot aisle) is no hypothesis, as a hall with both is
/// refused: listed as not tried, naming it; the other candidates are tried.
#[test]
fn a_candidate_overlapping_the_halls_own_opening_is_listed_not_tried() {
    let (mut s, params) = demo();
    let exhausting = |inlet: Side| {
        s.hall
            .racks
            .iter()
            .filter(|r| r.inlet == inlet)
            .map(|r| (r.id.clone(), r.position_m))
            .collect::<Vec<_>>()
    };
    // A rack of the row facing +y and the rack across its hot aisle.
    let (rack, at) = exhausting(Side::MinusY)[2].clone();
    let across = exhausting(Side::PlusY)
        .into_iter()
        .filter(|(_, p)| (p[0] - at[0]).abs() < 1e-9 && p[1] > at[1])
        .min_by(|a, b| a.1[1].total_cmp(&b.1[1]))
        .expect("a rack across the hot aisle")
        .0;
    s.hall.effects.push(
        serde_json::from_value(serde_json::json!({
            "kind": "bypass", "behind_rack": rack, "depth_m": 1.0,
            "fraction": 0.02, "fraction_bounds": [0.0, 0.2],
        }))
        .unwrap(),
    );
    EffectRegistry::builtin()
        .check_hall(&s.hall, "hall.json")
        .expect("one deep strip");
    let mut p = params;
    p.push(0.02);
    let d = run(&s, &p, &restricted(&s)).unwrap();
    // The rack's own default strip (0.4 m) lies within the hall's, and the strip across
    // the aisle reaches into it; no other candidate does.
    let overlapping: Vec<&str> = d
        .not_tried
        .iter()
        .filter(|n| n.reason.contains("would overlap an opening the hall has"))
        .map(|n| n.candidate.as_str())
        .collect();
    let names = [rack, across].map(|r| format!("bypass(behind_rack={r})"));
    assert_eq!(overlapping, names, "{:?}", d.not_tried);
    for name in &names {
        assert!(d.diagnosis.hypotheses.iter().all(|h| h.name != *name));
    }
    let tried = d.diagnosis.hypotheses.iter();
    assert_eq!(
        tried.filter(|h| h.name.starts_with("bypass(")).count(),
        s.hall.racks.len() - 2
    );
}
