//! The demo hall whose measurements hide a cut-out, and the steps of the story: calibrate
//! alpha, diagnose, add the suggested entry, recalibrate.

use std::time::Instant;

use kalibre::core::Model;
use kalibre::dc::calibration::{
    calibrate_hall_with_registry, HallCalibration, HallCalibrationSettings,
};
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosis, HallDiagnosisSettings};
use kalibre::dc::effects::{EffectFactory, EffectRegistry};
use kalibre::dc::hall::{AlphaMode, EffectSpec, Hall};
use kalibre::dc::sim::SimConfig;
use kalibre::dc::snapshots::HallSnapshot;
use kalibre::dc::synth::{self, Preset, SynthOptions};
use kalibre::dc::{Error, HallModel, Result};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::{CutoutBypassFactory, KIND};

/// What the demo hall hides.
///
/// | field | default | meaning |
/// |---|---|---|
/// | `seed` | 7 | synth seed (layout, alphas, states) and noise seed |
/// | `noise_c` | 0.15 | Gaussian sensor noise (C) |
/// | `tile` | 8 | which candidate tile (1-based along the first hot aisle) leaks |
/// | `flow_fraction` | 0.1 | the true share of the supply through it |
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// Seed of everything.
    pub seed: u64,
    /// Noise (C).
    pub noise_c: f64,
    /// The leaking tile, 1-based among the candidates.
    pub tile: usize,
    /// True flow fraction.
    pub flow_fraction: f64,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            seed: 7,
            noise_c: 0.15,
            tile: 8,
            flow_fraction: 0.1,
        }
    }
}

/// A demo hall, its noisy readings and what they hide.
#[derive(Debug, Clone)]
pub struct DemoHall {
    /// The hall as a modeller describes it: no effect, alpha a guess.
    pub hall: Hall,
    /// Snapshots with readings of the truth (fine grid, true alphas, the cut-out, noise).
    pub snapshots: Vec<HallSnapshot>,
    /// The hidden entry, with its true flow fraction.
    pub hidden: EffectSpec,
    /// True alpha per type (cfm/W), in the order of `hall.server_types`.
    pub true_alpha_type: Vec<f64>,
    /// MAE (C) of the model (default grid) at the true alphas and the true cut-out: the
    /// floor a perfect calibration reaches (grid error and noise).
    pub floor_mae_c: f64,
    /// MAE (C) of the model at the true alphas without the cut-out.
    pub no_effect_mae_c: f64,
    /// MAE (C) of the noise alone (readings against the noise-free truth): the issue's
    /// noise-only floor.
    pub noise_mae_c: f64,
}

fn mae(pred: &[Vec<f64>], snaps: &[HallSnapshot]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, s) in pred.iter().zip(snaps) {
        for (y, m) in p.iter().zip(&s.sensor_c) {
            if let Some(m) = m {
                sum += (y - m).abs();
                n += 1;
            }
        }
    }
    sum / n.max(1) as f64
}

/// Readings of `hall` (per-server alpha `alpha`, extra `effects` at their initial values)
/// on a grid of `cell_m`.
fn simulate(
    hall: &Hall,
    states: &[HallSnapshot],
    alpha: &[f64],
    effects: &[EffectSpec],
    registry: &EffectRegistry,
    cell_m: f64,
) -> Result<Vec<Vec<f64>>> {
    let mut h = hall.clone();
    h.calibrate.alpha = AlphaMode::PerServer;
    h.effects = effects.to_vec();
    let model = HallModel::with_registry(&h, SimConfig::default().with_cell_m(cell_m), registry)?;
    let mut params = model.layout().space().initial();
    params[..alpha.len()].copy_from_slice(alpha);
    states
        .iter()
        .map(|s| {
            model
                .evaluate(&s.state, &params)
                .map(|o| o.values)
                .map_err(|e| Error::Simulation(format!("snapshot `{}`: {e}", s.state.label)))
        })
        .collect()
}

/// Builds the demo: the synthetic `demo` hall and states of `options.seed`, readings
/// simulated on the synth's measurement grid (0.1 m) at the true per-server alphas with
/// the cut-out, plus seeded Gaussian noise rounded to 0.01 C.
pub fn demo_hall(options: &DemoOptions, registry: &EffectRegistry) -> Result<DemoHall> {
    let synth = synth::generate(
        &SynthOptions::new(Preset::Demo, options.seed)
            .with_noise_c(options.noise_c)
            .with_reference_runs(false),
    )?;
    let hall = synth.hall;
    let candidates = CutoutBypassFactory.candidates(&hall);
    let mut hidden = candidates
        .get(options.tile.wrapping_sub(1))
        .cloned()
        .ok_or_else(|| {
            Error::Mismatch(format!(
                "tile {} of {} candidates",
                options.tile,
                candidates.len()
            ))
        })?;
    hidden
        .fields
        .insert("flow_fraction".into(), options.flow_fraction.into());
    let alpha: Vec<f64> = hall
        .servers()
        .map(|s| {
            synth
                .truth
                .alpha_server_cfm_per_w
                .iter()
                .find(|a| a.id == s.server.id)
                .map(|a| a.alpha_cfm_per_w)
                .ok_or_else(|| Error::Mismatch(format!("no true alpha of `{}`", s.server.id)))
        })
        .collect::<Result<_>>()?;
    let fine = synth.truth.grid.measurement_cell_m;
    let clean = simulate(
        &hall,
        &synth.snapshots,
        &alpha,
        std::slice::from_ref(&hidden),
        registry,
        fine,
    )?;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(options.seed ^ 0x6375_746f_7574);
    let noise =
        Normal::new(0.0, options.noise_c).map_err(|e| Error::Mismatch(format!("noise_c: {e}")))?;
    let snapshots: Vec<HallSnapshot> = synth
        .snapshots
        .iter()
        .zip(&clean)
        .map(|(s, y)| HallSnapshot {
            state: s.state.clone(),
            sensor_c: y
                .iter()
                .map(|v| Some(((v + noise.sample(&mut rng)) * 100.0).round() / 100.0))
                .collect(),
        })
        .collect();
    let model_cell = SimConfig::default().cell_m;
    let at_truth = simulate(
        &hall,
        &snapshots,
        &alpha,
        std::slice::from_ref(&hidden),
        registry,
        model_cell,
    )?;
    let without = simulate(&hall, &snapshots, &alpha, &[], registry, model_cell)?;
    Ok(DemoHall {
        true_alpha_type: hall
            .server_types
            .iter()
            .map(|t| synth.truth.alpha_type_cfm_per_w[&t.id])
            .collect(),
        floor_mae_c: mae(&at_truth, &snapshots),
        no_effect_mae_c: mae(&without, &snapshots),
        noise_mae_c: mae(&clean, &snapshots),
        hall,
        snapshots,
        hidden,
    })
}

/// One calibration of the story.
#[derive(Debug)]
pub struct CalibrationStep {
    /// The calibration.
    pub calibration: HallCalibration,
    /// Wall time (s).
    pub wall_s: f64,
}

impl CalibrationStep {
    /// MAE (C) at the initial parameters.
    pub fn mae_before(&self) -> f64 {
        self.calibration.report.initial.mae_c.unwrap_or(f64::NAN)
    }

    /// Best MAE (C).
    pub fn mae_after(&self) -> f64 {
        self.calibration.report.best.mae_c
    }
}

/// Calibrates `hall` (alpha and its effects, built by `registry`).
pub fn calibrate(
    hall: &Hall,
    snaps: &[HallSnapshot],
    registry: &EffectRegistry,
    settings: &HallCalibrationSettings,
) -> Result<CalibrationStep> {
    let t = Instant::now();
    let calibration = calibrate_hall_with_registry(hall, snaps, settings, registry, None, vec![])?;
    Ok(CalibrationStep {
        calibration,
        wall_s: t.elapsed().as_secs_f64(),
    })
}

/// Diagnoses `hall` at `params` (its layout order) with every kind of `registry`.
pub fn diagnose(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
    registry: &EffectRegistry,
) -> Result<HallDiagnosis> {
    diagnose_hall(
        hall,
        snaps,
        params,
        registry,
        &HallDiagnosisSettings::default(),
    )
}

/// The rank (0-based) and the suggestion of the best `cutout_bypass` hypothesis.
pub fn best_cutout(d: &HallDiagnosis) -> Option<(usize, &EffectSpec)> {
    d.suggestions
        .iter()
        .enumerate()
        .find(|(_, s)| s.kind == KIND)
}

/// `hall` with `entry` added to its effects (what a user pastes into `hall.json`).
pub fn with_effect(hall: &Hall, entry: &EffectSpec) -> Hall {
    let mut h = hall.clone();
    h.effects.push(entry.clone());
    h
}
