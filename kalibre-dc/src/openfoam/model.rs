//! [`OpenFoamModel`]: one OpenFOAM solve per model run.

mod fingerprint;
mod solve;

use std::path::{Path, PathBuf};
use std::time::Instant;

use kalibre_core::external::RunDirs;
use kalibre_core::{Model, ModelError, Outputs};

use super::case::{which, CaseDir};
use super::geometry::{CaseExtras, CaseGeometry, RackGap};
use super::params::RunInputs;
use super::step::StepFailure;
use super::{OpenFoamError, OpenFoamSettings};
use crate::effects::{mods_at_upper_bounds, Effect, EffectRegistry};
use crate::hall::Hall;
use crate::sim::SimMods;
use crate::snapshots::OperatingState;
use crate::ParamLayout;

/// The effect kinds the case can represent: a change of the tiles' temperature, an extra
/// floor opening that takes part of the tiles' flow, a gap through a rack that returns
/// part of its exhaust to its intake, and containment panels opened by a fraction.
pub const SUPPORTED_EFFECTS: [&str; 4] = [
    "crac_supply_offset",
    "bypass",
    "rack_recirculation",
    "containment_leakage",
];

/// Version of the case generator: part of the fingerprint and the case directory name.
const GENERATOR: &str = "kalibre-dc-openfoam/3";

/// The name under which a run's [`Outputs::extras`] hold every server's intake air (C,
/// hall order): flux-weighted over the intake face and averaged over the same iterations
/// as the sensors.
pub const SERVER_INTAKE_KEY: &str = "server_intake_c";

/// The name under which a run's [`Outputs::extras`] count the attempts at it that were
/// killed from outside kalibre before it ran through (absent when none was).
pub const KILLED_ATTEMPTS_KEY: &str = "killed_attempts";

/// What a meshed case samples beyond the sensors, in its directory name only: a case
/// meshed before its `controlDict` sampled the server intakes lacks them, while the
/// sensors' readings (and so the fingerprint) are unchanged.
const CASE_SAMPLES: &str = "server-intakes";

/// A hall's OpenFOAM model, with the same [`ParamLayout`] as [`crate::HallModel`].
#[derive(Debug)]
pub struct OpenFoamModel {
    hall: Hall,
    geometry: CaseGeometry,
    /// What the effects add to the mesh, in the geometry's order (`byp0`, `rec0`, ...).
    extras: CaseExtras,
    effects: Vec<Box<dyn Effect>>,
    layout: ParamLayout,
    settings: OpenFoamSettings,
    case: CaseDir,
    runs: RunDirs,
    fingerprint: String,
    /// The fingerprint versions before it gave this model (its journals are read).
    legacy_fingerprint: String,
    sensor_names: Vec<String>,
}

/// What one run did, beyond its outputs (for overhead measurements and reports).
#[derive(Debug, Clone, PartialEq)]
pub struct RunTimings {
    /// Writing the run directory and the parameter file (s).
    pub prepare_s: f64,
    /// OpenFOAM programs (decomposePar, solver) (s).
    pub solve_s: f64,
    /// Reading the probes, log and balance (s).
    pub parse_s: f64,
    /// Removing the successful run's directory (s; 0 when kept).
    pub cleanup_s: f64,
    /// Relative energy balance error.
    pub energy_balance: f64,
    /// The directories of earlier attempts at this solve that were killed from outside
    /// (kept for their logs); empty when the first attempt ran through.
    pub killed_attempts: Vec<PathBuf>,
}

fn hash_hex(parts: &[&[u8]]) -> String {
    // 64-bit FNV-1a: stable across builds and platforms.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in parts {
        for b in p.iter().chain(b"\x00") {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    format!("{h:016x}")
}

/// `(key, legacy key)` of the meshed case: the key names the case directory and its runs.
///
/// The key hashes what the mesh is built from (the hall on the grid with the effects'
/// openings and gaps, and the settings), so editing a bound, an initial value or a
/// power meshes nothing again. The legacy key is the one versions before gave (the hall's
/// physics JSON, bounds included): a case meshed under it is used as it is.
fn case_keys(
    hall: &Hall,
    geometry: &CaseGeometry,
    extras: &CaseExtras,
    settings_json: &str,
) -> (String, String) {
    let geometry_key = geometry.mesh_description();
    let key = hash_hex(&[
        GENERATOR.as_bytes(),
        b"mesh-from-geometry",
        geometry_key.as_bytes(),
        settings_json.as_bytes(),
        CASE_SAMPLES.as_bytes(),
    ]);
    let hall_json = hall.physics_json();
    let extras_key = format!("{extras:?}");
    let mut legacy_parts: Vec<&[u8]> = vec![
        GENERATOR.as_bytes(),
        hall_json.as_bytes(),
        settings_json.as_bytes(),
    ];
    if *extras != CaseExtras::default() {
        legacy_parts.push(extras_key.as_bytes());
    }
    legacy_parts.push(CASE_SAMPLES.as_bytes());
    (key, hash_hex(&legacy_parts))
}

impl OpenFoamModel {
    /// The model of `hall` with its own effects (`hall.effects`) and alpha mode.
    pub fn new(hall: &Hall, settings: OpenFoamSettings) -> Result<Self, OpenFoamError> {
        let effects = EffectRegistry::builtin().build_all(hall)?;
        let layout = ParamLayout::new(hall, &effects)?;
        Self::with_layout(hall, settings, effects, layout)
    }

    /// The model with explicit effects and layout (as a calibration builds them).
    pub fn with_layout(
        hall: &Hall,
        settings: OpenFoamSettings,
        effects: Vec<Box<dyn Effect>>,
        layout: ParamLayout,
    ) -> Result<Self, OpenFoamError> {
        let settings = settings.check()?;
        for e in &effects {
            if !SUPPORTED_EFFECTS.contains(&e.kind()) {
                return Err(OpenFoamError::Unsupported(format!(
                    "effect `{}` (supported: {})",
                    e.kind(),
                    SUPPORTED_EFFECTS.join(", ")
                )));
            }
        }
        let extras = case_extras(hall, &effects)?;
        let geometry = CaseGeometry::with_extras(hall, settings.grid_m, &extras)?;
        let settings_json = json(&settings)?;
        let (case_key, legacy_case_key) = case_keys(hall, &geometry, &extras, &settings_json);
        let (fingerprint, legacy_fingerprint) = fingerprint::fingerprints(
            hall,
            &effects,
            &fingerprint::Inputs {
                settings: &settings,
                mode: layout.mode(),
                // Only halls with panels depend on the leak (a per-run value, so not in
                // the case), and no other fingerprint moves.
                panels: !geometry.panels.is_empty(),
                extras: &extras,
            },
        )?;
        let case = CaseDir::open_or_build(&geometry, &settings, &case_key, &legacy_case_key)?;
        if settings.np > 1 && (which("mpirun").is_none() || which("decomposePar").is_none()) {
            return Err(OpenFoamError::NotInstalled("mpirun / decomposePar".into()));
        }
        let runs = RunDirs::new(case.path().with_file_name(format!("runs-{}", case.key())));
        Ok(OpenFoamModel {
            hall: hall.clone(),
            sensor_names: hall.sensors.iter().map(|s| s.id.clone()).collect(),
            geometry,
            extras,
            effects,
            layout,
            settings,
            case,
            runs,
            fingerprint,
            legacy_fingerprint,
        })
    }

    /// Where each parameter sits (the same as the built-in model's).
    pub fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    /// The case on the grid.
    pub fn geometry(&self) -> &CaseGeometry {
        &self.geometry
    }

    /// The meshed case directory.
    pub fn case_dir(&self) -> &Path {
        self.case.path()
    }

    /// The settings.
    pub fn settings(&self) -> &OpenFoamSettings {
        &self.settings
    }

    /// The inputs of one run (flows, heat, tile temperatures).
    pub fn inputs(&self, state: &OperatingState, params: &[f64]) -> Result<RunInputs, ModelError> {
        self.layout
            .space()
            .check_physical(params)
            .map_err(|e| ModelError::InvalidParams(e.to_string()))?;
        let alpha = self.layout.alpha_per_server(params);
        let values: Vec<&[f64]> = (0..self.effects.len())
            .map(|e| self.layout.effect_values(params, e))
            .collect();
        self.inputs_at(state, &alpha, &values)
    }

    /// The inputs of one run at per-server `alpha` (cfm/W) and each effect's values.
    pub fn inputs_at(
        &self,
        state: &OperatingState,
        alpha: &[f64],
        effect_values: &[&[f64]],
    ) -> Result<RunInputs, ModelError> {
        if state.power_w.len() != self.geometry.servers.len()
            || alpha.len() != self.geometry.servers.len()
            || state.setpoint_c.len() != self.hall.cracs.len()
            || state.fan_speed.len() != self.hall.cracs.len()
            || effect_values.len() != self.effects.len()
        {
            return Err(ModelError::InvalidParams(format!(
                "snapshot `{}`, alphas or effect values do not match the hall's servers, CRACs and effects",
                state.label
            )));
        }
        let mut mods = SimMods::new(self.hall.cracs.len());
        for (effect, values) in self.effects.iter().zip(effect_values) {
            effect
                .modify(values, &self.hall, &mut mods)
                .map_err(|err| ModelError::InvalidParams(err.to_string()))?;
        }
        let mut opening_share = vec![0.0; self.extras.openings.len()];
        for o in &mods.supply_openings {
            let b = self
                .extras
                .openings
                .iter()
                .position(|r| *r == o.region)
                .ok_or_else(|| {
                    ModelError::InvalidParams(format!(
                        "a supply opening at {:?} that the meshed case does not have",
                        o.region
                    ))
                })?;
            opening_share[b] += o.share;
        }
        let mut gap_fraction: Vec<(usize, f64)> =
            self.extras.gaps.iter().map(|g| (g.rack, 0.0)).collect();
        for r in &mods.rack_recirculation {
            let gap = RackGap {
                rack: r.rack,
                z_m: r.z_m,
            };
            let i = self
                .extras
                .gaps
                .iter()
                .position(|g| *g == gap)
                .ok_or_else(|| {
                    ModelError::InvalidParams(format!(
                        "a recirculation gap ({gap:?}) that the meshed case does not have"
                    ))
                })?;
            gap_fraction[i].1 += r.fraction;
        }
        // The last opening of a side wins, as in the built-in simulator.
        let mut panel_opened = vec![0.0; self.geometry.panels.len()];
        for o in &mods.wall_openings {
            for (k, p) in self.geometry.panels.iter().enumerate() {
                if p.containment == o.containment && o.sides.contains(&p.side) {
                    panel_opened[k] = o.open_fraction;
                }
            }
        }
        RunInputs::new(
            &self.hall,
            state,
            alpha,
            &mods.supply_offset_c,
            &opening_share,
            &gap_fraction,
            &self.settings,
        )
        .and_then(|inputs| inputs.with_panels(&panel_opened, &self.settings))
        .map_err(ModelError::InvalidParams)
    }

    /// Runs one solve, returning the outputs and where the time went.
    pub fn evaluate_timed(
        &self,
        state: &OperatingState,
        params: &[f64],
    ) -> Result<(Outputs, RunTimings), ModelError> {
        let t0 = Instant::now();
        let inputs = self.inputs(state, params)?;
        self.solve_inputs(state, params, &inputs, t0)
    }

    /// Runs one solve at per-server `alpha` (cfm/W) and each effect's values (as a
    /// diagnosis linearises candidates), returning the outputs and where the time went.
    pub fn evaluate_at(
        &self,
        state: &OperatingState,
        alpha: &[f64],
        effect_values: &[&[f64]],
    ) -> Result<(Outputs, RunTimings), ModelError> {
        let t0 = Instant::now();
        let inputs = self.inputs_at(state, alpha, effect_values)?;
        let key: Vec<f64> = alpha
            .iter()
            .chain(effect_values.iter().flat_map(|v| v.iter()))
            .copied()
            .collect();
        self.solve_inputs(state, &key, &inputs, t0)
    }

    /// Solves `inputs` in a fresh run directory named from `key`'s values. A solve killed
    /// from outside (the out-of-memory killer, an administrator) is solved again in
    /// another fresh directory, up to `killed_retries` times: the kill says nothing about
    /// the parameters, and a journaled failure would stand until a resume. The killed
    /// attempts' directories stay, for their logs.
    fn solve_inputs(
        &self,
        state: &OperatingState,
        key: &[f64],
        inputs: &RunInputs,
        mut t0: Instant,
    ) -> Result<(Outputs, RunTimings), ModelError> {
        let key = key.iter().fold(
            u128::from_str_radix(&self.fingerprint[GENERATOR.len() + 1..], 16).unwrap_or(0),
            |h, p| h.rotate_left(13) ^ u128::from(p.to_bits()),
        );
        let attempts = self.settings.killed_retries.saturating_add(1);
        let mut killed = Vec::new();
        loop {
            let dir = self
                .runs
                .create(&state.label, key)
                .map_err(|e| ModelError::failed(format!("cannot create a run directory: {e}")))?;
            let mut result = self.run_in(&dir, inputs, t0);
            if let Err(StepFailure {
                killed_by: Some(_), ..
            }) = &result
            {
                if killed.len() + 1 < attempts as usize {
                    killed.push(dir.to_path_buf());
                    t0 = Instant::now();
                    continue;
                }
            }
            let keep = self.settings.keep_runs || result.is_err();
            if !keep {
                let t3 = Instant::now();
                let _ = std::fs::remove_dir_all(&dir);
                if let Ok((_, timings)) = &mut result {
                    timings.cleanup_s = t3.elapsed().as_secs_f64();
                }
            }
            return match result {
                Ok((mut outputs, mut timings)) => {
                    // Journaled with the run: an outside kill it outlived is not lost.
                    if !killed.is_empty() {
                        outputs
                            .extras
                            .insert(KILLED_ATTEMPTS_KEY.into(), vec![killed.len() as f64]);
                    }
                    timings.killed_attempts = killed;
                    Ok((outputs, timings))
                }
                Err(f) => {
                    let error = match f.error {
                        ModelError::Failed { reason, log_tail } if !killed.is_empty() => {
                            ModelError::Failed {
                                reason: format!(
                                    "{reason} (attempt {} of {attempts})",
                                    killed.len() + 1
                                ),
                                log_tail,
                            }
                        }
                        e => e,
                    };
                    Err(error.with_run_dir(&dir))
                }
            };
        }
    }
}

impl Model for OpenFoamModel {
    type Scenario = OperatingState;

    fn fingerprint(&self) -> String {
        self.fingerprint.clone()
    }

    fn legacy_fingerprints(&self) -> Vec<String> {
        vec![self.legacy_fingerprint.clone()]
    }

    fn evaluate(&self, scenario: &OperatingState, params: &[f64]) -> Result<Outputs, ModelError> {
        self.evaluate_timed(scenario, params).map(|(o, _)| o)
    }

    fn check_plausible(&self, outputs: &Outputs) -> Result<(), ModelError> {
        crate::check_sensor_c(&outputs.values, &self.sensor_names)
    }

    fn scenario_key(&self, scenario: &OperatingState) -> String {
        crate::operating_state_key(scenario)
    }
}

/// What `effects` add to the mesh: their openings and gaps, each effect at its
/// parameters' upper bounds showing where they are (they must be known before any run).
fn case_extras(hall: &Hall, effects: &[Box<dyn Effect>]) -> Result<CaseExtras, OpenFoamError> {
    let mut extras = CaseExtras::default();
    for (e, effect) in effects.iter().enumerate() {
        let mods = mods_at_upper_bounds(effect.as_ref(), hall)
            .map_err(|err| OpenFoamError::Unsupported(format!("effect {e}: {err}")))?;
        for o in mods.supply_openings {
            if !extras.openings.contains(&o.region) {
                extras.openings.push(o.region);
            }
        }
        for r in mods.rack_recirculation {
            let gap = RackGap {
                rack: r.rack,
                z_m: r.z_m,
            };
            if !extras.gaps.contains(&gap) {
                extras.gaps.push(gap);
            }
        }
    }
    Ok(extras)
}

/// JSON text of a value, for fingerprints.
fn json<T: serde::Serialize>(v: &T) -> Result<String, OpenFoamError> {
    serde_json::to_string(v).map_err(|e| OpenFoamError::Setting {
        name: "fingerprint".into(),
        reason: e.to_string(),
    })
}
