//! `--model command`: an external command, described by `model.toml`, as a hall's model.

use std::path::Path;

use kalibre_core::external::{CommandModelConfig, ExternalCommand, NamedScenario};
use kalibre_core::{Model, ModelError, Outputs};
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::ParamLayout;

use crate::cli::{CliError, CliResult};

/// An external command as a hall's model: each snapshot becomes the template variables
/// `setpoint_c/<crac>`, `fan_speed/<crac>` and `power_w/<server>`.
pub(super) struct HallCommand {
    pub(super) command: ExternalCommand<NamedScenario>,
    pub(super) layout: ParamLayout,
    crac_ids: Vec<String>,
    server_ids: Vec<String>,
    /// The `[[params]]` whose bounds, initial value or scale differ from the hall's, which
    /// the search uses: said once, so an edit of `model.toml` is not taken to count.
    pub(super) unused_param_settings: Vec<String>,
}

impl HallCommand {
    pub(super) fn new(hall: &Hall, config: CommandModelConfig, path: &Path) -> CliResult<Self> {
        let bad = |what: String| CliError::Input(format!("{}: {what}", path.display()));
        let effects = EffectRegistry::builtin().build_all(hall)?;
        let layout = ParamLayout::new(hall, &effects)?;
        let want = layout.space().names();
        let got = config.space.names();
        if want != got {
            return Err(bad(format!(
                "params must be the hall's calibrated parameters in order: [{}], got [{}]",
                want.join(", "),
                got.join(", ")
            )));
        }
        let sensors: Vec<String> = hall.sensors.iter().map(|s| s.id.clone()).collect();
        if config.command.output_names() != sensors.as_slice() {
            return Err(bad(format!(
                "output.names must be the hall's sensors in order: [{}]",
                sensors.join(", ")
            )));
        }
        let unused_param_settings = differing_params(layout.space(), &config.space);
        if !config.scenarios.is_empty() {
            return Err(bad(
                "[[scenarios]] are not used with a hall: the snapshots come from --snapshots"
                    .into(),
            ));
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

    pub(super) fn scenario(&self, state: &OperatingState) -> NamedScenario {
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
