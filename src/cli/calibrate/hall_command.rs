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

impl Model for HallCommand {
    type Scenario = OperatingState;

    fn fingerprint(&self) -> String {
        self.command.fingerprint()
    }

    fn evaluate(&self, state: &OperatingState, params: &[f64]) -> Result<Outputs, ModelError> {
        self.command.evaluate(&self.scenario(state), params)
    }

    fn check_plausible(&self, outputs: &Outputs) -> Result<(), ModelError> {
        kalibre_dc::check_sensor_c(&outputs.values, self.command.output_names())
    }
}
