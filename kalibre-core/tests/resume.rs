//! Crash and resume: a calibration whose journal is cut mid-line restarts, repeats no
//! finished run (the model counts its runs), and ends bit-identical to an uninterrupted one.

mod common;

use std::fs;

use common::*;
use kalibre_core::{Calibrator, Report, RunStore};

fn calibrate(path: &std::path::Path, model: &Poly) -> Report {
    let (obs, space) = (observations(), space());
    let store = RunStore::open(path, "poly-v1").unwrap();
    let report = Calibrator::new(model, QuadSurface::default(), &obs, &space)
        .with_seed(11)
        .with_max_iterations(6)
        .with_max_parallel_runs(2)
        .with_store(store)
        .run()
        .unwrap();
    report
}

#[test]
fn a_resumed_calibration_repeats_no_finished_run_and_ends_bit_identical() {
    let dir = temp_dir("resume");
    let path = dir.join("runs.jsonl");
    let first = Poly::new();
    let full = calibrate(&path, &first);
    let n = first.calls();
    assert_eq!(n, full.runs.total);
    assert_eq!(full.runs.new, n);
    assert!(n >= 12, "design plus iterations: {n} runs");
    let text = fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), n);

    // The crash: the journal holds `kept` whole lines, then half of the next one.
    let kept = n / 2 + 1;
    let mut cut = String::new();
    for l in &lines[..kept] {
        cut.push_str(l);
        cut.push('\n');
    }
    let torn = lines[kept];
    cut.push_str(&torn[..torn.len() / 2]);
    fs::write(&path, cut).unwrap();

    let second = Poly::new();
    let resumed = calibrate(&path, &second);
    // Every journaled run was replayed, not repeated; the torn one was run again.
    assert_eq!(second.calls(), n - kept);
    assert_eq!(resumed.runs.cached, kept);
    assert_eq!(resumed.runs.new, n - kept);
    let journal = resumed.journal.as_ref().unwrap();
    assert_eq!(journal.loaded, kept);
    assert!(journal.torn_tail.is_some());
    // Bit-identical results: the best parameters, and the whole report but its timings.
    assert_eq!(best_bits(&resumed), best_bits(&full));
    assert_eq!(without_timings(&resumed), without_timings(&full));
    assert_eq!(resumed.history.last().unwrap().model_runs, n);

    // A third start from the complete journal runs nothing at all.
    let third = Poly::new();
    let replay = calibrate(&path, &third);
    assert_eq!(third.calls(), 0);
    assert_eq!(replay.runs.cached, n);
    assert_eq!(without_timings(&replay), without_timings(&full));
    assert!(replay.journal.as_ref().unwrap().is_clean());
}

/// [`Poly`] with a physical limit: output 0 above 10 is impossible.
struct Bounded(Poly);

impl kalibre_core::Model for Bounded {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        self.0.fingerprint()
    }
    fn evaluate(
        &self,
        scenario: &Scen,
        params: &[f64],
    ) -> Result<kalibre_core::Outputs, kalibre_core::ModelError> {
        self.0.evaluate(scenario, params)
    }
    fn check_plausible(
        &self,
        outputs: &kalibre_core::Outputs,
    ) -> Result<(), kalibre_core::ModelError> {
        match outputs.values[0] {
            v if v > 10.0 => Err(kalibre_core::ModelError::Implausible {
                index: 0,
                name: "s0".into(),
                value: v.to_string(),
                reason: "at most 10".into(),
            }),
            _ => Ok(()),
        }
    }
}

#[test]
fn implausible_runs_are_failed_runs_and_an_implausible_journal_line_is_named() {
    let dir = temp_dir("implausible");
    let path = dir.join("runs.jsonl");
    let run = |model: &Bounded| {
        Calibrator::new(model, QuadSurface::default(), &observations(), &space())
            .with_seed(11)
            .with_max_iterations(6)
            .with_store(RunStore::open(&path, "poly-v1").unwrap())
            .run()
    };
    // The design's upper corner (4, 3) gives 2 * 4 + 3 = 11 at load 2: a failed run,
    // journaled as such; the loop still gets near the truth.
    let report = run(&Bounded(Poly::new())).unwrap();
    assert_eq!(report.initial.failed_runs, 1);
    let text = fs::read_to_string(&path).unwrap();
    let records: Vec<kalibre_core::RunRecord> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let implausible = records
        .iter()
        .filter(|r| matches!(r.error, Some(kalibre_core::ModelError::Implausible { .. })))
        .count();
    assert!(implausible >= 1, "{implausible} implausible runs journaled");
    assert!((report.best.params.get("a").unwrap() - TRUTH[0]).abs() < 0.05);

    // A run written into the journal with a value the model cannot give stops the
    // resume at its line, before it can reach the surrogate.
    let k = records
        .iter()
        .position(|r| r.outputs.is_some())
        .expect("an ok run");
    let mut edited = records[k].clone();
    edited.outputs.as_mut().unwrap()[0] = 1e308;
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[k] = serde_json::to_string(&edited).unwrap();
    fs::write(&path, lines.join("\n") + "\n").unwrap();
    let model = Bounded(Poly::new());
    let err = run(&model).unwrap_err().to_string();
    assert!(
        err.contains("runs.jsonl") && err.contains(&format!("line {}", k + 1)),
        "{err}"
    );
    assert!(err.contains("implausible"), "{err}");

    // So does an ok run with too few outputs.
    edited.outputs = Some(vec![1.0]);
    lines[k] = serde_json::to_string(&edited).unwrap();
    fs::write(&path, lines.join("\n") + "\n").unwrap();
    let err = run(&model).unwrap_err().to_string();
    assert!(
        err.contains(&format!("line {}", k + 1)) && err.contains("1 outputs"),
        "{err}"
    );
}

/// [`Poly`] behind a license server that can be down: every run fails while it is.
struct Licensed {
    poly: Poly,
    down: std::sync::atomic::AtomicBool,
}

impl kalibre_core::Model for Licensed {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        self.poly.fingerprint()
    }
    fn evaluate(
        &self,
        scenario: &Scen,
        params: &[f64],
    ) -> Result<kalibre_core::Outputs, kalibre_core::ModelError> {
        if self.down.load(std::sync::atomic::Ordering::SeqCst) {
            return Err(kalibre_core::ModelError::failed(
                "license server unreachable",
            ));
        }
        self.poly.evaluate(scenario, params)
    }
}

/// Runs that failed for a cause that has passed do not stick in the journal: the next
/// calibration runs them again, and ends as one that never saw the outage.
#[test]
fn runs_failed_in_an_outage_run_again_when_the_calibration_is_started_again() {
    let dir = temp_dir("outage");
    let path = dir.join("runs.jsonl");
    let model = Licensed {
        poly: Poly::new(),
        down: true.into(),
    };
    let run = |model: &Licensed| {
        Calibrator::new(model, QuadSurface::default(), &observations(), &space())
            .with_seed(11)
            .with_max_iterations(6)
            .with_max_parallel_runs(2)
            .with_store(RunStore::open(&path, "poly-v1").unwrap())
            .run()
    };
    let err = run(&model).unwrap_err().to_string();
    assert!(err.contains("license server unreachable"), "{err}");
    let failed_lines = fs::read_to_string(&path).unwrap().lines().count();
    assert!(failed_lines >= 4, "{failed_lines} failed runs journaled");

    model.down.store(false, std::sync::atomic::Ordering::SeqCst);
    let report = run(&model).unwrap();
    let journal = report.journal.as_ref().unwrap();
    assert_eq!(journal.failed_to_retry, failed_lines);
    assert_eq!(report.runs.failed, 0, "{:?}", report.runs);
    assert_eq!(report.runs.new, model.poly.calls());
    // The same as a calibration that never met the outage, journal aside.
    let clean = calibrate(&dir.join("clean.jsonl"), &Poly::new());
    let strip = |r: &Report| {
        let mut r = without_timings(r);
        r.journal = None;
        r
    };
    assert_eq!(strip(&report), strip(&clean));
}
