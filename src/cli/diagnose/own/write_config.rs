//! `--write-config FILE`: the next `model.toml`, with the effect the diagnosis names added
//! and every calibrated parameter starting where the model ran at its fit, so that the
//! next calibration's first point is a run the journal already holds.

use std::path::{Path, PathBuf};

use kalibre_core::diagnose::CandidateEffect;
use kalibre_core::external::CommandModelConfig;
use kalibre_core::Model;

use super::super::super::{own_model, same_file, CliError, CliResult};

/// The refusals that need no run: FILE beside `config` (its paths are relative to the
/// directory of model.toml), not a directory, and none of the inputs.
pub(super) fn check_target(path: &Path, config: &Path, inputs: &[(&str, &Path)]) -> CliResult {
    // model.toml itself must be one it can edit, before any run.
    let mut doc = parse(config)?;
    params_of(&mut doc, config)?;
    let bad = |why: String| {
        Err(CliError::Input(format!(
            "--write-config {}: {why}",
            path.display()
        )))
    };
    if path.is_dir() {
        return bad("is a directory; expected a file path".into());
    }
    // An existing file is replaced only if it is a model.toml (an earlier --write-config,
    // say): never the model's program, a template or a data file.
    if path.exists() && CommandModelConfig::load(path).is_err() {
        return bad(
            "exists and is not a model.toml, so writing would replace it (the model's \
             program or a template, perhaps); expected a new file, or a model.toml"
                .into(),
        );
    }
    let dir_of = |p: &Path| -> Option<PathBuf> {
        let parent = p.parent().filter(|d| !d.as_os_str().is_empty());
        std::fs::canonicalize(parent.unwrap_or(Path::new("."))).ok()
    };
    if dir_of(path).is_none() || dir_of(path) != dir_of(config) {
        return bad(format!(
            "expected a file in the directory of {} (its program, templates and runs_root \
             are relative to it)",
            config.display()
        ));
    }
    let mut named: Vec<(&str, Option<&Path>)> = vec![("the --config file", Some(config))];
    named.extend(inputs.iter().map(|(what, p)| (*what, Some(*p))));
    same_file::refuse_same_files(&[("--write-config", Some(path))], &named)
}

/// Writes `path`: `config`'s text with `effect` added (its `absent` and `effect` keys
/// deleted, `initial` its value in `point`) and every calibrated parameter's `initial` at
/// its value in `point` (every parameter by name), comments and layout kept. Checked by
/// loading it again: the same parameters in the same order, so the same fingerprint and
/// the same `--out`. Returns what was done, in words.
pub(super) fn write(
    path: &Path,
    config: &Path,
    cfg: &CommandModelConfig,
    effect: &CandidateEffect,
    point: &[(String, f64)],
) -> CliResult<String> {
    let mut doc = parse(config)?;
    let params = params_of(&mut doc, config)?;
    let value_of = |name: &str| point.iter().find(|(n, _)| n == name).map(|(_, v)| *v);
    let added: Vec<&str> = effect.params.iter().map(|p| p.name.as_str()).collect();
    for t in params.iter_mut() {
        let Some(name) = t.get("name").and_then(|n| n.as_str()).map(str::to_string) else {
            continue;
        };
        let Some(value) = value_of(&name) else {
            continue;
        };
        if added.contains(&name.as_str()) {
            t.remove("absent");
            t.remove("effect");
        } else if t.contains_key("absent") {
            // Another candidate: still held absent.
            continue;
        }
        // The new value in the old one's place, with its comment.
        match t.get_mut("initial").and_then(|i| i.as_value_mut()) {
            Some(v) => {
                let decor = v.decor().clone();
                *v = toml_edit::Value::from(value);
                *v.decor_mut() = decor;
            }
            None => t["initial"] = toml_edit::value(value),
        }
    }
    let written = doc.to_string();
    let tmp = path.with_extension("toml.partial");
    kalibre_core::write_atomic(&tmp, &written)
        .map_err(|e| CliError::Run(format!("--write-config {}: {e}", path.display())))?;
    // Loaded again as calibrate will: refused (and not left behind) if it would not resume
    // the same calibration.
    let check = own_model::load_config(&tmp, "").map(|next| {
        (next.command.fingerprint() == cfg.command.fingerprint())
            .then_some(next)
            .ok_or(())
    });
    let fail = |why: String| {
        let _ = std::fs::remove_file(&tmp);
        Err(CliError::Run(format!(
            "--write-config {}: {why}; nothing written",
            path.display()
        )))
    };
    match check {
        Err(e) => return fail(format!("the edited model.toml does not load ({e})")),
        Ok(Err(())) => {
            return fail("the edited model.toml is another model (its fingerprint changed)".into())
        }
        Ok(Ok(next)) if next.candidates.iter().any(|c| c.name == effect.name) => {
            return fail(format!("`{}` is still a candidate in it", effect.name))
        }
        Ok(Ok(_)) => {}
    }
    if let Err(e) = std::fs::rename(&tmp, path) {
        let _ = std::fs::remove_file(&tmp);
        return Err(CliError::Run(format!(
            "--write-config {}: {e}",
            path.display()
        )));
    }
    let values: Vec<String> = (effect.params.iter())
        .filter_map(|p| value_of(&p.name).map(|v| format!("{} = {v}", p.name)))
        .collect();
    Ok(format!(
        "wrote {}: {} added ({}), every calibrated parameter's `initial` where the model ran \
         at the fit; calibrate with --config {} and the same --out: its first point is that \
         run, read from the journal",
        path.display(),
        effect.name,
        values.join(", "),
        path.display()
    ))
}

/// model.toml as an editable document.
fn parse(config: &Path) -> CliResult<toml_edit::DocumentMut> {
    let file = config.display();
    let text =
        std::fs::read_to_string(config).map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    text.parse()
        .map_err(|e| CliError::Input(format!("{file}: not valid TOML: {e}")))
}

/// Its `[[params]]` tables, or why --write-config cannot edit them.
fn params_of<'d>(
    doc: &'d mut toml_edit::DocumentMut,
    config: &Path,
) -> CliResult<&'d mut toml_edit::ArrayOfTables> {
    doc.get_mut("params")
        .and_then(|p| p.as_array_of_tables_mut())
        .ok_or_else(|| {
            CliError::Input(format!(
                "{}: params: --write-config edits [[params]] tables, and these are written \
                 otherwise (inline); write them as [[params]], or drop --write-config and add \
                 the effect by hand (delete its `absent`, give `initial`)",
                config.display()
            ))
        })
}
