//! The run journal and cache (`runs.jsonl`): one JSON line per finished model run.
//!
//! Every finished run, success or failure, is appended as one line, flushed and synced
//! before the loop goes on, so a crash loses at most the runs in flight. On open the
//! journal is read back; a torn last line (a crash mid-write) and unparsable lines are
//! reported in a [`LoadReport`] and skipped, never fatal. Runs are keyed by model
//! fingerprint, scenario label, parameter names and the exact bits of the physical
//! parameter values, so a restarted calibration finds every run it already did.

mod load;

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use crate::{number, Error, ModelError, Outputs, Result};
use load::Loaded;
pub use load::{BadLine, LoadReport};

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
        if let Some(reason) = crate::model::non_finite_extra(&self.extras) {
            return Err(reason);
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

    /// Opens (or creates, with any missing directories) the journal at `path` for runs
    /// of the model with `fingerprint`.
    ///
    /// A torn last line is cut off the file before the next run is appended (nothing is
    /// written until then), so that later lines start clean; bad lines
    /// and runs of other fingerprints are skipped. See [`Self::load_report`].
    pub fn open(path: impl AsRef<Path>, fingerprint: impl Into<String>) -> Result<Self> {
        Self::open_impl(path.as_ref(), fingerprint.into(), &[], false)
    }

    /// [`Self::open`], or [`Self::open_replaying_failures`] when `replay_failures` (as a
    /// calibration's `--replay-failed` chooses).
    pub fn open_with(
        path: impl AsRef<Path>,
        fingerprint: impl Into<String>,
        replay_failures: bool,
    ) -> Result<Self> {
        Self::open_impl(path.as_ref(), fingerprint.into(), &[], replay_failures)
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
        Self::open_impl(path.as_ref(), fingerprint.into(), &[], true)
    }

    /// [`Self::open_with`], reading the lines of the fingerprints `aliases` as this
    /// model's too: the fingerprints earlier versions gave the same model
    /// ([`crate::Model::legacy_fingerprints`]), so that their journals are not lost when
    /// what a fingerprint covers changes. Their runs are reused like any other (and are
    /// not counted in [`LoadReport::other_fingerprint`]); new runs are journaled under
    /// `fingerprint`.
    ///
    /// ```
    /// use kalibre_core::{Outputs, RunStore};
    /// let path = std::env::temp_dir().join(format!("alias-doc-{}.jsonl", std::process::id()));
    /// let names = vec!["k".to_string()];
    /// {
    ///     let old = RunStore::open(&path, "model-v1").unwrap();
    ///     old.record("t0", &names, &[2.5], &Ok(Outputs::from(vec![1.0])), 0.1).unwrap();
    /// }
    /// let aliases = ["model-v1".to_string()];
    /// let store = RunStore::open_with_aliases(&path, "model-v2", &aliases, false).unwrap();
    /// assert_eq!(store.get("t0", &names, &[2.5]).unwrap().outputs, Some(vec![1.0]));
    /// assert_eq!(store.load_report().other_fingerprint, 0);
    /// # drop(store);
    /// # std::fs::remove_file(&path).unwrap();
    /// ```
    pub fn open_with_aliases(
        path: impl AsRef<Path>,
        fingerprint: impl Into<String>,
        aliases: &[String],
        replay_failures: bool,
    ) -> Result<Self> {
        Self::open_impl(path.as_ref(), fingerprint.into(), aliases, replay_failures)
    }

    fn open_impl(
        path: &Path,
        fingerprint: String,
        aliases: &[String],
        replay_failed: bool,
    ) -> Result<Self> {
        let path = path.to_path_buf();
        // `out/runs.jsonl` for a fresh `out/`: the journal goes where it was asked to,
        // not a bare "not found".
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
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

        let Loaded {
            runs,
            max_seq,
            lines,
            repair,
            load,
        } = load::read(&bytes, &path, &fingerprint, aliases, replay_failed)?;
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
    /// earlier, longer calibration made beyond this one's budget. Successful runs only.
    pub fn unreached(&self) -> Vec<(usize, RunRecord)> {
        let inner = self.lock();
        // Failures are in the cache only when replayed; unused, they are no result.
        let mut out: Vec<(usize, RunRecord)> = (inner.runs.iter())
            .filter(|(k, (_, rec))| !inner.reached.contains(*k) && rec.status == RunStatus::Ok)
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
            let body = serde_json::to_vec(&rec).map_err(|e| journal(e.to_string()))?;
            // The promise is that a restart finds every run: a line the next opening
            // could not read back (a float JSON writes as `null` where a number must be)
            // is refused here, before the file is touched, never written.
            if let Err(e) = serde_json::from_slice::<RunRecord>(&body) {
                return Err(journal(format!(
                    "run at scenario `{scenario}` not recorded: its line would not read \
                     back ({e})"
                )));
            }
            let mut line = Vec::with_capacity(body.len() + 2);
            match repair {
                Some(Repair::CutTo(len)) => {
                    file.set_len(len).map_err(|e| Error::io(path, e))?;
                }
                Some(Repair::Newline) => line.push(b'\n'),
                None => {}
            }
            line.extend_from_slice(&body);
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
