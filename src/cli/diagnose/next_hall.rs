//! `kalibre diagnose --write-hall`: the next hall, with the top significant suggestion
//! added where the diagnosis's fit puts it, and the path checked before any solve.

use kalibre_core::calibrate::Report;
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::next_hall::with_effect_refitted;
use kalibre_dc::HallModel;

use super::super::{CliError, CliResult};

/// `--write-hall`: the hall with the top significant suggestion added, warm-started at
/// its fit (the calibrated values refitted beside it); returns what to tell the user.
pub(super) fn write_next_hall(
    hall: &Hall,
    report: &Report,
    model: &HallModel,
    d: &kalibre_dc::diagnosis::HallDiagnosis,
    path: &std::path::Path,
) -> CliResult<Option<String>> {
    // A significant hypothesis is fitted in its range; one outside it has no entry (its
    // clamped entry would do nothing), so it is never written.
    let top = (d.diagnosis.hypotheses.iter().enumerate())
        .filter(|(_, h)| h.significant)
        .find_map(|(i, h)| d.entry(i).map(|e| (h, e)));
    let Some((h, entry)) = top else {
        // A file there from before is not this diagnosis's hall: said, so that a script
        // reading it next knows.
        let older = match path.exists() {
            true => " (the file there is older, left as it was)",
            false => "",
        };
        return Ok(Some(format!(
            "nothing significant: {} not written{older}",
            path.display()
        )));
    };
    let next = with_effect_refitted(hall, report, model, &EffectRegistry::builtin(), h, entry)?;
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| CliError::Input(format!("--write-hall: {}: {e}", dir.display())))?;
    }
    next.save(path)?;
    Ok(Some(format!(
        "wrote {}: the hall with {} added, warm-started where the predicted MAE ({:.3} C) \
         puts it: the effect at its fitted value, the calibrated parameters refitted beside it",
        path.display(),
        h.name,
        h.predicted_mae
    )))
}

/// A `--write-hall` path that could not be written, refused before the diagnosis's solves
/// (minutes of them with OpenFOAM) rather than after.
pub(super) fn check_writable_file(path: &std::path::Path) -> CliResult {
    let bad = |why: String| {
        Err(CliError::Input(format!(
            "--write-hall {}: {why}",
            path.display()
        )))
    };
    if path.is_dir() {
        return bad("is a directory; expected a file path".into());
    }
    // Missing directories are made when the hall is written; the nearest one that
    // exists must be a directory.
    let existing = path
        .ancestors()
        .skip(1)
        .find(|p| p.as_os_str().is_empty() || p.exists())
        .filter(|p| !p.as_os_str().is_empty());
    let dir = match existing {
        Some(p) if !p.is_dir() => return bad(format!("{} is not a directory", p.display())),
        Some(p) => p.to_path_buf(),
        None => std::path::PathBuf::from("."),
    };
    // The hall is written as a temporary file beside the target (through a link, beside
    // the link's target) and renamed over it, so that directory is the one to try.
    let dir = match std::fs::metadata(path) {
        Ok(meta) if !meta.is_file() => {
            return bad("is not a regular file (a FIFO, socket or device)".into())
        }
        // Stdout redirected to a file: the hall renamed over it would drop the diagnosis
        // printed there.
        Ok(_) if super::super::is_stdout(path) => {
            return bad("is the file stdout writes to, where the diagnosis is printed".into())
        }
        Ok(_) => match std::fs::canonicalize(path) {
            Ok(real) => real.parent().map(|p| p.to_path_buf()).unwrap_or(dir),
            Err(e) => return bad(format!("cannot resolve it: {e}")),
        },
        Err(_) => dir,
    };
    // Permissions, a read-only or virtual file system (/proc): only writing tells, so
    // write.
    let file = dir.join(format!(".kalibre-write-check-{}", std::process::id()));
    let made = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&file);
    let _ = std::fs::remove_file(&file);
    match made {
        Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => {
            bad(format!("cannot write in {}: {e}", dir.display()))
        }
        _ => Ok(()),
    }
}
