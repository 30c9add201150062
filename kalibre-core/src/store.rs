//! The run journal and cache (`runs.jsonl`): one JSON line per finished model run.
//!
//! Every finished run, success or failure, is appended as one line, flushed and synced
//! before the loop goes on, so a crash loses at most the runs in flight. On open the
//! journal is read back; a torn last line (a crash mid-write) and unparsable lines are
//! reported in a [`LoadReport`] and skipped, never fatal. Runs are keyed by model
//! fingerprint, scenario label, parameter names and the exact bits of the physical
//! parameter values, so a restarted calibration finds every run it already did.

use std::collections::hash_map::Entry;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use crate::{number, Error, ModelError, Outputs, Result};

/// Whether a journaled run succeeded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// The run returned valid outputs.
    Ok,
    /// The run failed; `error` says why.
    Failed,
}

/// One line of `runs.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunRecord {
    /// Sequence number in the journal (order of finishing; 0-based).
    pub seq: u64,
    /// The model's fingerprint ([`crate::Model::fingerprint`]).
    pub fingerprint: String,
    /// Snapshot label of the scenario.
    pub scenario: String,
    /// The scenario's inputs ([`crate::Model::scenario_key`]); absent when the model
    /// gives none. A run is reused only under the same key.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub scenario_key: String,
    /// Parameter names, in order.
    pub param_names: Vec<String>,
    /// Physical parameter values, in order.
    pub params: Vec<f64>,
    /// Success or failure.
    pub status: RunStatus,
    /// Outputs of a successful run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outputs: Option<Vec<f64>>,
    /// Per-output spread of a successful run, when the model reports one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spread: Option<Vec<f64>>,
    /// What else a successful run computed, by name ([`Outputs::extras`]).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub extras: BTreeMap<String, Vec<f64>>,
    /// Why a failed run failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<ModelError>,
    /// Wall time of the run, seconds.
    pub wall_s: f64,
}

impl RunRecord {
    /// The run's result as the model returned it (after output checks).
    pub fn result(&self) -> std::result::Result<Outputs, ModelError> {
        match (&self.status, &self.outputs, &self.error) {
            (RunStatus::Ok, Some(values), _) => Ok(Outputs {
                values: values.clone(),
                spread: self.spread.clone(),
                extras: self.extras.clone(),
            }),
            (_, _, Some(e)) => Err(e.clone()),
            _ => Err(ModelError::failed(
                "journal record has neither outputs nor error",
            )),
        }
    }

    fn check(&self) -> std::result::Result<(), String> {
        if self.params.len() != self.param_names.len() {
            return Err(format!(
                "{} parameter values for {} names",
                self.params.len(),
                self.param_names.len()
            ));
        }
        if !(self.wall_s.is_finite() && self.wall_s >= 0.0) {
            return Err(format!("wall_s {} is not a duration", number(self.wall_s)));
        }
        // JSON has no NaN or infinity: such a value would be written as null, and the
        // journal could not be read back.
        let lists = [
            ("parameter", Some(&self.params)),
            ("output", self.outputs.as_ref()),
            ("spread", self.spread.as_ref()),
        ];
        for (what, values) in lists {
            if let Some((i, v)) = values
                .into_iter()
                .flatten()
                .enumerate()
                .find(|(_, v)| !v.is_finite())
            {
                return Err(format!("{what} {i} is not finite ({})", number(*v)));
            }
        }
        if let (Some(spread), Some(outputs)) = (&self.spread, &self.outputs) {
            if spread.len() != outputs.len() {
                return Err(format!(
                    "{} spreads for {} outputs",
                    spread.len(),
                    outputs.len()
                ));
            }
            // A spread is a standard deviation.
            if let Some((i, v)) = spread.iter().enumerate().find(|(_, v)| **v < 0.0) {
                return Err(format!("spread {i} is negative ({})", number(*v)));
            }
        }
        match self.status {
            RunStatus::Ok if self.outputs.is_none() => Err("status ok without outputs".into()),
            RunStatus::Failed if self.error.is_none() => Err("status failed without error".into()),
            _ => Ok(()),
        }
    }
}

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
    /// Runs of another model fingerprint, ignored.
    pub other_fingerprint: usize,
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
    /// Runs journaled only as failed and replayed as failures, when the store was opened
    /// with [`RunStore::open_replaying_failures`] (`failed_to_retry` is then 0). Missing in
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

/// Cache key: scenario label and inputs, parameter names and the exact bits of the
/// values.
type Key = (String, String, Vec<String>, Vec<u64>);

fn key(scenario: &str, scenario_key: &str, names: &[String], params: &[f64]) -> Key {
    (
        scenario.to_string(),
        scenario_key.to_string(),
        names.to_vec(),
        params.iter().map(|x| x.to_bits()).collect(),
    )
}

#[derive(Debug)]
struct Inner {
    /// Each run with its 1-based journal line (0 for an in-memory store).
    runs: HashMap<Key, (usize, RunRecord)>,
    next_seq: u64,
    /// Lines in the journal file, so an appended run knows its line.
    lines: usize,
    file: Option<File>,
    /// Runs asked for or recorded since the store was opened: the rest of the journal is
    /// what this session did not reach ([`RunStore::unreached`]).
    reached: HashSet<Key>,
    /// What the file's end needs before the next line is appended (a torn tail cut, a
    /// newline): done then, so that a command refused after opening the journal leaves
    /// the file as it found it.
    repair: Option<Repair>,
}

/// A journal end to mend before appending.
#[derive(Debug, Clone, Copy)]
enum Repair {
    /// Cut the file to this many bytes (a torn last line).
    CutTo(u64),
    /// End the last line, which is whole but has no newline.
    Newline,
}

/// The journal and cache of model runs of one model fingerprint.
///
/// ```
/// use kalibre_core::{Outputs, RunStore};
/// let store = RunStore::in_memory("model-v1");
/// let names = vec!["k".to_string()];
/// store.record("t0", &names, &[2.5], &Ok(Outputs::from(vec![1.0, 2.0])), 0.1).unwrap();
/// let hit = store.get("t0", &names, &[2.5]).unwrap();
/// assert_eq!(hit.outputs, Some(vec![1.0, 2.0]));
/// assert!(store.get("t0", &names, &[2.5000001]).is_none());
/// ```
#[derive(Debug)]
pub struct RunStore {
    fingerprint: String,
    path: Option<PathBuf>,
    inner: Mutex<Inner>,
    load: LoadReport,
}

impl RunStore {
    /// A store without a file (tests, or calibrations that need no journal).
    pub fn in_memory(fingerprint: impl Into<String>) -> Self {
        RunStore {
            fingerprint: fingerprint.into(),
            path: None,
            inner: Mutex::new(Inner {
                runs: HashMap::new(),
                next_seq: 0,
                lines: 0,
                file: None,
                reached: HashSet::new(),
                repair: None,
            }),
            load: LoadReport::default(),
        }
    }

    /// Opens (or creates) the journal at `path` for runs of the model with `fingerprint`.
    ///
    /// A torn last line is cut off the file before the next run is appended (nothing is
    /// written until then), so that later lines start clean; bad lines
    /// and runs of other fingerprints are skipped. See [`Self::load_report`].
    pub fn open(path: impl AsRef<Path>, fingerprint: impl Into<String>) -> Result<Self> {
        Self::open_impl(path.as_ref(), fingerprint.into(), false)
    }

    /// [`Self::open`], but a run journaled only as failed is replayed as that failure
    /// rather than run again ([`LoadReport::failed_replayed`] counts them): for failures
    /// that recur at the same point (a solver that diverges at a corner of the box),
    /// which a resume would otherwise pay for again. A later `ok` line of the same point
    /// (a retry's result) is replayed instead.
    ///
    /// ```
    /// use kalibre_core::{ModelError, RunStore};
    /// let path = std::env::temp_dir().join(format!("replay-doc-{}.jsonl", std::process::id()));
    /// let names = vec!["k".to_string()];
    /// {
    ///     let store = RunStore::open(&path, "model-v1").unwrap();
    ///     let failed = Err(ModelError::failed("diverged"));
    ///     store.record("t0", &names, &[3.0], &failed, 9.0).unwrap();
    /// }
    /// // A resume runs it again ...
    /// assert!(RunStore::open(&path, "model-v1").unwrap().get("t0", &names, &[3.0]).is_none());
    /// // ... unless the failures are replayed.
    /// let store = RunStore::open_replaying_failures(&path, "model-v1").unwrap();
    /// assert!(store.get("t0", &names, &[3.0]).unwrap().result().is_err());
    /// assert_eq!(store.load_report().failed_replayed, 1);
    /// # drop(store);
    /// # std::fs::remove_file(&path).unwrap();
    /// ```
    pub fn open_replaying_failures(
        path: impl AsRef<Path>,
        fingerprint: impl Into<String>,
    ) -> Result<Self> {
        Self::open_impl(path.as_ref(), fingerprint.into(), true)
    }

    fn open_impl(path: &Path, fingerprint: String, replay_failed: bool) -> Result<Self> {
        let path = path.to_path_buf();
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        // Two calibrations appending to one journal would each run what the other ran
        // (each reads the file once). The lock lives as long as the store; a file system
        // without locks is let through, as before.
        if let Err(std::fs::TryLockError::WouldBlock) = file.try_lock() {
            return Err(Error::Journal {
                path: path.display().to_string(),
                reason: "another calibration has it open (it holds the journal's lock); wait \
                         for it to finish, or give this one another journal"
                    .into(),
            });
        }
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes)
            .map_err(|e| Error::io(&path, e))?;

        let mut load = LoadReport::default();
        let mut runs: HashMap<_, (usize, RunRecord)> = HashMap::new();
        let mut failed = HashSet::new();
        let mut max_seq: Option<u64> = None;
        let complete_len = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        let mut records = 0usize;
        let mut take = |line: usize, rec: RunRecord, load: &mut LoadReport| {
            records += 1;
            max_seq = Some(max_seq.map_or(rec.seq, |m: u64| m.max(rec.seq)));
            if rec.fingerprint != fingerprint {
                load.other_fingerprint += 1;
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
                        &path,
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
                    &path,
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
        Ok(RunStore {
            fingerprint,
            path: Some(path),
            inner: Mutex::new(Inner {
                runs,
                next_seq: max_seq.map_or(0, |m| m.saturating_add(1)),
                lines,
                file: Some(file),
                reached: HashSet::new(),
                repair,
            }),
            load,
        })
    }

    /// The model fingerprint this store serves.
    pub fn fingerprint(&self) -> &str {
        &self.fingerprint
    }

    /// The journal file, when there is one.
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// What opening the journal found.
    pub fn load_report(&self) -> &LoadReport {
        &self.load
    }

    /// Number of cached runs.
    pub fn len(&self) -> usize {
        self.lock().runs.len()
    }

    /// True when no run is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cached run at exactly these parameter values, if any.
    pub fn get(&self, scenario: &str, names: &[String], params: &[f64]) -> Option<RunRecord> {
        self.get_with_line(scenario, names, params)
            .map(|(_, rec)| rec)
    }

    /// The cached run at exactly these parameter values with its 1-based line in the
    /// journal (0 for an in-memory store), so a bad record can be named.
    pub fn get_with_line(
        &self,
        scenario: &str,
        names: &[String],
        params: &[f64],
    ) -> Option<(usize, RunRecord)> {
        self.get_keyed(scenario, "", names, params)
    }

    /// [`Self::get_with_line`] under the scenario's inputs ([`crate::Model::scenario_key`]).
    pub fn get_keyed(
        &self,
        scenario: &str,
        scenario_key: &str,
        names: &[String],
        params: &[f64],
    ) -> Option<(usize, RunRecord)> {
        let k = key(scenario, scenario_key, names, params);
        let mut inner = self.lock();
        let hit = inner.runs.get(&k).cloned();
        if hit.is_some() {
            inner.reached.insert(k);
        }
        hit
    }

    /// The journal's runs (of this fingerprint) that nobody asked for since the store was
    /// opened, in journal order with their lines: after a calibration, the runs an
    /// earlier, longer calibration made beyond this one's budget.
    pub fn unreached(&self) -> Vec<(usize, RunRecord)> {
        let inner = self.lock();
        let mut out: Vec<(usize, RunRecord)> = (inner.runs.iter())
            .filter(|(k, _)| !inner.reached.contains(*k))
            .map(|(_, run)| run.clone())
            .collect();
        out.sort_by_key(|(line, rec)| (*line, rec.seq));
        out
    }

    /// Journals a finished run (appended, flushed and synced before returning) and caches it.
    /// Safe to call from several threads.
    pub fn record(
        &self,
        scenario: &str,
        names: &[String],
        params: &[f64],
        result: &std::result::Result<Outputs, ModelError>,
        wall_s: f64,
    ) -> Result<RunRecord> {
        self.record_keyed(scenario, "", names, params, result, wall_s)
    }

    /// [`Self::record`] under the scenario's inputs ([`crate::Model::scenario_key`]).
    pub fn record_keyed(
        &self,
        scenario: &str,
        scenario_key: &str,
        names: &[String],
        params: &[f64],
        result: &std::result::Result<Outputs, ModelError>,
        wall_s: f64,
    ) -> Result<RunRecord> {
        let (status, outputs, spread, extras, error) = match result {
            Ok(o) => (
                RunStatus::Ok,
                Some(o.values.clone()),
                o.spread.clone(),
                o.extras.clone(),
                None,
            ),
            Err(e) => (
                RunStatus::Failed,
                None,
                None,
                BTreeMap::new(),
                Some(e.clone()),
            ),
        };
        let mut inner = self.lock();
        let rec = RunRecord {
            seq: inner.next_seq,
            fingerprint: self.fingerprint.clone(),
            scenario: scenario.to_string(),
            scenario_key: scenario_key.to_string(),
            param_names: names.to_vec(),
            params: params.to_vec(),
            status,
            outputs,
            spread,
            extras,
            error,
            wall_s,
        };
        if let Err(reason) = rec.check() {
            // Refused before it is written: a line no reader could take back.
            return Err(Error::Journal {
                path: self
                    .path
                    .as_deref()
                    .map_or_else(|| "(in memory)".into(), |p| p.display().to_string()),
                reason: format!("run at scenario `{scenario}` not recorded: {reason}"),
            });
        }
        let repair = inner.repair;
        if let Some(file) = inner.file.as_mut() {
            let path = self.path.as_deref().unwrap_or(Path::new("runs.jsonl"));
            let journal = |reason: String| Error::Journal {
                path: path.display().to_string(),
                reason,
            };
            let mut line = Vec::new();
            match repair {
                Some(Repair::CutTo(len)) => {
                    file.set_len(len).map_err(|e| Error::io(path, e))?;
                }
                Some(Repair::Newline) => line.push(b'\n'),
                None => {}
            }
            serde_json::to_writer(&mut line, &rec).map_err(|e| journal(e.to_string()))?;
            line.push(b'\n');
            // One write per line keeps a crash to a torn tail, never an interleaving.
            file.write_all(&line).map_err(|e| Error::io(path, e))?;
            file.flush().map_err(|e| Error::io(path, e))?;
            file.sync_data().map_err(|e| Error::io(path, e))?;
            inner.repair = None;
        }
        let line = if inner.file.is_some() {
            inner.lines += 1;
            inner.lines
        } else {
            0
        };
        inner.next_seq = inner.next_seq.saturating_add(1);
        let k = key(scenario, scenario_key, names, params);
        inner.reached.insert(k.clone());
        inner.runs.insert(k, (line, rec.clone()));
        Ok(rec)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock leaves the map consistent (insert is last).
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }
}

fn parse(line: &[u8]) -> std::result::Result<RunRecord, String> {
    let rec: RunRecord = serde_json::from_slice(line).map_err(|e| e.to_string())?;
    rec.check()?;
    Ok(rec)
}
