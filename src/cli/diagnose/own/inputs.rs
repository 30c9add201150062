//! What a diagnosis of a model of your own checks before any run: the calibration's
//! report is of this model and these measurements, and its journal holds the calibrated
//! runs.

use std::path::Path;

use kalibre_core::calibrate::{Report, REPORT_SCHEMA};
use kalibre_core::external::{CommandModelConfig, NamedScenario};
use kalibre_core::{Model, Observations};

use super::super::super::calibrate::generic::errors_in;
use super::super::super::params_file::load_params;
use super::super::super::{significant, CliError, CliResult};

/// The calibration's report and its best parameters, refused when it is of another model
/// than `cfg` (its fingerprint recorded otherwise) or not a calibration of one's own.
pub(super) fn read_report(
    report_path: &Path,
    cfg: &CommandModelConfig,
    config: &Path,
    measurements_scaled: bool,
) -> CliResult<(Report, Vec<f64>)> {
    let file = report_path.display();
    if !report_path.exists() {
        let dir = report_path.parent().unwrap_or(Path::new("."));
        return Err(CliError::Input(format!(
            "{file}: no calibration there yet: calibrate first, with kalibre calibrate \
             --model command --config {} --measurements FILE --out {}",
            crate::cli::shell_word(config),
            crate::cli::shell_word(dir)
        )));
    }
    let text = std::fs::read_to_string(report_path)
        .map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    let json: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| CliError::Input(format!("{file}: not valid JSON: {e}")))?;
    let report: Report = serde_json::from_value(json.clone())
        .map_err(|e| CliError::Input(format!("{file}: not a kalibre report: {e}")))?;
    if report.schema != REPORT_SCHEMA {
        return Err(CliError::Input(format!(
            "{file}: /schema: expected \"{REPORT_SCHEMA}\", found \"{}\"",
            report.schema
        )));
    }
    let kind = json.pointer("/model/kind").and_then(|k| k.as_str());
    if kind != Some("command") || json.pointer("/model/config").is_none() {
        return Err(CliError::Input(format!(
            "{file}: /model: not a calibration of a model of your own (kind {}); diagnose a \
             hall's with --hall and --snapshots",
            kind.map_or("not recorded".to_string(), |k| format!("`{k}`"))
        )));
    }
    let recorded = json.pointer("/model/fingerprint").and_then(|f| f.as_str());
    if recorded != Some(cfg.command.fingerprint().as_str()) {
        let parts =
            report_path.with_file_name(super::super::super::calibrate::generic::MODEL_PARTS);
        let what = super::super::super::calibrate::generic::changed_since(&parts, cfg)
            .unwrap_or_else(|| {
                "its program, arguments, templates, outputs, parameters or a file of \
                 fingerprint_files changed since"
                    .to_string()
            });
        return Err(CliError::Input(format!(
            "{file}: /model/fingerprint: the calibration ran another model than {} ({what}): \
             calibrate it into another --out (this one's journal holds the other model's \
             runs), then diagnose that",
            config.display()
        )));
    }
    let recorded_in = json.pointer("/model/errors_in").and_then(|e| e.as_str());
    if let Some(recorded_in) = recorded_in {
        if recorded_in != errors_in(measurements_scaled) {
            return Err(CliError::Input(format!(
                "{file}: /model/errors_in: the calibration weighed the errors in {recorded_in}, \
                 these measurements {} (an `sd` column {}): diagnose with the calibration's \
                 measurements, or calibrate again",
                if measurements_scaled {
                    "in sd"
                } else {
                    "in the outputs' units"
                },
                if measurements_scaled {
                    "added"
                } else {
                    "removed"
                }
            )));
        }
    }
    // A candidate held at another value than the calibration's, or one added or turned
    // into a calibrated parameter since, is a model.toml edit: named there.
    for c in cfg.candidates.iter().flat_map(|c| &c.params) {
        let was = (json.pointer(&format!("/best/params/{}", c.name))).and_then(|v| v.as_f64());
        if let Some(was) = was.filter(|was| *was != c.absent) {
            return Err(CliError::Input(format!(
                "{}: `params[{}].absent` is {}, but the calibration ran `{}` at {}: \
                 calibrate again with the candidates as they are now, then diagnose",
                config.display(),
                c.index,
                kalibre_core::number(c.absent),
                c.name,
                kalibre_core::number(was)
            )));
        }
    }
    // A candidate then that is calibrated now: this model.toml's calibration is not the
    // one in the report (older reports do not record their candidates).
    if let Some(then) = json
        .pointer("/model/candidates")
        .and_then(|c| c.as_object())
    {
        // Still held there: a candidate, or a parameter fixed at the same value.
        let held = |name: &str, absent: Option<f64>| {
            let candidate =
                (cfg.candidates.iter()).any(|c| c.params.iter().any(|p| p.name == name));
            let fixed = (cfg.space.params().iter())
                .any(|p| p.name == name && p.is_fixed() && Some(p.lower) == absent);
            candidate || fixed
        };
        if let Some(name) = (then.iter())
            .find(|(n, absent)| !held(n, absent.as_f64()))
            .map(|(n, _)| n)
        {
            return Err(CliError::Input(format!(
                "{}: `{name}` is calibrated here, but the calibration held it absent (a \
                 candidate then): calibrate with this model.toml first (into the same --out, \
                 which resumes), then diagnose",
                config.display()
            )));
        }
    }
    let params = load_params(report_path, &json, &cfg.space)?;
    Ok((report, params))
}

/// The report's residual rows must be these measurements: a diagnosis against other data
/// than the calibration's would credit effects with the difference.
pub(super) fn check_same_measurements(
    report_path: &Path,
    report: &Report,
    obs: &Observations<NamedScenario>,
    measurements: &Path,
) -> CliResult {
    let outputs = obs.outputs();
    let mut rows = 0;
    for s in obs.snapshots() {
        for (o, m) in outputs.iter().zip(&s.measured) {
            let Some(m) = m else { continue };
            rows += 1;
            let fitted = (report.residuals.iter())
                .find(|r| r.snapshot == s.label && r.sensor == o.name)
                .map(|r| r.measured_c);
            let same = fitted.is_some_and(|f| (f - m).abs() <= 1e-9 * m.abs().max(1.0));
            if !same {
                let what = match fitted {
                    Some(f) => format!(
                        "`{}` in `{}` reads {} here, {} in the calibration",
                        o.name,
                        s.label,
                        significant(*m, 6),
                        significant(f, 6)
                    ),
                    None => format!("`{}` in `{}` was not in the calibration", o.name, s.label),
                };
                return Err(not_the_measurements(report_path, measurements, &what));
            }
        }
    }
    if rows != report.residuals.len() {
        let what = format!(
            "{rows} measurements here, {} in the calibration",
            report.residuals.len()
        );
        return Err(not_the_measurements(report_path, measurements, &what));
    }
    Ok(())
}

/// The journal must hold the calibration's runs at its parameters, answering what the
/// report recorded, before any step runs: a scenario's variables edited since (not in the
/// model's fingerprint) have no run there, and the diagnosis would explain the edit.
pub(super) fn check_calibrated_runs(
    store: &kalibre_core::RunStore,
    cfg: &CommandModelConfig,
    obs: &Observations<NamedScenario>,
    params: &[f64],
    report: &Report,
    config: &Path,
) -> CliResult {
    let names = cfg.space.names();
    let journal = store
        .path()
        .map_or_else(String::new, |p| p.display().to_string());
    for s in obs.snapshots() {
        let key = cfg.command.scenario_key(&s.scenario);
        let outputs = store
            .get_keyed(&s.label, &key, &names, params)
            .and_then(|(_, rec)| rec.result().ok());
        let Some(outputs) = outputs else {
            return Err(CliError::Input(format!(
                "{}: scenario `{}`: {journal} has no run of the calibrated parameters under \
                 its variables as they are now: they changed since the calibration (or the \
                 journal lost the run); calibrate again, then diagnose",
                config.display(),
                s.label
            )));
        };
        for ((o, m), v) in (obs.outputs().iter()).zip(&s.measured).zip(&outputs.values) {
            if m.is_none() {
                continue;
            }
            let recorded = (report.residuals.iter())
                .find(|r| r.snapshot == s.label && r.sensor == o.name)
                .map(|r| r.predicted_c);
            // The report keeps (v / scale) * scale with an sd column: equal to v but for
            // its last bit or so.
            if recorded.is_some_and(|r| (r - v).abs() > 1e-12 * r.abs().max(v.abs())) {
                return Err(CliError::Input(format!(
                    "{journal}: scenario `{}`: the run at the calibrated parameters gives {} for \
                     `{}`, where the report recorded {}: the report is not this journal's; \
                     calibrate again, then diagnose",
                    s.label,
                    significant(*v, 6),
                    o.name,
                    significant(recorded.unwrap_or_default(), 6)
                )));
            }
        }
    }
    Ok(())
}

fn not_the_measurements(report_path: &Path, measurements: &Path, what: &str) -> CliError {
    CliError::Input(format!(
        "{}: not the measurements {} was calibrated on: {what}; diagnose with the \
         calibration's measurements, or calibrate again",
        measurements.display(),
        report_path.display()
    ))
}
