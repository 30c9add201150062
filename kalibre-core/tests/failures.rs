//! A model that fails in part of the space: failures are journaled as failed runs, the
//! loop continues and still finds the result, and proposals on failed points are moved.

mod common;

use std::collections::HashSet;
use std::fs;

use common::*;
use kalibre_core::{
    Calibrator, Model, ModelError, Objective, Observations, RunRecord, RunStatus, RunStore,
    SearchOutcome, Searcher, Snapshot,
};

/// Fails (`Err`) for `a > 3` and returns a NaN output for `b < 0.8`: the design's lower
/// corner (0, 0.5) and upper corner (4, 3) both fail.
const ZONE: FailZone = FailZone {
    a_err: 3.0,
    b_nan: 0.8,
};

#[test]
fn failed_runs_are_journaled_and_the_loop_still_finds_the_truth() {
    let dir = temp_dir("failures");
    let path = dir.join("runs.jsonl");
    let (model, obs, space) = (Poly::failing(ZONE), observations(), space());
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_seed(1)
        .with_max_iterations(12)
        .with_target_score(1e-3)
        .with_store(RunStore::open(&path, "poly-v1").unwrap())
        .run()
        .unwrap();
    // The two failing corners, at both snapshots.
    assert_eq!(r.initial.failed_runs, 4);
    assert!(r.runs.failed >= 4);
    for (name, truth) in ["a", "b"].iter().zip(TRUTH) {
        let got = r.best.params.get(name).unwrap();
        assert!((got - truth).abs() < 2e-3, "{name}: {got} vs {truth}");
    }
    let records: Vec<RunRecord> = fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(records.len(), r.runs.total);
    let failed: Vec<&RunRecord> = records
        .iter()
        .filter(|x| x.status == RunStatus::Failed)
        .collect();
    assert_eq!(failed.len(), r.runs.failed);
    assert!(failed.iter().all(|x| x.outputs.is_none()));
    assert!(failed
        .iter()
        .any(|x| matches!(x.error, Some(ModelError::Failed { .. }))));
    assert!(failed
        .iter()
        .any(|x| matches!(x.error, Some(ModelError::NonFinite { index: 2, .. }))));
}

/// Proposes `at(seed)` whatever the surrogate says: a search stuck where the model fails.
struct Proposes(fn(u64) -> Vec<f64>);

impl Searcher for Proposes {
    fn search(
        &self,
        _objective: &dyn Objective,
        _start: &[f64],
        seed: u64,
    ) -> kalibre_core::Result<SearchOutcome> {
        Ok(SearchOutcome {
            timed_out: false,
            best_unit: (self.0)(seed),
            best_cost: 0.0,
            evaluations: 0,
            trace: Vec::new(),
        })
    }
}

#[test]
fn a_proposal_on_a_failed_point_is_moved_and_never_repeated() {
    let (model, obs, space) = (Poly::failing(ZONE), observations(), space());
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        // The design's upper corner, which fails: the loop must move off it.
        .with_searcher(Proposes(|_| vec![1.0, 1.0]))
        .with_max_iterations(5)
        .run()
        .unwrap();
    assert_eq!(r.history.len(), 5);
    assert!(r.history.iter().all(|h| h.perturbed));
    let mut seen = HashSet::new();
    for h in &r.history {
        let bits: Vec<u64> = h.params.values().iter().map(|v| v.to_bits()).collect();
        assert!(seen.insert(bits), "point {:?} run twice", h.params);
    }
    assert_eq!(model.calls(), r.runs.total);
    // Near the corner (a > 3) every run fails; the best stays a design point.
    assert_eq!(r.best.iteration, 0);
}

/// The error of a two-iteration calibration of `model`, which must fail.
fn failure_of<M: kalibre_core::Model<Scenario = Scen>>(model: &M) -> String {
    Calibrator::new(model, QuadSurface::default(), &observations(), &space())
        .with_max_iterations(2)
        .run()
        .unwrap_err()
        .to_string()
}

#[test]
fn a_design_that_fails_everywhere_says_why() {
    // Fails at every point: a > -1 always.
    let e = failure_of(&Poly::failing(FailZone {
        a_err: -1.0,
        b_nan: 0.0,
    }));
    assert!(e.contains("runs of the initial design failed"), "{e}");
    // The model's own reason, not only a count.
    assert!(
        e.contains("the first: model run failed: diverged at a ="),
        "{e}"
    );
    // Without a journal there is none to look in: said so, with how to keep one.
    assert!(
        e.contains("a journal, `with_store(RunStore::open(..))`, keeps each run's reason"),
        "{e}"
    );
}

/// Poly with its answer altered by `alter` (given the Poly, the scenario and the
/// parameters), under its own fingerprint.
struct Altered {
    poly: Poly,
    fingerprint: &'static str,
    alter: fn(&Poly, &Scen, &[f64]) -> Result<kalibre_core::Outputs, ModelError>,
}

impl Model for Altered {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        self.fingerprint.into()
    }
    fn evaluate(
        &self,
        scenario: &Scen,
        params: &[f64],
    ) -> Result<kalibre_core::Outputs, ModelError> {
        (self.alter)(&self.poly, scenario, params)
    }
}

#[test]
fn a_snapshot_that_fails_everywhere_is_named_with_its_reason() {
    // Poly, except that every run at the second snapshot fails (as a hall snapshot with
    // every fan off does).
    let e = failure_of(&Altered {
        poly: Poly::failing(FailZone {
            a_err: 10.0,
            b_nan: 0.0,
        }),
        fingerprint: "poly-dead-t1",
        alter: |poly, scenario, params| {
            if scenario.id == 1 {
                return Err(ModelError::failed("no supply air (all fans off)"));
            }
            poly.evaluate(scenario, params)
        },
    });
    assert!(
        e.contains("no parameter point ran successfully at every snapshot"),
        "{e}"
    );
    // Where and why, not only that nothing ran; the snapshot that ran is not blamed.
    assert!(
        e.contains("snapshot `t1` failed at every design point (the first: model run failed: no supply air (all fans off))"),
        "{e}"
    );
    assert!(!e.contains("`t0`"), "{e}");
}

/// Poly with a spread reported at every output, `spread` each.
struct WithSpread(Poly, f64);

impl kalibre_core::Model for WithSpread {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        format!("poly-spread-{}", self.1)
    }
    fn evaluate(
        &self,
        scenario: &Scen,
        params: &[f64],
    ) -> Result<kalibre_core::Outputs, ModelError> {
        let mut out = self.0.evaluate(scenario, params)?;
        out.spread = Some(vec![self.1; out.values.len()]);
        Ok(out)
    }
}

#[test]
fn a_negative_spread_fails_the_run_and_says_so() {
    let sound = Poly::failing(FailZone {
        a_err: 10.0,
        b_nan: 0.0,
    });
    let e = failure_of(&WithSpread(sound, -0.1));
    assert!(e.contains("runs of the initial design failed"), "{e}");
    assert!(e.contains("a negative or non-finite value"), "{e}");
}

#[test]
fn a_proposal_beside_a_failed_point_is_moved_too() {
    let (model, obs, space) = (Poly::failing(ZONE), observations(), space());
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        // The failing corner give or take 1e-7, as a search re-finding one optimum does:
        // each proposal is a new point to the duplicate check, but no new chance for the
        // model.
        .with_searcher(Proposes(|seed| vec![0.99 - 1e-7 * (seed % 5) as f64, 0.99]))
        .with_max_iterations(5)
        .run()
        .unwrap();
    // The first proposal fails (a > 3); every later one lands beside it and is moved.
    assert!(!r.history[0].perturbed);
    assert!(
        r.history[1..].iter().all(|h| h.perturbed),
        "{:?}",
        r.history
    );
    let first = r.history[0].params.values();
    for h in &r.history[1..] {
        let moved = h.params.values()[0] - first[0];
        assert!(moved.abs() > 1e-3, "{:?}", h.params);
    }
}

/// A panicking run is a failed run, journaled with the panic's message, and the
/// calibration goes on to the truth.
#[test]
fn a_model_that_panics_fails_the_run_not_the_calibration() {
    let dir = temp_dir("panics");
    let path = dir.join("runs.jsonl");
    // Poly, except that it panics (as an `unwrap` in a user's simulator would) for a > 3.
    let model = Altered {
        poly: Poly::new(),
        fingerprint: "poly-v1",
        alter: |poly, scenario, params| {
            assert!(params[0] <= 3.0, "index out of range at a = {}", params[0]);
            poly.evaluate(scenario, params)
        },
    };
    let r = Calibrator::new(&model, QuadSurface::default(), &observations(), &space())
        .with_seed(1)
        .with_max_iterations(12)
        .with_target_score(1e-3)
        .with_store(RunStore::open(&path, "poly-v1").unwrap())
        .run()
        .unwrap();
    assert!(r.initial.failed_runs >= 2, "{:?}", r.initial);
    for (name, truth) in ["a", "b"].iter().zip(TRUTH) {
        let got = r.best.params.get(name).unwrap();
        assert!((got - truth).abs() < 2e-3, "{name}: {got} vs {truth}");
    }
    let journal = fs::read_to_string(&path).unwrap();
    assert!(
        journal.contains("the model panicked: index out of range at a = 4"),
        "{journal}"
    );
}

/// The wrong number of outputs stops the calibration at the first run that shows it,
/// journaled, instead of failing every run of the design first.
#[test]
fn a_model_with_the_wrong_output_count_stops_at_its_first_run() {
    let dir = temp_dir("short");
    let path = dir.join("runs.jsonl");
    // Poly with one output too few: a model that does not fit the observations.
    let short = Altered {
        poly: Poly::new(),
        fingerprint: "poly-short",
        alter: |poly, scenario, params| {
            let mut out = poly.evaluate(scenario, params)?;
            out.values.pop();
            Ok(out)
        },
    };
    let err = Calibrator::new(&short, QuadSurface::default(), &observations(), &space())
        .with_max_iterations(2)
        .with_max_parallel_runs(1)
        .with_store(RunStore::open(&path, "poly-short").unwrap())
        .run()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("the model returned 3 outputs where the observations have 4"),
        "{err}"
    );
    let journal = fs::read_to_string(&path).unwrap();
    assert_eq!(journal.lines().count(), 1, "{journal}");
    assert!(journal.contains(r#""status":"failed""#), "{journal}");
}

/// A model whose outputs changed under the same fingerprint finds every journaled run
/// stale: the journal's refusal says to change the fingerprint or the journal, not to
/// delete one line.
#[test]
fn outputs_changed_under_one_fingerprint_are_blamed_on_the_fingerprint() {
    let dir = temp_dir("same-fingerprint");
    let path = dir.join("runs.jsonl");
    let full = Altered {
        poly: Poly::new(),
        fingerprint: "poly-same",
        alter: |poly, scenario, params| poly.evaluate(scenario, params),
    };
    Calibrator::new(&full, QuadSurface::default(), &observations(), &space())
        .with_max_iterations(1)
        .with_store(RunStore::open(&path, "poly-same").unwrap())
        .run()
        .unwrap();
    let short = Altered {
        poly: Poly::new(),
        fingerprint: "poly-same",
        alter: |poly, scenario, params| {
            let mut out = poly.evaluate(scenario, params)?;
            out.values.pop();
            Ok(out)
        },
    };
    // The observations lose the output too, so only the journal's runs disagree.
    let full_obs = observations();
    let three = Observations::new(
        full_obs.outputs()[..3].to_vec(),
        full_obs
            .snapshots()
            .iter()
            .map(|s| Snapshot {
                measured: s.measured[..3].to_vec(),
                ..s.clone()
            })
            .collect(),
    )
    .unwrap();
    let err = Calibrator::new(&short, QuadSurface::default(), &three, &space())
        .with_max_iterations(1)
        .with_store(RunStore::open(&path, "poly-same").unwrap())
        .run()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("line 1 ") && err.contains("give the model a new fingerprint"),
        "{err}"
    );
    assert!(!err.contains("delete the line"), "{err}");
}

/// A searcher's point outside the unit box is clamped onto it, coordinate by coordinate
/// (`kalibre_core::search`'s docs): the model runs at the box's face, never outside its
/// bounds; a point of the wrong length is an error.
#[test]
fn a_searcher_point_outside_the_box_is_clamped_onto_it() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let r = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_searcher(Proposes(|_| vec![1.7, -0.3]))
        .with_max_iterations(1)
        .run()
        .unwrap();
    assert_eq!(r.history[0].params.values(), vec![4.0, 0.5]);
    let err = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_searcher(Proposes(|_| vec![0.5]))
        .with_max_iterations(1)
        .run()
        .unwrap_err()
        .to_string();
    assert!(err.contains("invalid point [0.5]"), "{err}");
}
