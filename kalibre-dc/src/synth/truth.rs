//! The hidden ground truth of a synthetic hall (`truth.json`, `kalibre.truth/1`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::hall::EffectSpec;

/// The schema tag of `truth.json`.
pub const TRUTH_SCHEMA: &str = "kalibre.truth/1";

/// What generated a synthetic hall's measurements; never read by calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truth {
    /// Always `kalibre.truth/1`.
    pub schema: String,
    /// Preset name (`demo`, `hall-a`, `hall-b`).
    pub preset: String,
    /// The seed everything was drawn from.
    pub seed: u64,
    /// The hall's `name`.
    pub hall_name: String,
    /// True base alpha per server type (cfm/W), before the per-server jitter.
    pub alpha_type_cfm_per_w: BTreeMap<String, f64>,
    /// Half-width of the uniform per-server multiplicative jitter (0.03 = +-3 %).
    pub alpha_jitter: f64,
    /// True alpha per server (cfm/W), in hall order.
    pub alpha_server_cfm_per_w: Vec<ServerAlpha>,
    /// The initial alpha written into `hall.json` for every type, and how it was chosen.
    pub alpha_initial: InitialAlpha,
    /// Effects present in the measurements but absent from `hall.json`.
    pub hidden_effects: Vec<HiddenEffect>,
    /// Measurement noise.
    pub noise: Noise,
    /// Grids used.
    pub grid: GridInfo,
    /// Per snapshot: flows and readings.
    pub snapshots: Vec<TruthSnapshot>,
    /// Mean absolute errors of reference model runs against the noisy measurements.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceErrors>,
}

impl Truth {
    /// The true alpha of every server (cfm/W), in hall order.
    pub fn alpha_per_server(&self) -> Vec<f64> {
        self.alpha_server_cfm_per_w
            .iter()
            .map(|a| a.alpha_cfm_per_w)
            .collect()
    }

    /// A server's true intake air in a snapshot (C), when the truth records it.
    pub fn server_intake_c(&self, snapshot: &str, server: &str) -> Option<f64> {
        self.snapshots
            .iter()
            .find(|t| t.label == snapshot)?
            .server_intake_c
            .as_ref()?
            .get(server)
            .copied()
    }
}

/// The true alpha of one server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServerAlpha {
    /// Server id.
    pub id: String,
    /// Server type id.
    #[serde(rename = "type")]
    pub server_type: String,
    /// True alpha (cfm/W).
    pub alpha_cfm_per_w: f64,
}

/// The hall's initial (deliberately wrong) alpha.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialAlpha {
    /// The value written for every type (cfm/W).
    pub value_cfm_per_w: f64,
    /// How it was chosen.
    pub policy: String,
}

/// An effect hidden in the measurements.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HiddenEffect {
    /// The entry as requested (`--effect`).
    pub requested: EffectSpec,
    /// The entry as the effect resolved it (defaults filled in): pasting it into
    /// `hall.json` `effects` reproduces the effect.
    pub resolved: EffectSpec,
    /// Its parameter values, by effect-relative name.
    pub parameters: BTreeMap<String, f64>,
}

/// The measurement noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Always `gaussian`.
    pub distribution: String,
    /// Standard deviation (C).
    pub sigma_c: f64,
    /// Readings are rounded to this step after adding noise (C).
    pub rounding_c: f64,
    /// The seed of the noise stream (derived from the hall seed).
    pub seed: u64,
}

/// The grids of the measurement simulation and of the model's default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridInfo {
    /// Cell size of the simulation that produced the measurements (m).
    pub measurement_cell_m: f64,
    /// Cells of that simulation.
    pub measurement_cells: usize,
    /// The simulator's default cell size, used for the reference model runs (m).
    pub model_cell_m: f64,
}

/// Flows and readings of one snapshot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSnapshot {
    /// Snapshot label as in `snapshots.csv`.
    pub label: String,
    /// Total CRAC supply flow (m3/s).
    pub supply_flow_m3_s: f64,
    /// Total true server air flow (m3/s).
    pub server_flow_m3_s: f64,
    /// Total server power (W).
    pub power_w: f64,
    /// Noise-free readings of the measurement simulation (C), by sensor id.
    pub sensor_c_noise_free: BTreeMap<String, f64>,
    /// The model on its default grid at the true alphas and true hidden effects (C): the
    /// best a complete model can do; its error is the noise and model-form floor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_c_model_at_truth: Option<BTreeMap<String, f64>>,
    /// Each server's intake air in the measurement simulation (C, the flow-weighted mean
    /// over its intake face), by server id: what a calibrated model should predict where
    /// no sensor measures (the OpenFOAM datasets' `truth.json` has the same key).
    /// Missing in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub server_intake_c: Option<BTreeMap<String, f64>>,
}

/// Reference errors (MAE over all snapshots and sensors, C) against the noisy readings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceErrors {
    /// The model on its default grid at the hall's initial alpha, no effects.
    pub uncalibrated_mae_c: f64,
    /// The model on its default grid at the true alphas and hidden effects.
    pub model_at_truth_mae_c: f64,
    /// The model on its default grid at the true alphas without the hidden effects
    /// (equal to `model_at_truth_mae_c` when nothing is hidden).
    pub model_at_truth_without_effects_mae_c: f64,
    /// The noise-free measurement simulation (noise alone).
    pub noise_only_mae_c: f64,
}
