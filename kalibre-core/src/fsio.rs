//! Writing result files so that a crash never leaves half of one.

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` whole or not at all: into a temporary file beside it, synced,
/// then renamed over `path`. A process killed mid-write leaves the old file (or none) and
/// a stray `.NAME.tmp-PID`, never a truncated `report.json` that the next command would
/// have to refuse. A path that is a device or FIFO is written into directly.
///
/// ```
/// let dir = std::env::temp_dir().join(format!("kalibre-doc-atomic-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("report.json");
/// kalibre_core::write_atomic(&path, b"{}").unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "{}");
/// ```
pub fn write_atomic(path: &Path, bytes: impl AsRef<[u8]>) -> std::io::Result<()> {
    // A device or FIFO (`--out /dev/null`) is written into, never renamed over: as root
    // that rename would replace /dev/null with a file for every process on the machine.
    // Opened by the name given, links and all: `/dev/stdout` on a pipe resolves to
    // `pipe:[N]`, which is no path.
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        let mut f = std::fs::OpenOptions::new().write(true).open(path)?;
        return f.write_all(bytes.as_ref()).and_then(|()| f.flush());
    }
    // Through a symbolic link, as a plain write would: the link stays, its target changes.
    let resolved;
    let path = if path.is_symlink() {
        resolved = std::fs::canonicalize(path)?;
        resolved.as_path()
    } else {
        path
    };
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::other("not a file path"))?
        .to_string_lossy();
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes.as_ref())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_whole_files_and_writes_through_links() {
        let dir = std::env::temp_dir().join(format!("kalibre-atomic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("report.json");
        std::fs::write(&path, "old and longer").unwrap();
        write_atomic(&path, "new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        #[cfg(unix)]
        {
            let link = dir.join("link.json");
            std::os::unix::fs::symlink(&path, &link).unwrap();
            write_atomic(&link, "through").unwrap();
            assert!(link.is_symlink());
            assert_eq!(std::fs::read_to_string(&path).unwrap(), "through");
        }
        // A FIFO (like a device) is written into and stays one: a file renamed over
        // /dev/null would be what every later reader of it gets.
        #[cfg(unix)]
        {
            let fifo = dir.join("fifo");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            assert!(made.unwrap().success());
            let reader = {
                let fifo = fifo.clone();
                std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
            };
            write_atomic(&fifo, "through the pipe").unwrap();
            // Before waiting on the reader, which a replaced FIFO would leave blocked.
            assert!(!std::fs::metadata(&fifo).unwrap().is_file());
            assert_eq!(reader.join().unwrap(), "through the pipe");
        }
        // A directory in the way: an error, the temporary file gone.
        std::fs::create_dir_all(dir.join("taken")).unwrap();
        assert!(write_atomic(&dir.join("taken"), "x").is_err());
        let strays: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(strays.is_empty(), "{strays:?}");
    }
}
