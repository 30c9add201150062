//! The calibration's journal as `diagnose` reads it: whether its runs are of this model,
//! and each snapshot's conditions as its runs recorded them.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use crate::cli::{CliError, CliResult};

/// Each snapshot label's scenario keys in `journal` (for reports that carry none),
/// after refusing a journal with runs of a model other than the one of `fingerprints`
/// (its fingerprint and those earlier versions gave it). A missing
/// journal gives none; one that cannot be read, or lines that are not JSON, are named
/// in a warning, as the check cannot see into them.
pub(super) fn scenario_keys(
    journal: &Path,
    fingerprints: &[String],
    hall: &Path,
    model_name: &str,
) -> CliResult<HashMap<String, HashSet<String>>> {
    let mut keys: HashMap<String, HashSet<String>> = HashMap::new();
    let text = match std::fs::read_to_string(journal) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(keys),
        Err(e) => {
            eprintln!(
                "kalibre: warning: {}: not read ({e}); the calibration's model is not \
                 checked against `{}`",
                journal.display(),
                hall.display()
            );
            return Ok(keys);
        }
    };
    let mut other = false;
    // A killed calibration leaves a torn last line (its resume repairs it).
    let mut unread = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            if !line.trim().is_empty() {
                unread.push(i + 1);
            }
            continue;
        };
        other |= v["fingerprint"]
            .as_str()
            .is_some_and(|f| !fingerprints.iter().any(|ours| ours == f));
        if let (Some(label), Some(key)) = (v["scenario"].as_str(), v["scenario_key"].as_str()) {
            keys.entry(label.to_string())
                .or_default()
                .insert(key.to_string());
        }
    }
    if let Some(first) = unread.first() {
        eprintln!(
            "kalibre: warning: {}: {} line(s) are not JSON (first: line {first}); the runs \
             on them are not checked against `{}`",
            journal.display(),
            unread.len(),
            hall.display()
        );
    }
    if other {
        return Err(CliError::Input(format!(
            "{}: runs of another model (a different hall.json, effects, --grid-m, --model or \
             OpenFOAM option) than `{}` with --model {model_name}{}",
            journal.display(),
            hall.display(),
            super::super::hall_changes::clause(journal.parent().unwrap_or(Path::new(".")), hall),
        )));
    }
    Ok(keys)
}

/// Refuses a `report.json` or `runs.jsonl` in the calibration directory that is not a
/// regular file: `calibrate` wrote files there, and a FIFO would block the read. A
/// calibration with runs but no report (running, stopped, or ended in an error) is named
/// as such: its report is written at its end.
pub(super) fn check_regular_files(calibration: &Path) -> CliResult {
    let report = calibration.join("report.json");
    if !report.exists() && calibration.join("runs.jsonl").is_file() {
        return Err(CliError::Input(format!(
            "{}: not there: the calibration in {} has runs but no report (it is running, \
             was stopped, or ended in an error); run its calibrate command again, which \
             resumes from its runs, then diagnose",
            report.display(),
            calibration.display()
        )));
    }
    for name in ["report.json", "runs.jsonl"] {
        let path = calibration.join(name);
        if std::fs::metadata(&path).is_ok_and(|m| !m.is_file()) {
            return Err(CliError::Input(format!(
                "{}: not a regular file (a directory, FIFO, socket or device); --calibration \
                 is the directory `kalibre calibrate --out` wrote",
                path.display()
            )));
        }
    }
    Ok(())
}
