//! What `calibrate` and `simulate` share for a model of your own (`--model command
//! --config model.toml` with no hall): reading its configuration, and the refusal of the
//! OpenFOAM flags.

use std::path::Path;

use kalibre_core::external::CommandModelConfig;

use super::openfoam_args::OpenFoamArgs;
use super::{CliError, CliResult};

/// `model.toml` read and checked, its program found and its `[[scenarios]]` not empty;
/// `no_scenarios` completes the refusal's "no [[scenarios]]" with what they are for.
pub(crate) fn load_config(path: &Path, no_scenarios: &str) -> CliResult<CommandModelConfig> {
    let cfg = CommandModelConfig::load(path).map_err(|e| CliError::Input(e.to_string()))?;
    (cfg.command.check_program())
        .and_then(|()| cfg.command.check_runs_root())
        .map_err(|e| CliError::Input(format!("{}: {e}", path.display())))?;
    if cfg.scenarios.is_empty() {
        return Err(CliError::Input(format!(
            "{}: no [[scenarios]]{no_scenarios}",
            path.display()
        )));
    }
    Ok(cfg)
}

/// Warns of each parameter the program cannot see: one that no template, argument or
/// `env` value writes reaches it only through `kalibre-run.json`, and a calibration of a
/// parameter the program ignores ends wherever the search left it. A fixed parameter
/// that is no candidate effect moves nothing anyway, so it is not named.
pub(crate) fn warn_unwritten_params(path: &Path, cfg: &CommandModelConfig) {
    let candidate = |name: &str| {
        cfg.candidates
            .iter()
            .any(|c| c.params.iter().any(|p| p.name == name))
    };
    for name in cfg.command.unwritten_params() {
        let Some(i) = cfg.space.index_of(name) else {
            continue;
        };
        if cfg.space.params()[i].is_fixed() && !candidate(name) {
            continue;
        }
        eprintln!(
            "kalibre: warning: {}: params[{i}] `{name}` is written by no template, argument \
             or env value (no {{{{{name}}}}} anywhere), so the program sees it only in each \
             run's kalibre-run.json; if it does not read that file, `{name}` changes nothing",
            path.display()
        );
    }
}

/// The OpenFOAM flags refused: OpenFOAM solves a hall, which a model of your own is not.
pub(crate) fn refuse_openfoam_flags(openfoam: &OpenFoamArgs) -> CliResult {
    openfoam.refuse_unless_because(
        false,
        "OpenFOAM solves a hall, and a model of your own runs its own program",
    )
}
