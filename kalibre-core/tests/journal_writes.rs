//! What the journal writes it reads back: a run's extras or a failure's numbers that JSON
//! cannot hold (NaN, infinity) never make a line the next opening skips or refuses, and
//! a journal in a directory that does not exist yet is created there.

mod common;

use std::fs;

use common::*;
use kalibre_core::{
    Calibrator, Model, ModelError, Outputs, Report, RunRecord, RunStatus, RunStore,
};

/// [`Poly`] with an extra `probe` whose second value is NaN where `b < 1` (the design's
/// lower corner among others).
struct Probed(Poly);

impl Model for Probed {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        "probed-v1".into()
    }
    fn evaluate(&self, s: &Scen, p: &[f64]) -> Result<Outputs, ModelError> {
        let mut out = self.0.evaluate(s, p)?;
        let probe = if p[1] < 1.0 { f64::NAN } else { p[1] };
        out.extras.insert("probe".into(), vec![1.0, probe]);
        Ok(out)
    }
}

fn calibrate(path: &std::path::Path, model: &Probed, replay_failed: bool) -> Report {
    let (obs, space) = (observations(), space());
    let store = RunStore::open_with(path, model.fingerprint(), replay_failed).unwrap();
    let report = Calibrator::new(model, QuadSurface::default(), &obs, &space)
        .with_seed(3)
        .with_max_iterations(4)
        .with_store(store)
        .run()
        .unwrap();
    report
}

fn records(path: &std::path::Path) -> Vec<RunRecord> {
    (fs::read_to_string(path).unwrap().lines())
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// A run whose extras hold a NaN fails, named, and is journaled as that failure: the
/// next opening reads every line, runs again only the failures (as for any failure),
/// and replays every run when asked to replay failures.
#[test]
fn a_nan_extra_fails_its_run_and_every_line_reads_back() {
    let dir = temp_dir("journal-nan-extra");
    let path = dir.join("runs.jsonl");
    let first = Probed(Poly::new());
    let full = calibrate(&path, &first, false);
    let recs = records(&path);
    assert_eq!(recs.len(), full.runs.total, "every run journaled");
    let failed: Vec<&RunRecord> = recs
        .iter()
        .filter(|r| r.status == RunStatus::Failed)
        .collect();
    assert!(!failed.is_empty() && failed.len() < recs.len());
    for r in &failed {
        let why = r.error.as_ref().unwrap().to_string();
        assert!(r.params[1] < 1.0, "{r:?}");
        assert!(
            why.contains("extra `probe` value 1 is not finite (NaN)"),
            "{why}"
        );
    }
    // What a successful run gave is all there, bit for bit.
    let ok = recs.iter().find(|r| r.status == RunStatus::Ok).unwrap();
    assert_eq!(ok.extras["probe"], vec![1.0, ok.params[1]]);

    let store = RunStore::open(&path, "probed-v1").unwrap();
    let load = store.load_report().clone();
    assert!(load.is_clean(), "{load:?}");
    assert_eq!(load.lines, recs.len());
    assert_eq!(load.loaded + load.failed_to_retry, recs.len());
    drop(store);

    // Resumed: only the failures run again (and fail again, journaled), nothing else.
    let second = Probed(Poly::new());
    let resumed = calibrate(&path, &second, false);
    assert_eq!(second.0.calls(), failed.len());
    assert_eq!(best_bits(&resumed), best_bits(&full));
    // Replaying failures: no run at all.
    let third = Probed(Poly::new());
    let replayed = calibrate(&path, &third, true);
    assert_eq!(third.0.calls(), 0);
    assert_eq!(best_bits(&replayed), best_bits(&full));
    let _ = fs::remove_dir_all(dir);
}

/// Given a NaN extra directly, the store refuses the run before writing anything.
#[test]
fn the_store_refuses_a_nan_extra_before_writing() {
    let dir = temp_dir("journal-nan-refused");
    let path = dir.join("runs.jsonl");
    let store = RunStore::open(&path, "m1").unwrap();
    let out = Outputs {
        values: vec![1.0],
        spread: None,
        extras: [("intake".to_string(), vec![20.0, f64::INFINITY])].into(),
    };
    let names = vec!["k".to_string()];
    let e = store
        .record("t0", &names, &[1.0], &Ok(out), 0.1)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("extra `intake` value 1 is not finite (inf)"),
        "{e}"
    );
    assert!(store.is_empty());
    assert_eq!(fs::read_to_string(&path).unwrap(), "");
    let _ = fs::remove_dir_all(dir);
}

/// A timeout whose limit is not a finite number (a model of one's own may give one) is
/// journaled as `null` and read back as NaN: the line loads, the failure replays.
#[test]
fn a_timeout_without_a_finite_limit_reads_back() {
    let dir = temp_dir("journal-timeout-nan");
    let path = dir.join("runs.jsonl");
    let names = vec!["k".to_string()];
    let timeout = |seconds| {
        Err(ModelError::Timeout {
            seconds,
            log_tail: Some("run dir: /runs/t0-1".into()),
        })
    };
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store
            .record("t0", &names, &[1.0], &timeout(f64::NAN), 0.1)
            .unwrap();
        store
            .record("t0", &names, &[2.0], &timeout(f64::INFINITY), 0.1)
            .unwrap();
    }
    let store = RunStore::open_replaying_failures(&path, "m1").unwrap();
    assert!(store.load_report().is_clean(), "{:?}", store.load_report());
    assert_eq!(store.load_report().failed_replayed, 2);
    for k in [1.0, 2.0] {
        let rec = store.get("t0", &names, &[k]).unwrap();
        match rec.result() {
            Err(e @ ModelError::Timeout { seconds, .. }) => {
                assert!(seconds.is_nan(), "{seconds}");
                assert_eq!(e.run_dir(), Some("/runs/t0-1"));
            }
            other => panic!("{other:?}"),
        }
    }
    let _ = fs::remove_dir_all(dir);
}

/// `RunStore::open("out/runs.jsonl", ..)` for an `out/` not made yet creates it.
#[test]
fn a_journal_in_a_missing_directory_is_created() {
    let dir = temp_dir("journal-missing-dir");
    let path = dir.join("out").join("deeper").join("runs.jsonl");
    let names = vec!["k".to_string()];
    {
        let store = RunStore::open(&path, "m1").unwrap();
        let ok = Ok(Outputs::from(vec![2.0]));
        store.record("t0", &names, &[1.0], &ok, 0.1).unwrap();
    }
    let store = RunStore::open(&path, "m1").unwrap();
    assert_eq!(
        store.get("t0", &names, &[1.0]).unwrap().outputs,
        Some(vec![2.0])
    );
    // A path whose directory cannot be made is an error naming it, not a panic.
    let blocker = dir.join("file");
    fs::write(&blocker, "").unwrap();
    let e = RunStore::open(blocker.join("runs.jsonl"), "m1").unwrap_err();
    assert!(e.to_string().contains("file"), "{e}");
    let _ = fs::remove_dir_all(dir);
}
