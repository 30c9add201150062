//! `--params`: parameter values from a JSON object of name -> value, or from a
//! calibration's `report.json` (its best parameters, and the model it recorded).

use std::path::Path;

use kalibre_core::calibrate::REPORT_SCHEMA;
use kalibre_core::ParamSpace;

use super::calibrated_model::CalibratedModel;
use super::{say, CliError, CliResult};

/// Reads a `--params` file: a JSON object, or a calibration's `report.json` with the model
/// it recorded (if any).
pub(in crate::cli) fn read_params_file(
    path: &Path,
) -> CliResult<(serde_json::Value, Option<CalibratedModel>)> {
    let json = read_params_json(path)?;
    // Only a report (one with `best`) records a model; a plain object is all parameters.
    let recorded = match json.get("best") {
        Some(_) => CalibratedModel::of_report(path, json.get("model"))?,
        None => None,
    };
    Ok((json, recorded))
}

/// A `--params` file's JSON: no key given twice, and a report's schema ours.
pub(in crate::cli) fn read_params_json(path: &Path) -> CliResult<serde_json::Value> {
    let file = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    // A byte-order mark some Windows editors write: an encoding marker, not JSON (as
    // hall.json takes it).
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let json: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| CliError::Input(format!("{file}: not valid JSON: {e}")))?;
    // A parameter named twice would keep its last value without a word.
    if let Some((field, message)) = kalibre_dc::json_keys::duplicate_key_problem(text) {
        return Err(CliError::Input(format!("{file}: {field}: {message}")));
    }
    if json.get("best").is_some() {
        match json.get("schema") {
            Some(serde_json::Value::String(s)) if s == REPORT_SCHEMA => {}
            None => {}
            Some(other) => {
                return Err(CliError::Input(format!(
                    "{file}: /schema: expected \"{REPORT_SCHEMA}\", found {other}"
                )))
            }
        }
    }
    Ok(json)
}

/// Parameter values by name from a JSON object or a report's `best.params` (`json`, read
/// from `path`).
pub(in crate::cli) fn load_params(
    path: &Path,
    json: &serde_json::Value,
    space: &ParamSpace,
) -> CliResult<Vec<f64>> {
    let file = path.display().to_string();
    let (map, pointer) = match json.get("best").and_then(|b| b.get("params")) {
        Some(p) => (p, "/best/params"),
        None => (json, ""),
    };
    let map = map.as_object().ok_or_else(|| {
        CliError::Input(format!(
            "{file}: {}: expected an object of parameter name -> value",
            if pointer.is_empty() { "/" } else { pointer }
        ))
    })?;
    let mut values = space.initial();
    for (name, v) in map {
        // The key as a JSON pointer (RFC 6901: `alpha/db` is `alpha~1db`), and the name
        // beside it where the escape hides it.
        let escaped = kalibre_dc::json_keys::escape_pointer_token(name);
        let field = if escaped == *name {
            format!("{pointer}/{name}")
        } else {
            format!("{pointer}/{escaped} (`{name}`)")
        };
        let i = space.index_of(name).ok_or_else(|| {
            CliError::Input(format!(
                "{file}: {field}: unknown parameter (known: {})",
                super::some_names(&space.names())
            ))
        })?;
        let x = v
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| CliError::Input(format!("{file}: {field}: expected a finite number")))?;
        values[i] = x;
    }
    // A report names every parameter it calibrated: one missing is an edit, not a value
    // to take from the hall (a hand-written object may leave some at their initial).
    let names = space.names();
    let missing: Vec<String> = (names.iter())
        .filter(|n| !map.contains_key(*n))
        .cloned()
        .collect();
    if !pointer.is_empty() {
        if let Some(missing) = missing.first() {
            return Err(CliError::Input(format!(
                "{file}: {pointer}: no value of `{missing}` (a calibration report has every \
                 calibrated parameter; is it of another hall?)"
            )));
        }
    } else if !missing.is_empty() {
        // Documented, but a short object is as likely a slip as a choice: said once.
        say!(
            "note: {file} gives no value of {} of the {} parameters ({}): they keep their \
             initial values",
            missing.len(),
            names.len(),
            super::some_names(&missing)
        );
    }
    space
        .check_physical(&values)
        .map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    Ok(values)
}
