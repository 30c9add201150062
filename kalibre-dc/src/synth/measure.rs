//! The measurements of a synthetic hall: the built-in simulator at the true alphas and
//! hidden effects on a fine grid, then seeded Gaussian noise rounded to 0.01 C; and the
//! reference runs of the model on its default grid.

use std::collections::BTreeMap;

use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::operate::{round_to, TrueAlpha, ALPHA_JITTER, M3_S_PER_CFM};
use super::truth::{
    GridInfo, HiddenEffect, InitialAlpha, Noise, ReferenceErrors, ServerAlpha, Truth,
    TruthSnapshot, TRUTH_SCHEMA,
};
use super::SynthOptions;
use crate::effects::{self, Effect};
use crate::hall::Hall;
use crate::sim::{SimConfig, Simulator};
use crate::snapshots::{HallSnapshot, OperatingState};
use crate::{Error, Result};

/// Readings are rounded to this step (C).
const ROUNDING_C: f64 = 0.01;

/// Snapshots with noisy readings and the truth behind them.
pub(crate) struct Measured {
    pub snapshots: Vec<HallSnapshot>,
    pub truth: Truth,
}

/// Sensor readings of every state, in order (rayon collects in order, so the result does
/// not depend on the thread count).
fn run_all(
    sim: &Simulator,
    states: &[OperatingState],
    alpha: &[f64],
    effects: &[(&dyn Effect, &[f64])],
) -> Result<Vec<Vec<f64>>> {
    states
        .par_iter()
        .map(|s| {
            sim.solve(s, alpha, effects)
                .map(|sol| sol.sensor_c().to_vec())
        })
        .collect()
}

/// Mean absolute difference over all snapshots and sensors.
fn mae(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (x, y) in a.iter().zip(b) {
        for (u, v) in x.iter().zip(y) {
            sum += (u - v).abs();
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

fn sim_config(cell_m: f64) -> SimConfig {
    SimConfig {
        cell_m,
        ..SimConfig::default()
    }
}

/// Number of cells of a grid of `cell_m` over `size_m` (as the simulator's grid rounds).
fn cells(size_m: [f64; 3], cell_m: f64) -> usize {
    size_m
        .iter()
        .map(|l| ((l / cell_m).round() as usize).max(2))
        .product()
}

/// Simulates the measurements and assembles the truth.
#[allow(clippy::too_many_arguments)]
pub(crate) fn measure<R: Rng>(
    hall: &Hall,
    states: &[OperatingState],
    alpha: &TrueAlpha,
    options: &SynthOptions,
    initial: InitialAlpha,
    noise_seed: u64,
    noise_rng: &mut R,
) -> Result<Measured> {
    let built: Vec<Box<dyn Effect>> = options
        .effects
        .iter()
        .map(|s| effects::from_spec(s, hall))
        .collect::<Result<_>>()?;
    // The truth it writes must be a hall's `effects`, which refuse such a pair.
    if let Some((first, again)) = effects::first_repeat(&built) {
        return Err(crate::Error::Mismatch(format!(
            "synth options: hidden effect {} (`{}`) is the same kind in the same place as \
             hidden effect {}: only their sum would act; give one",
            again + 1,
            built[again].kind(),
            first + 1
        )));
    }
    if let Some((first, again, _)) = effects::first_overlapping_openings(&built, hall) {
        return Err(crate::Error::Mismatch(format!(
            "synth options: hidden effect {} (`{}`) opens the floor where hidden effect {} \
             does: the two could not be told apart there; give openings that do not overlap",
            again + 1,
            built[again].kind(),
            first + 1
        )));
    }
    let values: Vec<Vec<f64>> = built
        .iter()
        .map(|e| e.parameters().iter().map(|p| p.initial).collect())
        .collect();
    let hidden: Vec<(&dyn Effect, &[f64])> = built
        .iter()
        .zip(&values)
        .map(|(e, v)| (e.as_ref(), v.as_slice()))
        .collect();

    let fine_cell = options.measurement_cell();
    let fine = Simulator::new(hall, sim_config(fine_cell))?;
    // Sensor readings and server intakes of every state, in order.
    let (noise_free, intakes): (Vec<Vec<f64>>, Vec<Vec<f64>>) = states
        .par_iter()
        .map(|s| {
            fine.solve(s, &alpha.per_server, &hidden)
                .map(|sol| (sol.sensor_c().to_vec(), sol.server_intake_c.clone()))
        })
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .unzip();
    drop(fine);

    let normal = Normal::new(0.0, options.noise_c)
        .map_err(|e| Error::Mismatch(format!("noise_c {}: {e}", options.noise_c)))?;
    let noisy: Vec<Vec<f64>> = noise_free
        .iter()
        .map(|row| {
            row.iter()
                .map(|t| round_to(t + normal.sample(noise_rng), ROUNDING_C))
                .collect()
        })
        .collect();

    let model_cell = options.model_cell();
    let (at_truth, reference) = if options.reference_runs {
        let model = Simulator::new(hall, sim_config(model_cell))?;
        let uncalibrated: Vec<f64> = hall
            .server_types
            .iter()
            .map(|t| t.alpha_cfm_per_w.initial)
            .collect();
        let uncal_alpha: Vec<f64> = hall
            .server_type_indices()
            .into_iter()
            .map(|t| uncalibrated[t.unwrap_or(0)])
            .collect();
        let uncal = run_all(&model, states, &uncal_alpha, &[])?;
        let truth_runs = run_all(&model, states, &alpha.per_server, &hidden)?;
        let without = if hidden.is_empty() {
            mae(&truth_runs, &noisy)
        } else {
            mae(&run_all(&model, states, &alpha.per_server, &[])?, &noisy)
        };
        let reference = ReferenceErrors {
            uncalibrated_mae_c: mae(&uncal, &noisy),
            model_at_truth_mae_c: mae(&truth_runs, &noisy),
            model_at_truth_without_effects_mae_c: without,
            noise_only_mae_c: mae(&noise_free, &noisy),
        };
        (Some(truth_runs), Some(reference))
    } else {
        (None, None)
    };

    let by_sensor = |row: &[f64]| -> BTreeMap<String, f64> {
        hall.sensors
            .iter()
            .zip(row)
            .map(|(s, v)| (s.id.clone(), *v))
            .collect()
    };
    let rated: Vec<f64> = hall.cracs.iter().map(|c| c.rated_flow_m3_s).collect();
    let truth_snapshots = states
        .iter()
        .enumerate()
        .map(|(k, s)| TruthSnapshot {
            label: s.label.clone(),
            supply_flow_m3_s: s.fan_speed.iter().zip(&rated).map(|(f, r)| f * r).sum(),
            server_flow_m3_s: alpha
                .per_server
                .iter()
                .zip(&s.power_w)
                .map(|(a, p)| a * p * M3_S_PER_CFM)
                .sum(),
            power_w: s.power_w.iter().sum(),
            sensor_c_noise_free: by_sensor(&noise_free[k]),
            sensor_c_model_at_truth: at_truth.as_ref().map(|t| by_sensor(&t[k])),
            server_intake_c: Some(
                hall.servers()
                    .zip(&intakes[k])
                    .map(|(s, v)| (s.server.id.clone(), *v))
                    .collect(),
            ),
        })
        .collect();

    let truth = Truth {
        schema: TRUTH_SCHEMA.to_string(),
        preset: options.preset.to_string(),
        seed: options.seed,
        hall_name: hall.name.clone(),
        alpha_type_cfm_per_w: hall
            .server_types
            .iter()
            .zip(&alpha.per_type)
            .map(|(t, a)| (t.id.clone(), *a))
            .collect(),
        alpha_jitter: ALPHA_JITTER,
        alpha_server_cfm_per_w: hall
            .servers()
            .zip(&alpha.per_server)
            .map(|(s, a)| ServerAlpha {
                id: s.server.id.clone(),
                server_type: s.server.server_type.clone(),
                alpha_cfm_per_w: *a,
            })
            .collect(),
        alpha_initial: initial,
        hidden_effects: built
            .iter()
            .zip(&options.effects)
            .zip(&values)
            .map(|((e, requested), v)| HiddenEffect {
                requested: requested.clone(),
                resolved: e.to_spec(),
                parameters: e
                    .parameters()
                    .iter()
                    .zip(v)
                    .map(|(p, x)| (p.name.clone(), *x))
                    .collect(),
            })
            .collect(),
        noise: Noise {
            distribution: "gaussian".into(),
            sigma_c: options.noise_c,
            rounding_c: ROUNDING_C,
            seed: noise_seed,
        },
        grid: GridInfo {
            measurement_cell_m: fine_cell,
            measurement_cells: cells(hall.room.size_m, fine_cell),
            model_cell_m: model_cell,
        },
        snapshots: truth_snapshots,
        reference,
    };
    let snapshots = states
        .iter()
        .zip(noisy)
        .map(|(s, row)| HallSnapshot {
            state: s.clone(),
            sensor_c: row.into_iter().map(Some).collect(),
        })
        .collect();
    Ok(Measured { snapshots, truth })
}
