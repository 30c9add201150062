//! Helpers of the command-line tests: the built binary, the OpenFOAM development data
//! shipped in `data/openfoam`, scratch directories and error checks.
#![allow(dead_code)] // each test file uses some of them

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `kalibre calibrate` flags for a calibration of a second or two: one iteration, no
/// polish, no grid check, no progress.
pub const QUICK_CALIBRATION: [&str; 6] = [
    "--iterations",
    "1",
    "--polish",
    "0",
    "--no-grid-check",
    "--quiet",
];

pub fn kalibre() -> Command {
    Command::new(env!("CARGO_BIN_EXE_kalibre"))
}

pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/openfoam")
        .join(name)
}

pub fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kalibre-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub fn run(cmd: &mut Command) -> Output {
    cmd.output().expect("the kalibre binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `kalibre COMMAND --hall DATASET/hall.json --snapshots DATASET/snapshots.csv`, on an
/// OpenFOAM development dataset.
pub fn on_dataset(command: &str, dataset: &str) -> Command {
    on_files(
        command,
        &data(&format!("{dataset}/hall.json")),
        &data(&format!("{dataset}/snapshots.csv")),
    )
}

/// `kalibre COMMAND --hall HALL --snapshots SNAPSHOTS`.
pub fn on_files(command: &str, hall: &Path, snapshots: &Path) -> Command {
    let mut c = kalibre();
    c.arg(command)
        .arg("--hall")
        .arg(hall)
        .arg("--snapshots")
        .arg(snapshots);
    c
}

/// `kalibre diagnose --hall HALL --snapshots SNAPSHOTS --calibration CALIBRATION`.
pub fn diagnose_cmd(hall: &Path, snapshots: &Path, calibration: &Path) -> Command {
    let mut c = on_files("diagnose", hall, snapshots);
    c.arg("--calibration").arg(calibration);
    c
}

/// A bad input gives exit code 2 and one readable error line naming what is wrong.
pub fn assert_input_error(o: &Output, needle: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "one error line, got: {err}");
    assert!(lines[0].starts_with("kalibre: error: "), "{err}");
    assert!(err.contains(needle), "`{needle}` not in: {err}");
}

/// Asserts that each (snapshot, parameters) pair appears once among a journal's runs,
/// and returns how many runs there are.
pub fn assert_each_run_once(runs: &[serde_json::Value]) -> usize {
    let mut keys: Vec<String> = runs
        .iter()
        .map(|v| format!("{}|{}", v["scenario"], v["params"]))
        .collect();
    let n = keys.len();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), n, "a run was repeated");
    n
}
