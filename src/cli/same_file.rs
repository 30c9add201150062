//! Output paths that would land on an input or on another output: refused before any
//! work, so that a result never replaces the measurements, the hall, a report or a run
//! journal (hours of solves), and one output never silently replaces another.

use std::path::{Path, PathBuf};

use super::{CliError, CliResult};

/// Where `path` points: the file itself through any links when it exists, else its
/// resolved directory and name (a path not written yet can still meet another).
fn resolve(path: &Path) -> Option<PathBuf> {
    if let Ok(real) = std::fs::canonicalize(path) {
        return Some(real);
    }
    let name = path.file_name()?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    std::fs::canonicalize(parent).ok().map(|d| d.join(name))
}

/// Refuses an output (flag, path) that is one of `inputs` (what it is, path) or the
/// same file as an earlier output.
pub(crate) fn refuse_same_files(
    outputs: &[(&str, Option<&Path>)],
    inputs: &[(&str, Option<&Path>)],
) -> CliResult {
    let inputs: Vec<(&str, PathBuf)> = inputs
        .iter()
        .filter_map(|(what, p)| Some((*what, std::fs::canonicalize((*p)?).ok()?)))
        .collect();
    let mut seen: Vec<(&str, PathBuf)> = Vec::new();
    for (flag, path) in outputs {
        let Some(path) = path else { continue };
        let Some(real) = resolve(path) else { continue };
        if let Some((what, _)) = inputs.iter().find(|(_, p)| *p == real) {
            return Err(CliError::Input(format!(
                "{flag} {} is {what}: writing there would replace it; expected another path",
                path.display()
            )));
        }
        if let Some((other, _)) = seen.iter().find(|(_, p)| *p == real) {
            return Err(CliError::Input(format!(
                "{flag} {} is also the {other} file: one output would replace the other; \
                 expected another path",
                path.display()
            )));
        }
        seen.push((flag, real));
    }
    Ok(())
}

/// Refuses `out`'s files `out_files` (named `--out's NAME`) where one of them is one of
/// `inputs`: an input kept in `--out` under an output's name would be replaced by it.
pub(crate) fn refuse_inputs_in_out(
    out: &Path,
    out_files: &[&str],
    inputs: &[(&str, Option<&Path>)],
) -> CliResult {
    let paths: Vec<(String, PathBuf)> = out_files
        .iter()
        .map(|name| (format!("--out's {name}"), out.join(name)))
        .collect();
    let outputs: Vec<(&str, Option<&Path>)> = paths
        .iter()
        .map(|(what, path)| (what.as_str(), Some(path.as_path())))
        .collect();
    refuse_same_files(&outputs, inputs)
}
