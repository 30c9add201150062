//! `--model command`: an external command, described by `model.toml`, as a hall's model.

use std::path::Path;

use kalibre_core::external::{CommandModelConfig, ExternalCommand, NamedScenario};
use kalibre_core::{Model, ModelError, Outputs};
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{HallSnapshot, OperatingState};
use kalibre_dc::ParamLayout;

use crate::cli::{CliError, CliResult};

/// Why a `model.toml` used with a hall must not list `[[scenarios]]`.
const NO_SCENARIOS_WITH_A_HALL: &str =
    "[[scenarios]] are not used with a hall: the snapshots come from --snapshots";

/// Loads `model.toml` for a hall, whose snapshots are the scenarios: a `[[scenarios]]`
/// list is refused as such, not for a variable its entries lack.
pub(in crate::cli) fn load_config(path: &Path) -> CliResult<CommandModelConfig> {
    CommandModelConfig::load_without_scenarios(path, NO_SCENARIOS_WITH_A_HALL)
        .map_err(|e| CliError::Input(e.to_string()))
}

/// An external command as a hall's model: each snapshot becomes the template variables
/// `setpoint_c/<crac>`, `fan_speed/<crac>` and `power_w/<server>`.
pub(in crate::cli) struct HallCommand {
    pub(in crate::cli) command: ExternalCommand<NamedScenario>,
    pub(in crate::cli) layout: ParamLayout,
    crac_ids: Vec<String>,
    server_ids: Vec<String>,
    /// The `[[params]]` whose bounds, initial value or scale differ from the hall's, which
    /// the search uses: said once, so an edit of `model.toml` is not taken to count.
    pub(in crate::cli) unused_param_settings: Vec<String>,
}

impl HallCommand {
    pub(in crate::cli) fn new(
        hall: &Hall,
        config: CommandModelConfig,
        path: &Path,
    ) -> CliResult<Self> {
        let bad = |what: String| CliError::Input(format!("{}: {what}", path.display()));
        (config.command.check_program())
            .and_then(|()| config.command.check_runs_root())
            .map_err(|e| bad(e.to_string()))?;
        let effects = EffectRegistry::builtin().build_all(hall)?;
        let layout = ParamLayout::new(hall, &effects)?;
        let want = layout.space().names();
        let got = config.space.names();
        if want != got {
            return Err(bad(format!(
                "params must be the hall's calibrated parameters in order: {}; expected [{}]",
                first_difference(("params", "parameters"), &got, &want),
                crate::cli::some_names(&want)
            )));
        }
        let sensors: Vec<String> = hall.sensors.iter().map(|s| s.id.clone()).collect();
        let given = config.command.output_names();
        if given != sensors.as_slice() {
            return Err(bad(format!(
                "output.names must be the hall's sensors in order: {}; expected [{}]",
                first_difference(("output.names", "sensors"), given, &sensors),
                crate::cli::some_names(&sensors)
            )));
        }
        let unused_param_settings = differing_params(layout.space(), &config.space);
        if !config.scenarios.is_empty() {
            return Err(bad(NO_SCENARIOS_WITH_A_HALL.into()));
        }
        let model = HallCommand {
            command: config.command,
            layout,
            crac_ids: hall.cracs.iter().map(|c| c.id.clone()).collect(),
            server_ids: hall.servers().map(|s| s.server.id.clone()).collect(),
            unused_param_settings,
        };
        Ok(model)
    }

    /// Renders every placeholder of the templates and arguments for each snapshot before
    /// the first run, so that a bad template fails at once (naming `path`), not per run.
    pub(in crate::cli) fn check_snapshots(&self, snaps: &[HallSnapshot], path: &Path) -> CliResult {
        for s in snaps {
            self.command
                .check_scenario(&self.scenario(&s.state))
                .map_err(|e| CliError::Input(format!("{}: {e}", path.display())))?;
        }
        Ok(())
    }

    pub(in crate::cli) fn scenario(&self, state: &OperatingState) -> NamedScenario {
        let mut s = NamedScenario::new(state.label.clone());
        for (i, id) in self.crac_ids.iter().enumerate() {
            s = s
                .with(format!("setpoint_c/{id}"), state.setpoint_c[i])
                .with(format!("fan_speed/{id}"), state.fan_speed[i]);
        }
        for (id, p) in self.server_ids.iter().zip(&state.power_w) {
            s = s.with(format!("power_w/{id}"), *p);
        }
        s
    }
}

/// Where the `given` list (`list`: its key and what it names) first parts from the
/// hall's `want`, in words: with the 60-70 sensors of a large hall, or thousands of
/// per-server parameters, the whole lists alone hide a swapped pair.
fn first_difference((list, what): (&str, &str), given: &[String], want: &[String]) -> String {
    match given.iter().zip(want).position(|(g, s)| g != s) {
        Some(i) => {
            let where_ = match want[i..].iter().position(|s| *s == given[i]) {
                Some(k) => format!(", which comes at index {} in the hall's order", i + k),
                None if want.contains(&given[i]) => {
                    ", which the hall has earlier (given twice?)".into()
                }
                None => format!(" (`{}` is not one of the hall's {what})", given[i]),
            };
            format!(
                "{list}[{i}] is `{}` where the hall has `{}`{where_}",
                given[i], want[i]
            )
        }
        None if given.len() < want.len() => format!(
            "{} names given, the hall has {} {what} (the first missing: `{}`)",
            given.len(),
            want.len(),
            want[given.len()]
        ),
        None => format!(
            "{} names given, the hall has {} {what} (the first extra: `{}`)",
            given.len(),
            want.len(),
            given[want.len()]
        ),
    }
}

/// Each `model.toml` parameter (named as the hall's) whose bounds, initial value or scale
/// differ from the hall's: `name [lower, upper] from initial, scale (the hall: ...)`.
fn differing_params(
    hall: &kalibre_core::ParamSpace,
    config: &kalibre_core::ParamSpace,
) -> Vec<String> {
    let show = |p: &kalibre_core::Param| {
        format!(
            "[{}, {}] from {}, {:?}",
            p.lower, p.upper, p.initial, p.scale
        )
        .to_lowercase()
    };
    hall.params()
        .iter()
        .zip(config.params())
        .filter(|(h, c)| {
            (h.lower, h.upper, h.initial, h.scale) != (c.lower, c.upper, c.initial, c.scale)
        })
        .map(|(h, c)| format!("{} {} (the hall: {})", h.name, show(c), show(h)))
        .collect()
}

impl Model for HallCommand {
    type Scenario = OperatingState;

    fn fingerprint(&self) -> String {
        self.command.fingerprint()
    }

    fn evaluate(&self, state: &OperatingState, params: &[f64]) -> Result<Outputs, ModelError> {
        self.command.evaluate(&self.scenario(state), params)
    }

    fn scenario_key(&self, scenario: &OperatingState) -> String {
        self.command.scenario_key(&self.scenario(scenario))
    }

    fn check_plausible(&self, outputs: &Outputs) -> Result<(), ModelError> {
        kalibre_dc::check_sensor_c(&outputs.values, self.command.output_names())
    }
}

#[cfg(test)]
mod tests {
    use super::first_difference;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    /// Each way a list parts from the hall's is named by the entry at fault.
    #[test]
    fn the_first_difference_names_the_entry_at_fault() {
        let hall = names(&["alpha/web", "alpha/db", "alpha/gpu"]);
        let list = ("params", "parameters");
        let said = |given: &[&str]| first_difference(list, &names(given), &hall);
        assert_eq!(
            said(&["alpha/WEB", "alpha/db", "alpha/gpu"]),
            "params[0] is `alpha/WEB` where the hall has `alpha/web` (`alpha/WEB` is not one \
             of the hall's parameters)"
        );
        assert!(said(&["alpha/db", "alpha/web", "alpha/gpu"])
            .ends_with("which comes at index 1 in the hall's order"));
        assert!(said(&["alpha/web", "alpha/web", "alpha/gpu"])
            .ends_with("which the hall has earlier (given twice?)"));
        assert!(said(&["alpha/web"]).contains("the first missing: `alpha/db`"));
    }
}
