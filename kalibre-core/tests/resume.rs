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
