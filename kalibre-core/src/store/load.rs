//! Reading a journal back: each line parsed and checked, the runs of this model keyed,
//! repeats and conflicts counted, a torn last line told from another file's text.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{key, Key, Repair, RunRecord, RunStatus};
use crate::{Error, Result};

/// A journal line that could not be used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BadLine {
    /// 1-based line number.
    pub line: usize,
    /// Why it was skipped.
    pub reason: String,
}

/// What opening a journal found.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadReport {
    /// Complete lines read (the torn tail excluded).
    pub lines: usize,
    /// Runs loaded into the cache.
    pub loaded: usize,
    /// Runs of another model fingerprint (neither the store's nor one of its aliases),
    /// ignored.
    pub other_fingerprint: usize,
    /// The line of the first of them (1-based), so that a journal mixing two models'
    /// runs can be looked at where it starts to. Missing in older reports: `None`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub other_fingerprint_first_line: Option<usize>,
    /// Repeated keys (the first record is kept).
    pub duplicates: usize,
    /// The repeats among them whose result differs from the kept one (other outputs, or
    /// failed where it ran): one of the two is wrong, so each is named. Missing in older
    /// reports: empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub conflicts: Vec<BadLine>,
    /// Runs (distinct points) journaled only as failed: not replayed, so that a
    /// failure whose cause has passed (a timeout, a crashed license server, a setting
    /// since fixed) does not stick; they run again when asked for. Within one opening
    /// of the store a failed run is replayed like any other. Missing in older reports: 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub failed_to_retry: usize,
    /// Runs journaled only as failed, kept to replay as failures where asked for, when the store was opened
    /// with [`RunStore::open_replaying_failures`](super::RunStore::open_replaying_failures) (`failed_to_retry` is then 0). Missing in
    /// older reports: 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub failed_replayed: usize,
    /// Complete lines that could not be parsed, skipped.
    pub bad_lines: Vec<BadLine>,
    /// A torn last line (no trailing newline and unparsable), cut off the file.
    pub torn_tail: Option<BadLine>,
}

impl LoadReport {
    /// True when every line was read cleanly.
    pub fn is_clean(&self) -> bool {
        self.bad_lines.is_empty() && self.torn_tail.is_none()
    }
}

/// How every journal line begins (`RunRecord`'s first field).
const RECORD_START: &str = r#"{"seq":"#;

/// Whether a line cut off mid-write could be this: a run record's beginning.
fn could_start_a_record(tail: &[u8]) -> bool {
    let start = RECORD_START.as_bytes();
    tail.starts_with(start) || start.starts_with(tail)
}

/// A file at the journal's path that is not one: refused, never cut or appended to.
fn not_a_journal(path: &Path, why: String) -> Error {
    Error::Journal {
        path: path.display().to_string(),
        reason: format!(
            "not a kalibre run journal: {why}; kalibre neither cuts nor appends to it: move \
             it, or write the calibration elsewhere"
        ),
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// What a journal's bytes hold for one model.
pub(super) struct Loaded {
    /// Each run with its 1-based line.
    pub(super) runs: HashMap<Key, (usize, RunRecord)>,
    /// The highest sequence number of any record (of any model).
    pub(super) max_seq: Option<u64>,
    /// Lines in the file once repaired.
    pub(super) lines: usize,
    /// What the file's end needs before the next line is appended.
    pub(super) repair: Option<Repair>,
    /// What was found.
    pub(super) load: LoadReport,
}

/// Reads the journal `bytes` (of the file at `path`) for the model `fingerprint`, whose
/// runs may also be journaled under its `aliases`; with `replay_failed`, a point
/// journaled only as failed is kept as that failure.
pub(super) fn read(
    bytes: &[u8],
    path: &Path,
    fingerprint: &str,
    aliases: &[String],
    replay_failed: bool,
) -> Result<Loaded> {
    let mut load = LoadReport::default();
    let mut runs: HashMap<_, (usize, RunRecord)> = HashMap::new();
    let mut failed = HashSet::new();
    let mut max_seq: Option<u64> = None;
    let complete_len = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let mut records = 0usize;
    let mut take = |line: usize, rec: RunRecord, load: &mut LoadReport| {
        records += 1;
        max_seq = Some(max_seq.map_or(rec.seq, |m: u64| m.max(rec.seq)));
        if rec.fingerprint != fingerprint && !aliases.contains(&rec.fingerprint) {
            load.other_fingerprint += 1;
            load.other_fingerprint_first_line.get_or_insert(line);
            return;
        }
        let k = key(
            &rec.scenario,
            &rec.scenario_key,
            &rec.param_names,
            &rec.params,
        );
        match runs.entry(k) {
            // Only a result is replayed; a failure is tried again (a later `ok` line
            // of the same point is that retry's result).
            Entry::Vacant(v) if rec.status == RunStatus::Failed && !replay_failed => {
                failed.insert(v.into_key());
            }
            // A replayed failure gives way to a retry's result; a retry that failed
            // again is the same failure (as it is when failures are not replayed).
            Entry::Occupied(mut kept)
                if replay_failed && kept.get().1.status == RunStatus::Failed =>
            {
                if rec.status == RunStatus::Ok {
                    kept.insert((line, rec));
                }
            }
            Entry::Occupied(kept) => {
                load.duplicates += 1;
                let (first_line, first): &(usize, RunRecord) = kept.get();
                if first.status != rec.status || first.outputs != rec.outputs {
                    load.conflicts.push(BadLine {
                        line,
                        reason: format!(
                            "repeats the run of line {first_line} with another result; \
                             line {first_line}'s is used"
                        ),
                    });
                }
            }
            Entry::Vacant(v) => {
                v.insert((line, rec));
                load.loaded += 1;
            }
        }
    };
    for (i, line) in bytes[..complete_len].split(|&b| b == b'\n').enumerate() {
        if line.is_empty() {
            continue;
        }
        load.lines += 1;
        match parse(line) {
            Ok(rec) => take(i + 1, rec, &mut load),
            Err(reason) => load.bad_lines.push(BadLine {
                line: i + 1,
                reason,
            }),
        }
    }
    let tail = &bytes[complete_len..];
    let tail_line = bytes[..complete_len]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1;
    let mut repair = None;
    let mut lines = tail_line - 1;
    if !tail.is_empty() {
        match parse(tail) {
            // Only the newline is missing: the record is whole.
            Ok(rec) => {
                load.lines += 1;
                take(tail_line, rec, &mut load);
                repair = Some(Repair::Newline);
                lines = tail_line;
            }
            // Whole JSON that is not a run record is a bad line like any other,
            // kept in the file; only text cut off mid-write is torn.
            Err(reason) if serde_json::from_slice::<serde_json::Value>(tail).is_ok() => {
                load.lines += 1;
                load.bad_lines.push(BadLine {
                    line: tail_line,
                    reason,
                });
                repair = Some(Repair::Newline);
                lines = tail_line;
            }
            // Text that cannot be the start of a record is another file's, not a
            // crash's: cutting it would destroy it.
            Err(_) if !could_start_a_record(tail) => {
                return Err(not_a_journal(
                    path,
                    format!(
                        "its last line ({} bytes, no newline) is not a run record cut off \
                         mid-write (those start with {RECORD_START})",
                        tail.len()
                    ),
                ));
            }
            Err(reason) => {
                load.torn_tail = Some(BadLine {
                    line: tail_line,
                    reason: format!("torn last line ({} bytes): {reason}", tail.len()),
                });
                repair = Some(Repair::CutTo(complete_len as u64));
            }
        }
    }
    if records == 0 {
        if let Some(first) = load.bad_lines.first() {
            return Err(not_a_journal(
                path,
                format!(
                    "none of its {} line(s) is a run record (line {}: {})",
                    load.lines, first.line, first.reason
                ),
            ));
        }
    }
    load.failed_to_retry = failed.iter().filter(|k| !runs.contains_key(*k)).count();
    if replay_failed {
        let replayed = runs.values().filter(|(_, r)| r.status == RunStatus::Failed);
        load.failed_replayed = replayed.count();
        load.loaded -= load.failed_replayed;
    }
    Ok(Loaded {
        runs,
        max_seq,
        lines,
        repair,
        load,
    })
}

fn parse(line: &[u8]) -> std::result::Result<RunRecord, String> {
    let rec: RunRecord = serde_json::from_slice(line).map_err(|e| e.to_string())?;
    rec.check()?;
    Ok(rec)
}
