//! What differs when `--out`'s run journal holds another model's runs: the model's
//! settings recorded in `report.json` (`--model`, `--grid-m`, `--alpha`, OpenFOAM's
//! options) and the parameters the journal's runs were made over, named one by one
//! instead of a bare "another model".

use std::path::Path;

use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::ParamLayout;

use super::super::calibrated_model::CalibratedModel;
use super::super::{hall_changes, CliError};

/// The refusal of a journal of `runs` runs of another model (the first on `first_line`),
/// with what differs between the calibration that wrote it and this one (`current`, over
/// `hall`).
pub(super) fn explain(
    journal: &Path,
    (runs, first_line): (usize, Option<usize>),
    current: &CalibratedModel,
    hall: &Hall,
    hall_file: &Path,
) -> CliError {
    let out = journal.parent().unwrap_or(Path::new("."));
    let mut differences = recorded_settings(&out.join("report.json"), current);
    if let Some(d) = parameters(journal, hall) {
        differences.push(d);
    }
    // A command model's runs depend on its configuration, not on hall.json's fields.
    let hall_changes = match current.kind.as_str() {
        "command" => None,
        _ => hall_changes::since_runs(out, hall_file),
    };
    let hall_unchanged = hall_changes.as_ref().is_some_and(|c| c.is_empty());
    if let Some(changes) = hall_changes.filter(|c| !c.is_empty()) {
        differences.push(hall_changes::describe(out, hall_file, &changes));
    }
    let why = match (differences.is_empty(), hall_unchanged) {
        (false, _) => differences.join("; "),
        (true, true) => format!(
            "the same model settings, parameters and hall ({} reads as {}, on which they \
             were made, bounds and initial values aside), so the model's configuration \
             changed since (another --config), or another kalibre version made them (before \
             bounds and initial values were left out of the model's fingerprint, runs were \
             journaled under the ones they were made with: calibrate with those to reuse \
             them)",
            hall_file.display(),
            out.join(hall_changes::RUNS_HALL).display()
        ),
        (true, false) => "the same model settings and parameters, so hall.json (its \
                          geometry, servers or effects) or the model's configuration \
                          changed since"
            .to_string(),
    };
    let from = first_line.map_or_else(String::new, |l| format!(" (the first on line {l})"));
    CliError::Input(format!(
        "{}: holds {runs} runs of another model{from}: {why}. Calibrate into another --out \
         (or move runs.jsonl away to start afresh)",
        journal.display()
    ))
}

/// The settings of `report.json`'s model record that differ from `current`'s, as flags.
fn recorded_settings(report: &Path, current: &CalibratedModel) -> Vec<String> {
    let Some(json) = std::fs::read_to_string(report)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
    else {
        return Vec::new();
    };
    let Ok(Some(theirs)) = CalibratedModel::of_report(report, json.get("model")) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut differ = |flag: &str, a: String, b: String| {
        if a != b {
            out.push(format!("its runs are {flag} {a}, this calibration's {b}"));
        }
    };
    let opt = |v: Option<String>| v.unwrap_or_else(|| "(none)".into());
    differ("--model", theirs.kind.clone(), current.kind.clone());
    differ(
        "--grid-m",
        opt(theirs.grid_m.map(|g| format!("{g}"))),
        opt(current.grid_m.map(|g| format!("{g}"))),
    );
    // As the flag spells it: `per_type` in the record, `per-type` on the command line.
    let alpha = |m: &kalibre_dc::hall::AlphaMode| {
        serde_json::to_value(m)
            .ok()
            .and_then(|v| v.as_str().map(|s| s.replace('_', "-")))
            .unwrap_or_else(|| format!("{m:?}"))
    };
    differ("--alpha", alpha(&theirs.alpha), alpha(&current.alpha));
    differ(
        "--of-iterations",
        opt(theirs.of_iterations.map(|i| i.to_string())),
        opt(current.of_iterations.map(|i| i.to_string())),
    );
    differ(
        "--np",
        opt(theirs.np.map(|i| i.to_string())),
        opt(current.np.map(|i| i.to_string())),
    );
    out
}

/// The journal's parameters against this calibration's (`--alpha`, effects added or
/// taken away), when they differ.
fn parameters(journal: &Path, hall: &Hall) -> Option<String> {
    let effects = EffectRegistry::builtin().build_all(hall).ok()?;
    let ours = ParamLayout::new(hall, &effects).ok()?.space().names();
    let text = std::fs::read_to_string(journal).ok()?;
    let theirs: Vec<String> = text
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| serde_json::from_value(v["param_names"].clone()).ok())
        .find(|names: &Vec<String>| *names != ours)?;
    let only = |a: &[String], b: &[String]| -> Vec<String> {
        a.iter().filter(|n| !b.contains(n)).cloned().collect()
    };
    let list = |names: Vec<String>| match names.len() {
        0 => "none".to_string(),
        _ => crate::cli::some_names(&names),
    };
    let (gone, new) = (only(&theirs, &ours), only(&ours, &theirs));
    Some(if gone.is_empty() && new.is_empty() {
        "its runs have the same parameters in another order".into()
    } else {
        format!(
            "its runs have parameters this calibration lacks: {}; this calibration has \
             parameters they lack: {}",
            list(gone),
            list(new)
        )
    })
}
