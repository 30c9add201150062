//! Fresh working directories for model runs, and the ones interrupted runs left behind.

use std::fs::{File, OpenOptions, TryLockError};
use std::io;
use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Allocates run directories under a root: `<label>-<hash>-<n>`, where the label is the
/// scenario's (reduced to `[A-Za-z0-9._-]`), the hash identifies the scenario and the
/// parameters, and `n` counts from 1. A directory is claimed by `create_dir`, which is
/// atomic, so parallel runs (threads or processes) never share one and an existing
/// directory, from this calibration or an earlier one, is never reused.
///
/// While a run uses its directory, a locked marker file beside it (`.<name>.running`)
/// says so. A process killed mid-run cannot remove its marker, but the operating system
/// releases the lock, so [`RunDirs::remove_interrupted`] can tell the directories of
/// interrupted runs from those of live ones (of this process or another) and from the
/// ones kept on purpose (failed runs, `keep_runs = "all"`), which have no marker.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDirs {
    root: PathBuf,
}

/// Longest label kept in a directory name.
const MAX_LABEL: usize = 48;

/// The marker's name for a run directory's name.
fn marker_name(dir_name: &str) -> String {
    format!(".{dir_name}.running")
}

/// A claimed run directory (dereferences to its path). Dropping it ends the run's claim:
/// its marker goes, the directory stays (the caller removes it or keeps it).
#[derive(Debug)]
pub struct RunDir {
    path: PathBuf,
    /// The marker and its locked handle; `None` where the file system has no locks.
    marker: Option<(PathBuf, File)>,
}

impl RunDir {
    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Deref for RunDir {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for RunDir {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for RunDir {
    fn drop(&mut self) {
        if let Some((marker, lock)) = self.marker.take() {
            if super::groups::stopping() {
                // Ended by kalibre's stop, which waits for its runs to go: left marked, as
                // an interrupted run's, for the next command's sweep (the lock goes with
                // the process), not kept as a failed run's.
                std::mem::forget(lock);
                return;
            }
            // Removed while still locked, so no sweep can take it for an interrupted run's.
            let _ = std::fs::remove_file(marker);
        }
    }
}

impl RunDirs {
    /// Directories under `root` (created when the first run needs it).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        RunDirs { root: root.into() }
    }

    /// The root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The label as it appears in a directory name.
    pub fn sanitize(label: &str) -> String {
        let s: String = label
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                    c
                } else {
                    '_'
                }
            })
            .take(MAX_LABEL)
            .collect();
        // No hidden or `..` names.
        let s = s.trim_start_matches('.');
        if s.is_empty() {
            "run".into()
        } else {
            s.into()
        }
    }

    /// Creates and returns a new, empty directory for a run of `label` with identity `key`,
    /// marked as in use until the returned [`RunDir`] is dropped.
    pub fn create(&self, label: &str, key: u128) -> io::Result<RunDir> {
        std::fs::create_dir_all(&self.root)?;
        let stem = format!("{}-{:016x}", Self::sanitize(label), (key >> 64) as u64);
        for n in 1..=1_000_000u32 {
            let name = format!("{stem}-{n}");
            // The marker is claimed and locked before the directory exists, so a sweep
            // never finds a live run's directory without its locked marker.
            let marker = self.root.join(marker_name(&name));
            let lock = match OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&marker)
            {
                Ok(file) => match file.try_lock() {
                    Ok(()) => Some((marker.clone(), file)),
                    // A sweep holds it: that name is being cleared; take the next.
                    Err(TryLockError::WouldBlock) => continue,
                    Err(TryLockError::Error(_)) => {
                        let _ = std::fs::remove_file(&marker);
                        None
                    }
                },
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                // A root that takes no marker still takes runs; they are just not swept.
                Err(_) => None,
            };
            let dir = self.root.join(&name);
            match std::fs::create_dir(&dir) {
                Ok(()) => {
                    return Ok(RunDir {
                        path: dir,
                        marker: lock,
                    })
                }
                Err(e) => {
                    if let Some((m, _)) = &lock {
                        let _ = std::fs::remove_file(m);
                    }
                    if e.kind() != io::ErrorKind::AlreadyExists {
                        return Err(e);
                    }
                }
            }
        }
        Err(io::Error::other(format!(
            "{}: a million run directories named {stem}-* exist",
            self.root.display()
        )))
    }

    /// Makes the root when missing, and checks that a run directory can be made in it
    /// (by making and removing one).
    pub fn check_writable(&self) -> io::Result<()> {
        std::fs::create_dir_all(&self.root)?;
        let probe = self.root.join(format!(".probe-{}", std::process::id()));
        std::fs::create_dir(&probe).or_else(|e| match e.kind() {
            io::ErrorKind::AlreadyExists => Ok(()),
            _ => Err(e),
        })?;
        std::fs::remove_dir(&probe)
    }

    /// Removes the directories that runs killed mid-run left under the root (their markers
    /// unlocked), and returns them. Live runs, of this process or another, and directories
    /// kept on purpose are left alone. A missing root has none.
    pub fn remove_interrupted(&self) -> io::Result<Vec<PathBuf>> {
        let entries = match std::fs::read_dir(&self.root) {
            Ok(entries) => entries,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e),
        };
        let mut removed = Vec::new();
        for entry in entries {
            let entry = entry?;
            let file_name = entry.file_name();
            let Some(name) = file_name
                .to_str()
                .and_then(|n| n.strip_prefix('.'))
                .and_then(|n| n.strip_suffix(".running"))
            else {
                continue;
            };
            let marker = entry.path();
            let Ok(file) = OpenOptions::new().write(true).open(&marker) else {
                continue;
            };
            // Locked: a live run's. Unlocked: its run was killed.
            if file.try_lock().is_err() {
                continue;
            }
            let dir = self.root.join(name);
            let is_dir = std::fs::symlink_metadata(&dir).is_ok_and(|m| m.is_dir());
            // A solver the killed run started may work on in there; removed from under
            // it, it would hold its cores to its end for nothing.
            if is_dir && !end_processes_in(&dir, ORPHAN_GRACE) {
                continue;
            }
            if is_dir {
                std::fs::remove_dir_all(&dir)?;
                removed.push(dir);
            }
            std::fs::remove_file(&marker)?;
        }
        removed.sort();
        Ok(removed)
    }
}

/// How long a process left working in an interrupted run's directory may take to go
/// after SIGTERM before it gets SIGKILL.
const ORPHAN_GRACE: Duration = Duration::from_secs(5);

/// Ends the processes still working in `dir` (their working directory inside it): what
/// a run started that outlived its killed kalibre (`kill -9`, the out-of-memory killer),
/// since the kernel's parent-death signal reaches only the run's first process. SIGTERM,
/// then SIGKILL after `grace`. Whether none is left (one of another user's stays).
#[cfg(target_os = "linux")]
fn end_processes_in(dir: &Path, grace: Duration) -> bool {
    let Ok(dir) = std::fs::canonicalize(dir) else {
        return true;
    };
    let own = std::process::id();
    // A zombie has no working directory to read: it counts as gone.
    let inside = || -> Vec<libc::pid_t> {
        let Ok(procs) = std::fs::read_dir("/proc") else {
            return Vec::new();
        };
        (procs.flatten())
            .filter_map(|e| {
                let pid: u32 = e.file_name().to_str()?.parse().ok()?;
                let cwd = std::fs::read_link(e.path().join("cwd")).ok()?;
                (pid != own && cwd.starts_with(&dir)).then_some(pid as libc::pid_t)
            })
            .collect()
    };
    let signal_all = |signal: libc::c_int| {
        for pid in inside() {
            // SAFETY: kill has no memory effects; a process already gone gives ESRCH.
            unsafe {
                libc::kill(pid, signal);
            }
        }
    };
    let gone_within = |wait: Duration| {
        let until = Instant::now() + wait;
        loop {
            if inside().is_empty() {
                return true;
            }
            if Instant::now() >= until {
                return false;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    if inside().is_empty() {
        return true;
    }
    signal_all(libc::SIGTERM);
    if gone_within(grace) {
        return true;
    }
    signal_all(libc::SIGKILL);
    gone_within(Duration::from_secs(5))
}

#[cfg(not(target_os = "linux"))]
fn end_processes_in(_dir: &Path, _grace: Duration) -> bool {
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sanitizes_labels() {
        assert_eq!(RunDirs::sanitize("x; rm -rf /"), "x__rm_-rf__");
        assert_eq!(RunDirs::sanitize("$(touch pwned)"), "__touch_pwned_");
        assert_eq!(RunDirs::sanitize("../.."), "_..");
        assert_eq!(RunDirs::sanitize(".."), "run");
        assert_eq!(RunDirs::sanitize("2024-07-01T12:00"), "2024-07-01T12_00");
    }

    fn root(name: &str) -> PathBuf {
        let root =
            std::env::temp_dir().join(format!("kalibre-rundirs-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        root
    }

    #[test]
    fn a_live_run_is_marked_and_an_ended_one_is_not() {
        let dirs = RunDirs::new(root("live"));
        let run = dirs.create("t0", 7).unwrap();
        let marker = dirs
            .root()
            .join(marker_name(&run.file_name().unwrap().to_string_lossy()));
        assert!(marker.is_file());
        // Live: neither it nor its directory is swept.
        assert!(dirs.remove_interrupted().unwrap().is_empty());
        assert!(run.is_dir());
        let path = run.to_path_buf();
        drop(run);
        // Ended (kept, as a failed run's is): no marker, never swept.
        assert!(!marker.exists());
        assert!(dirs.remove_interrupted().unwrap().is_empty());
        assert!(path.is_dir());
        std::fs::remove_dir_all(dirs.root()).unwrap();
    }

    /// A solver a killed run started, still at work in its directory, is ended before
    /// the directory is removed, not left to run on in a deleted directory.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_process_left_in_a_killed_runs_directory_is_ended_first() {
        use std::os::unix::process::{CommandExt, ExitStatusExt};
        let dirs = RunDirs::new(root("orphan"));
        let mut run = dirs.create("t0", 7).unwrap();
        let mut solver = std::process::Command::new("sleep")
            .arg("60")
            .current_dir(run.path())
            .process_group(0)
            .spawn()
            .unwrap();
        let path = run.to_path_buf();
        // The marker's lock went with the killed kalibre; the solver did not.
        drop(run.marker.take());
        // A test beside this one that forks holds a copy of the marker until its child
        // execs, and the lock with it: the sweep then sees a live run and waits for the
        // next one.
        let t0 = Instant::now();
        let mut removed = dirs.remove_interrupted().unwrap();
        while removed.is_empty() && t0.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
            removed = dirs.remove_interrupted().unwrap();
        }
        assert_eq!(removed, vec![path.clone()]);
        let status = solver.wait().unwrap();
        assert_eq!(status.signal(), Some(libc::SIGTERM), "{status:?}");
        assert!(!path.exists());
        std::fs::remove_dir_all(dirs.root()).unwrap();
    }

    #[test]
    fn a_killed_runs_directory_is_removed_and_its_name_not_reused_meanwhile() {
        let dirs = RunDirs::new(root("killed"));
        let run = dirs.create("t0", 7).unwrap();
        std::fs::write(run.join("out.txt"), "partial").unwrap();
        let path = run.to_path_buf();
        // What a killed process leaves: the directory and an unlocked marker.
        let (marker, lock) = {
            let mut run = run;
            run.marker.take().unwrap()
        };
        drop(lock);
        assert!(marker.is_file());
        let next = dirs.create("t0", 7).unwrap();
        assert_ne!(next.path(), path, "a claimed name is never reused");
        assert_eq!(dirs.remove_interrupted().unwrap(), vec![path.clone()]);
        assert!(!path.exists() && !marker.exists());
        assert!(next.is_dir(), "the live run stays");
        drop(next);
        std::fs::remove_dir_all(dirs.root()).unwrap();
    }
}
