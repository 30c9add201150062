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
    cfg.command
        .check_program()
        .map_err(|e| CliError::Input(format!("{}: {e}", path.display())))?;
    if cfg.scenarios.is_empty() {
        return Err(CliError::Input(format!(
            "{}: no [[scenarios]]{no_scenarios}",
            path.display()
        )));
    }
    Ok(cfg)
}

/// The OpenFOAM flags refused: OpenFOAM solves a hall, which a model of your own is not.
pub(crate) fn refuse_openfoam_flags(openfoam: &OpenFoamArgs) -> CliResult {
    openfoam.refuse_unless_because(
        false,
        "OpenFOAM solves a hall, and a model of your own runs its own program",
    )
}
