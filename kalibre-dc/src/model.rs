//! The built-in simulator as a kalibre [`kalibre_core::Model`].

use kalibre_core::{check_outputs, Model, ModelError, Outputs};

use crate::effects::{mods_at_upper_bounds, Effect, EffectRegistry};
use crate::hall::{Hall, SupplyKind};
use crate::sim::{
    rack_heat, server_air, FrontSupply, RackHeat, SensorInfluence, ServerAir, SimConfig, Simulator,
    Solution,
};
use crate::snapshots::OperatingState;
use crate::{Error, ParamLayout, Result};

/// Checks that each effect acts somewhere on `sim`'s grid: its modifications at its
/// parameters' upper bounds ([`mods_at_upper_bounds`]) resolved onto open cells. An
/// effect that acts nowhere would fail every run that gives it a value.
fn check_effect_placements(sim: &Simulator, effects: &[Box<dyn Effect>]) -> Result<()> {
    for (i, effect) in effects.iter().enumerate() {
        let mods = mods_at_upper_bounds(effect.as_ref(), sim.hall())?;
        sim.check_placements(&mods).map_err(|e| match e {
            Error::Geometry(message) => Error::Effect {
                kind: effect.kind().to_string(),
                message: format!("effects/{i}: {message}"),
            },
            other => other,
        })?;
    }
    Ok(())
}

/// A hall's thermal model: the simulator, the hall's effects and the parameter layout.
///
/// Parameters (in [`Self::layout`] order) are alpha per type or server, then each
/// effect's parameters; outputs are the sensor temperatures in hall order.
#[derive(Debug)]
pub struct HallModel {
    sim: Simulator,
    effects: Vec<Box<dyn Effect>>,
    layout: ParamLayout,
    fingerprint: String,
    /// The fingerprint earlier versions gave this model ([`legacy_fingerprint`]); none
    /// for a hall with `front` CRACs, whose supply they released otherwise, or with a
    /// sensor beside a containment panel, which they read across it.
    legacy_fingerprint: Option<String>,
    sensor_names: Vec<String>,
}

impl HallModel {
    /// The model of `hall` with the built-in effect kinds for `hall.effects`.
    pub fn new(hall: &Hall, config: SimConfig) -> Result<Self> {
        Self::with_registry(hall, config, &EffectRegistry::builtin())
    }

    /// The model with `hall.effects` built by `registry` (for downstream effect kinds).
    pub fn with_registry(
        hall: &Hall,
        config: SimConfig,
        registry: &EffectRegistry,
    ) -> Result<Self> {
        let effects = registry.build_all(hall)?;
        Self::with_effects(hall, config, effects)
    }

    /// The model with explicit effects (in place of `hall.effects`).
    pub fn with_effects(
        hall: &Hall,
        config: SimConfig,
        effects: Vec<Box<dyn Effect>>,
    ) -> Result<Self> {
        let layout = ParamLayout::new(hall, &effects)?;
        let config_json =
            serde_json::to_string(&config).map_err(|e| Error::Mismatch(format!("config: {e}")))?;
        let model_json = hall.model_json(hall.calibrate.alpha, &effects);
        let mut parts = vec![model_json.as_bytes(), config_json.as_bytes()];
        // A `front` CRAC's supply enters along its jet since session 58, where it
        // entered at its face before: runs made before are another model's, so such a
        // hall's fingerprint says so and has no legacy one. Other halls keep theirs.
        let front_jet = hall.cracs.iter().any(|c| c.supply == SupplyKind::Front)
            && config.front_supply == FrontSupply::Jet;
        if front_jet {
            parts.push(FRONT_SUPPLY_JET.as_bytes());
        }
        let sim = Simulator::new(hall, config)?;
        // A sensor within half a cell of a containment panel reads its own side's air
        // since session 59, a blend with the other side's before: the same holds there.
        let beside_panels = !sim.sensors_beside_panels().is_empty();
        if beside_panels {
            parts.push(SENSORS_BESIDE_PANELS.as_bytes());
        }
        // So is a containment side on a cell centre: outward since session 59.
        let tied = crate::sim::containment_side_on_cell_centre(hall, sim.grid());
        if tied {
            parts.push(CONTAINMENT_TIES_OUTWARD.as_bytes());
        }
        let fingerprint = format!("{SIM_FINGERPRINT}:{:016x}", fnv1a(&parts));
        let legacy_fingerprint = if front_jet || beside_panels || tied {
            None
        } else {
            Some(legacy_fingerprint(hall, &config_json, &effects)?)
        };
        check_effect_placements(&sim, &effects)?;
        let sensor_names = hall.sensors.iter().map(|s| s.id.clone()).collect();
        Ok(HallModel {
            sim,
            effects,
            layout,
            fingerprint,
            legacy_fingerprint,
            sensor_names,
        })
    }

    /// Where each parameter sits.
    pub fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    /// The simulator.
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The effects, in layout order.
    pub fn effects(&self) -> &[Box<dyn Effect>] {
        &self.effects
    }

    /// Every server's air in one state at `params` (layout order): what the model says
    /// where no sensor measures.
    pub fn server_air(&self, state: &OperatingState, params: &[f64]) -> Result<Vec<ServerAir>> {
        let solution = self.solve(state, params)?;
        server_air(self.sim.hall(), state, &solution)
    }

    /// Solves one state at `params` (layout order), effects included, and returns the run
    /// with each sensor's sensitivity to each server's rise in its flow
    /// ([`Simulator::sensor_influence`]): one adjoint solve per sensor.
    pub fn sensor_influence(
        &self,
        state: &OperatingState,
        params: &[f64],
    ) -> Result<(Solution, SensorInfluence)> {
        self.layout.space().check_physical(params)?;
        let alpha = self.layout.alpha_per_server(params);
        let effects = self.effect_values(params);
        self.sim.sensor_influence(state, &alpha, &effects)
    }

    /// Solves one state at `params` and says which racks warm each sensor in its flow:
    /// every rack's part of every sensor's warming, no cut ([`crate::sim::rack_heat`]
    /// over [`Self::sensor_influence`]; one adjoint solve per sensor). The run comes back
    /// too, for whatever else is read off it.
    pub fn rack_heat(
        &self,
        state: &OperatingState,
        params: &[f64],
    ) -> Result<(Solution, Vec<RackHeat>)> {
        let (solution, influence) = self.sensor_influence(state, params)?;
        let rows = rack_heat(self.sim.hall(), &state.label, &solution, &influence, 0.0)?;
        Ok((solution, rows))
    }

    /// Each effect with its values in `params`.
    fn effect_values<'a>(&'a self, params: &'a [f64]) -> Vec<(&'a dyn Effect, &'a [f64])> {
        self.effects
            .iter()
            .enumerate()
            .map(|(e, effect)| (effect.as_ref(), self.layout.effect_values(params, e)))
            .collect()
    }

    /// Solves one state at `params` (layout order) and returns every field (for VTK and
    /// reports).
    pub fn solve(&self, state: &OperatingState, params: &[f64]) -> Result<Solution> {
        self.layout.space().check_physical(params)?;
        let alpha = self.layout.alpha_per_server(params);
        let effects = self.effect_values(params);
        self.sim.solve(state, &alpha, &effects)
    }
}

impl Model for HallModel {
    type Scenario = OperatingState;

    /// The hall ([`Hall::model_json`]: bounds and initial values of the calibrated
    /// parameters left out) and the simulator's configuration.
    fn fingerprint(&self) -> String {
        self.fingerprint.clone()
    }

    fn legacy_fingerprints(&self) -> Vec<String> {
        self.legacy_fingerprint.iter().cloned().collect()
    }

    fn evaluate(
        &self,
        scenario: &OperatingState,
        params: &[f64],
    ) -> std::result::Result<Outputs, ModelError> {
        if let Err(e) = self.layout.space().check_physical(params) {
            return Err(ModelError::InvalidParams(e.to_string()));
        }
        let sol = self
            .solve(scenario, params)
            .map_err(|e| ModelError::failed(e.to_string()))?;
        check_outputs(Outputs::from(sol.sensor_c().to_vec()), &self.sensor_names)
    }

    fn check_plausible(&self, outputs: &Outputs) -> std::result::Result<(), ModelError> {
        check_sensor_c(&outputs.values, &self.sensor_names)
    }

    fn scenario_key(&self, scenario: &OperatingState) -> String {
        operating_state_key(scenario)
    }
}

/// [`Model::scenario_key`] of a hall model: a digest of the snapshot's setpoints, fan
/// speeds and powers (not its label), so that a journaled run is reused only under the
/// conditions it ran at.
pub fn operating_state_key(state: &OperatingState) -> String {
    kalibre_core::scenario_digest(&format!(
        "setpoint_c {:?} fan_speed {:?} power_w {:?}",
        state.setpoint_c, state.fan_speed, state.power_w
    ))
}

/// The sensor temperatures (C) a hall model can give. Below absolute zero is impossible;
/// above 10,000 C (far past anything air-cooled, even at the lowest alpha bounds, which
/// give about 190 C on the presets) a solve has diverged or the value is not a model's.
pub const PLAUSIBLE_SENSOR_C: std::ops::RangeInclusive<f64> = -273.15..=10_000.0;

/// Every predicted sensor temperature (`sensor_c`, hall order) in
/// [`PLAUSIBLE_SENSOR_C`]: the [`Model::check_plausible`] of every hall model (built-in,
/// OpenFOAM, external command), and `kalibre simulate`'s check of its predictions.
///
/// ```
/// use kalibre_dc::check_sensor_c;
/// let names = vec!["s1".to_string(), "s2".to_string()];
/// assert!(check_sensor_c(&[24.0, 41.5], &names).is_ok());
/// assert!(check_sensor_c(&[24.0, 1e308], &names).is_err());
/// ```
pub fn check_sensor_c(
    sensor_c: &[f64],
    sensor_names: &[String],
) -> std::result::Result<(), ModelError> {
    let (lo, hi) = (PLAUSIBLE_SENSOR_C.start(), PLAUSIBLE_SENSOR_C.end());
    match sensor_c
        .iter()
        .enumerate()
        .find(|(_, v)| !PLAUSIBLE_SENSOR_C.contains(*v))
    {
        Some((index, v)) => Err(ModelError::Implausible {
            index,
            name: sensor_names
                .get(index)
                .cloned()
                .unwrap_or_else(|| format!("#{index}")),
            value: format!("{} C", crate::snapshots::number(*v)),
            reason: format!("a sensor temperature is in [{lo}, {hi}] C"),
        }),
        None => Ok(()),
    }
}

/// The version of the built-in model's fingerprint: its prefix.
const SIM_FINGERPRINT: &str = "kalibre-dc-sim/3";

/// Hashed into the fingerprint of a hall with `front` CRACs: how their supply enters.
const FRONT_SUPPLY_JET: &str = "front-supply: along the jet";

/// Hashed into the fingerprint of a hall with a sensor beside a containment panel: it
/// reads the air on its own side.
const SENSORS_BESIDE_PANELS: &str = "sensors beside panels: their own side";

/// Hashed into the fingerprint of a hall with a containment side on a cell centre: it
/// goes outward, as a rack's cells do.
const CONTAINMENT_TIES_OUTWARD: &str = "containment ties: outward";

/// The fingerprint versions before bounds and initial values were left out gave the
/// model of `hall` with `config` (as JSON) and `effects`: the hall's physics JSON, bounds
/// and initial values included, and the effects' entries as each writes itself. Kept
/// exactly, so that the runs they journaled are read as this model's
/// ([`Model::legacy_fingerprints`]).
fn legacy_fingerprint(
    hall: &Hall,
    config_json: &str,
    effects: &[Box<dyn Effect>],
) -> Result<String> {
    let specs: Vec<_> = effects.iter().map(|e| e.to_spec()).collect();
    let effects_json =
        serde_json::to_string(&specs).map_err(|e| Error::Mismatch(format!("effects: {e}")))?;
    Ok(format!(
        "{SIM_FINGERPRINT}:{:016x}",
        fnv1a(&[
            hall.physics_json().as_bytes(),
            config_json.as_bytes(),
            effects_json.as_bytes()
        ])
    ))
}

/// 64-bit FNV-1a: a hash that is stable across builds and platforms.
fn fnv1a(parts: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in parts {
        for b in p.iter().chain(b"\x00") {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}
