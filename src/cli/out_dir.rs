//! The `--out` directory of `calibrate`, `synth` and `demo`: checked before any work, and
//! held by one command at a time.
//!
//! A calibration's expensive runs go to `runs.jsonl` in `--out`. Two calibrations in one
//! directory at once would each run every point the other runs (the journal is read once,
//! when a calibration starts), so the second is refused while the first holds the lock.
//! The lock is the operating system's (`flock`): it ends with the process, even a killed
//! one, so a crash never leaves the directory locked.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

use super::{io_err, CliError, CliResult};

/// The lock file's name in `--out`.
pub const LOCK_FILE: &str = ".kalibre.lock";

/// Holds `--out` for one command until dropped (or the process ends).
#[derive(Debug)]
pub struct OutLock {
    _file: File,
}

/// Refuses an `--out` that exists and is not a directory (a file, a dangling link),
/// naming it, before any work is done.
pub fn check_is_dir(out: &Path) -> CliResult {
    let Ok(link) = std::fs::symlink_metadata(out) else {
        // Missing: made later, under its nearest existing ancestor, which must be a
        // directory.
        let ancestor = out.ancestors().skip(1).find(|p| p.exists());
        if let Some(file) = ancestor.filter(|p| !p.as_os_str().is_empty() && !p.is_dir()) {
            return Err(CliError::Input(format!(
                "--out {}: {} is a file, not a directory; give a directory (it is made if \
                 missing)",
                out.display(),
                file.display()
            )));
        }
        return Ok(());
    };
    let why = match std::fs::metadata(out) {
        Ok(m) if m.is_dir() => return Ok(()),
        Ok(_) => "is a file, not a directory",
        Err(_) if link.file_type().is_symlink() => "is a symbolic link to nothing",
        Err(_) => "cannot be read",
    };
    Err(CliError::Input(format!(
        "--out {}: {why}; give a directory (it is made if missing)",
        out.display()
    )))
}

/// Refuses any of `names` in `--out` that exists and is not a regular file (a directory,
/// a FIFO that would block the journal's read, a device): found now, not after the
/// calibration's runs.
pub fn check_files(out: &Path, names: &[&str]) -> CliResult {
    for name in names {
        let path = out.join(name);
        let Ok(meta) = std::fs::metadata(&path) else {
            continue;
        };
        let kind = meta.file_type();
        if kind.is_file() {
            continue;
        }
        let what = if kind.is_dir() {
            "a directory"
        } else {
            "not a regular file (a FIFO, socket or device)"
        };
        return Err(CliError::Input(format!(
            "--out {}: {name} is {what}; kalibre writes a file there: move it or give another \
             --out",
            out.display()
        )));
    }
    Ok(())
}

/// Makes `out` (and its parents) and takes its lock, refusing when another command
/// holds it; `flag` is the option that named `out` (`--out`, or `--calibration` for a
/// diagnosis, which waits for the calibration rather than going elsewhere).
pub fn lock(out: &Path, flag: &str, command: &str) -> CliResult<OutLock> {
    check_is_dir(out)?;
    // Opening a FIFO for writing would wait for a reader.
    check_files(out, &[LOCK_FILE])?;
    std::fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
    let path = out.join(LOCK_FILE);
    let file = OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| io_err(&path, e))?;
    match file.try_lock() {
        Ok(()) => Ok(OutLock { _file: file }),
        Err(TryLockError::WouldBlock) => Err(CliError::Input(format!(
            "{flag} {}: another kalibre command is working in this directory (it holds \
             {LOCK_FILE}); wait for it to finish{}",
            out.display(),
            if flag == "--out" {
                format!(", or give {command} another --out")
            } else {
                String::new()
            }
        ))),
        Err(TryLockError::Error(e)) => Err(io_err(&path, e)),
    }
}

/// Refuses an output file path (`flag PATH`) that cannot take a file: a directory, a
/// path with no file name (`.`), or one whose directory cannot be made. A missing
/// directory is made, as `--out` directories are. Found now, not when the file is
/// written after the runs.
pub fn check_out_file(flag: &str, path: &Path) -> CliResult {
    let refuse = |why: &str| {
        Err(CliError::Input(format!(
            "{flag} {}: {why}; expected a file path",
            path.display()
        )))
    };
    if path.is_dir() {
        return refuse("is a directory");
    }
    if path.file_name().is_none() {
        return refuse("names no file");
    }
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => {
            if let Err(e) = std::fs::create_dir_all(dir) {
                return refuse(&format!(
                    "its directory {} cannot be made: {e}",
                    dir.display()
                ));
            }
        }
        _ => {}
    }
    // Written beside itself and renamed (`write_atomic`), after the runs: a directory
    // that takes no file must be found now, not once every slow run is done.
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return Ok(()); // a device or FIFO is written into, not renamed over
    }
    let resolved = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    let name = resolved.file_name().unwrap_or_default().to_string_lossy();
    let probe = resolved.with_file_name(format!(".{name}.probe-{}", std::process::id()));
    match std::fs::File::create(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => refuse(&format!("no file can be written in its directory ({e})")),
    }
}

/// Says on stderr which run directories of killed runs `removed` (the result of a
/// model's `remove_interrupted_runs`) cleared, or why they could not be.
pub fn note_interrupted_runs(removed: std::io::Result<Vec<PathBuf>>) {
    match removed {
        Ok(dirs) if dirs.is_empty() => {}
        Ok(dirs) => {
            let root = dirs[0].parent().unwrap_or(Path::new("."));
            eprintln!(
                "kalibre: note: removed {} run director{} that runs killed mid-run left under \
                 {} (first: {})",
                dirs.len(),
                if dirs.len() == 1 { "y" } else { "ies" },
                root.display(),
                dirs[0].file_name().unwrap_or_default().to_string_lossy()
            );
        }
        Err(e) => eprintln!(
            "kalibre: warning: the run directories of runs killed earlier were not removed: {e}"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("kalibre-out-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_second_lock_is_refused_until_the_first_is_dropped() {
        let d = dir("lock");
        let first = lock(&d, "--out", "calibrate").unwrap();
        let err = lock(&d, "--out", "calibrate").unwrap_err().to_string();
        assert!(err.contains("another kalibre command"), "{err}");
        drop(first);
        lock(&d, "--out", "calibrate").unwrap();
    }

    #[test]
    fn an_out_that_is_a_file_or_holds_a_directory_is_named() {
        let d = dir("kinds");
        std::fs::create_dir_all(d.join("report.json")).unwrap();
        let err = check_files(&d, &["runs.jsonl", "report.json"]).unwrap_err();
        assert!(
            err.to_string().contains("report.json is a directory"),
            "{err}"
        );
        let file = d.join("plain");
        std::fs::write(&file, "x").unwrap();
        let err = check_is_dir(&file).unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert!(
            err.to_string().contains("is a file, not a directory"),
            "{err}"
        );
        #[cfg(unix)]
        {
            let dangling = d.join("dangling");
            std::os::unix::fs::symlink(d.join("nowhere"), &dangling).unwrap();
            let err = check_is_dir(&dangling).unwrap_err().to_string();
            assert!(err.contains("symbolic link to nothing"), "{err}");
        }
    }
}
