//! Fresh working directories for model runs.

use std::io;
use std::path::{Path, PathBuf};

/// Allocates run directories under a root: `<label>-<hash>-<n>`, where the label is the
/// scenario's (reduced to `[A-Za-z0-9._-]`), the hash identifies the scenario and the
/// parameters, and `n` counts from 1. A directory is claimed by `create_dir`, which is
/// atomic, so parallel runs (threads or processes) never share one and an existing
/// directory, from this calibration or an earlier one, is never reused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDirs {
    root: PathBuf,
}

/// Longest label kept in a directory name.
const MAX_LABEL: usize = 48;

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

    /// Creates and returns a new, empty directory for a run of `label` with identity `key`.
    pub fn create(&self, label: &str, key: u128) -> io::Result<PathBuf> {
        std::fs::create_dir_all(&self.root)?;
        let stem = format!("{}-{:016x}", Self::sanitize(label), (key >> 64) as u64);
        for n in 1..=1_000_000u32 {
            let dir = self.root.join(format!("{stem}-{n}"));
            match std::fs::create_dir(&dir) {
                Ok(()) => return Ok(dir),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(e),
            }
        }
        Err(io::Error::other(format!(
            "{}: a million run directories named {stem}-* exist",
            self.root.display()
        )))
    }
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
}
