//! What changed in a hall file since a calibration's runs were made. `kalibre calibrate`
//! keeps the hall.json it started its journal with as `--out`'s `runs-hall.json`; when a
//! later calibration or diagnosis is refused because the journal holds another model's
//! runs, the two halls are compared field by field, so the refusal can say which rack,
//! CRAC or sensor changed instead of "hall.json changed".

use std::path::Path;

use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use serde_json::Value;

use super::{io_err, CliResult};

/// The copy of the hall.json a calibration directory's runs were made on.
pub const RUNS_HALL: &str = "runs-hall.json";

/// How many changed fields a message lists before "and N more".
const LISTED: usize = 4;

/// Keeps `hall_file` as `out`'s [`RUNS_HALL`] when `journal` holds no run yet (missing or
/// empty), so that it describes the runs about to be made. A journal with runs keeps the
/// copy made when it was started.
pub fn keep_runs_hall(out: &Path, hall_file: &Path, journal: &Path) -> CliResult {
    let started = std::fs::metadata(journal).is_ok_and(|m| m.len() > 0);
    if started {
        return Ok(());
    }
    let bytes = std::fs::read(hall_file).map_err(|e| io_err(hall_file, e))?;
    let copy = out.join(RUNS_HALL);
    kalibre_core::write_atomic(&copy, bytes).map_err(|e| io_err(&copy, e))
}

/// The hall's changes since the runs of the calibration directory `dir`: `None` when the
/// directory keeps no copy of their hall (made before copies were kept) or it cannot be
/// read; else the changed fields as `pointer: before -> now`, empty when none of the
/// model's fields changed (the name, `extra` notes and the calibrated parameters' bounds
/// and initial values are not the model's).
pub fn since_runs(dir: &Path, hall_file: &Path) -> Option<Vec<String>> {
    let before = physics(&dir.join(RUNS_HALL))?;
    let now = physics(hall_file)?;
    let mut changes = Vec::new();
    diff(&before, &now, &mut String::new(), None, &mut changes);
    Some(changes)
}

/// `changes` as one clause for an error message, naming `hall_file` and the copy in
/// `dir` it was compared with.
pub fn describe(dir: &Path, hall_file: &Path, changes: &[String]) -> String {
    let more = changes.len().saturating_sub(LISTED);
    let mut listed = changes
        .iter()
        .take(LISTED)
        .cloned()
        .collect::<Vec<_>>()
        .join("; ");
    if more > 0 {
        listed.push_str(&format!("; and {more} more"));
    }
    format!(
        "{} changed since its runs (they were made on {}): {listed}",
        hall_file.display(),
        dir.join(RUNS_HALL).display()
    )
}

/// `"; <describe>"` when `hall_file` changed since the runs of `dir`, else nothing: the
/// tail of a refusal that names the model's other differences itself.
pub fn clause(dir: &Path, hall_file: &Path) -> String {
    match since_runs(dir, hall_file) {
        Some(changes) if !changes.is_empty() => {
            format!("; {}", describe(dir, hall_file, &changes))
        }
        _ => String::new(),
    }
}

/// The hall's fields the model reads, as JSON: as the model's fingerprint hashes it
/// ([`Hall::model_json`]: its name and notes cleared, and the calibrated parameters'
/// bounds and initial values left out, which change no run), so that only what makes
/// the runs another model's is named. A hall whose effects do not build (a kind the
/// built-in registry lacks) is compared with its effects' entries as written.
fn physics(path: &Path) -> Option<Value> {
    let hall = Hall::load(path).ok()?;
    let text = match EffectRegistry::builtin().build_all(&hall) {
        Ok(effects) => hall.model_json(hall.calibrate.alpha, &effects),
        Err(_) => hall.physics_json(),
    };
    serde_json::from_str(&text).ok()
}

/// Appends to `out` each difference between `before` and `now` at `pointer` (a JSON
/// pointer into the hall), `id` being the id of the innermost entry it is in.
fn diff(
    before: &Value,
    now: &Value,
    pointer: &mut String,
    id: Option<&str>,
    out: &mut Vec<String>,
) {
    match (before, now) {
        (Value::Object(a), Value::Object(b)) => {
            let keys = a.keys().chain(b.keys().filter(|k| !a.contains_key(*k)));
            for key in keys {
                let len = pointer.len();
                pointer.push('/');
                pointer.push_str(key);
                match (a.get(key), b.get(key)) {
                    (Some(x), Some(y)) => diff(x, y, pointer, id, out),
                    (Some(x), None) => out.push(change(pointer, id, &render(x), "none")),
                    (None, Some(y)) => out.push(change(pointer, id, "none", &render(y))),
                    (None, None) => {}
                }
                pointer.truncate(len);
            }
        }
        (Value::Array(a), Value::Array(b)) if has_ids(a) && has_ids(b) => {
            diff_by_id(a, b, pointer, out)
        }
        (Value::Array(a), Value::Array(b)) if a.len() == b.len() && !is_leaf(a) => {
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                let len = pointer.len();
                pointer.push_str(&format!("/{i}"));
                diff(x, y, pointer, id, out);
                pointer.truncate(len);
            }
        }
        (x, y) if x != y => out.push(change(pointer, id, &render(x), &render(y))),
        _ => {}
    }
}

/// Entries matched by their `id` (racks, servers, CRACs, sensors ...), so that one
/// added or removed entry reads as that, not as every later entry changed.
fn diff_by_id(before: &[Value], now: &[Value], pointer: &mut String, out: &mut Vec<String>) {
    let id_of = |v: &Value| v["id"].as_str().unwrap_or_default().to_string();
    let before_ids: Vec<String> = before.iter().map(id_of).collect();
    let now_ids: Vec<String> = now.iter().map(id_of).collect();
    for (i, id) in before_ids.iter().enumerate() {
        if !now_ids.contains(id) {
            out.push(format!("{pointer}/{i} ({id}): removed"));
        }
    }
    let mut kept_order = Vec::new();
    for (i, entry) in now.iter().enumerate() {
        let id = &now_ids[i];
        match before_ids.iter().position(|b| b == id) {
            None => out.push(format!("{pointer}/{i} ({id}): added")),
            Some(j) => {
                kept_order.push(j);
                let len = pointer.len();
                pointer.push_str(&format!("/{i}"));
                diff(&before[j], entry, pointer, Some(id), out);
                pointer.truncate(len);
            }
        }
    }
    // The sensors' order is the outputs' order, so a reordering is a change of its own.
    if kept_order.windows(2).any(|w| w[0] > w[1]) {
        out.push(format!("{pointer}: the same entries in another order"));
    }
}

/// Every entry an object with a string `id`.
fn has_ids(entries: &[Value]) -> bool {
    !entries.is_empty() && entries.iter().all(|v| v["id"].is_string())
}

/// An array of numbers or strings (a position, a size): shown whole when it changes.
fn is_leaf(entries: &[Value]) -> bool {
    entries.iter().all(|v| !v.is_object() && !v.is_array())
}

fn change(pointer: &str, id: Option<&str>, before: &str, now: &str) -> String {
    let at = match id {
        Some(id) => format!("{pointer} ({id})"),
        None if pointer.is_empty() => "/".into(),
        None => pointer.to_string(),
    };
    format!("{at}: {before} -> {now}")
}

/// A value compactly, cut to a readable length.
fn render(v: &Value) -> String {
    let text = v.to_string();
    if text.chars().count() <= 40 {
        return text;
    }
    let cut: String = text.chars().take(37).collect();
    format!("{cut}...")
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn changes(a: Value, b: Value) -> Vec<String> {
        let mut out = Vec::new();
        diff(&a, &b, &mut String::new(), None, &mut out);
        out
    }

    #[test]
    fn names_a_moved_rack_by_its_pointer_and_id() {
        let a = json!({"racks": [{"id": "A1", "position_m": [1.0, 2.0, 0.0]},
                                 {"id": "A2", "position_m": [2.0, 2.0, 0.0]}]});
        let b = json!({"racks": [{"id": "A1", "position_m": [1.0, 2.0, 0.0]},
                                 {"id": "A2", "position_m": [2.5, 2.0, 0.0]}]});
        assert_eq!(
            changes(a, b),
            ["/racks/1/position_m (A2): [2.0,2.0,0.0] -> [2.5,2.0,0.0]"]
        );
    }

    #[test]
    fn an_added_or_removed_entry_is_one_change() {
        let a = json!({"sensors": [{"id": "s1", "z": 1}, {"id": "s2", "z": 1},
                                   {"id": "s3", "z": 1}]});
        let b = json!({"sensors": [{"id": "s1", "z": 1}, {"id": "s3", "z": 1},
                                   {"id": "s4", "z": 1}]});
        assert_eq!(
            changes(a, b),
            ["/sensors/1 (s2): removed", "/sensors/2 (s4): added"]
        );
    }

    #[test]
    fn a_reordering_is_named() {
        let a = json!({"sensors": [{"id": "s1"}, {"id": "s2"}]});
        let b = json!({"sensors": [{"id": "s2"}, {"id": "s1"}]});
        assert_eq!(
            changes(a, b),
            ["/sensors: the same entries in another order"]
        );
    }

    #[test]
    fn fields_added_and_removed_and_long_values_cut() {
        let a = json!({"room": {"size_m": [10.0, 8.0, 3.0]}, "effects": []});
        let b = json!({"room": {"size_m": [10.0, 8.0, 3.0], "plenum_m": 0.6},
                       "effects": [{"kind": "bypass", "fraction": 0.1, "behind_rack": "A03"}]});
        let got = changes(a, b);
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(
            got.contains(&"/room/plenum_m: none -> 0.6".to_string()),
            "{got:?}"
        );
        let effects = got.iter().find(|c| c.starts_with("/effects: [] -> [{"));
        assert!(effects.is_some_and(|c| c.ends_with("...")), "{got:?}");
        assert!(changes(json!({"a": 1}), json!({"a": 1})).is_empty());
    }

    #[test]
    fn describe_lists_four_and_counts_the_rest() {
        let all: Vec<String> = (0..6).map(|i| format!("/x/{i}: 0 -> 1")).collect();
        let text = describe(Path::new("out"), Path::new("hall.json"), &all);
        assert!(
            text.starts_with("hall.json changed since its runs (they were made on out/"),
            "{text}"
        );
        assert!(text.contains("/x/3: 0 -> 1; and 2 more"), "{text}");
        assert!(!text.contains("/x/4"), "{text}");
    }
}
