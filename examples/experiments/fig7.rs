//! Fig. 7: test MAE of the surrogates against the share of training data.
//!
//! The model runs `samples` times at one operating state (the first snapshot; the paper
//! uses one time instant) with alpha drawn as [`AlphaDraw`] says (by default uniformly
//! between its bounds in cfm/W, the paper's literal reading); the runs are
//! split 8:2 into training and test sets once (seeded). For each seed, a seeded shuffle
//! of the training set gives the first 5, 15, 30 and 50 % to fit on; each surrogate
//! (thermal graph with fixed adjacency, with trainable adjacency, vanilla MLP) is fitted
//! with that seed and scored on the whole test set.

use std::time::Instant;

use kalibre::baselines::{InputLevel, Mlp, MlpSettings};
use kalibre::core::{Model, ParamSpace, Sample, Surrogate, TrainingSet};
use kalibre::dc::calibration::{HallCalibrationSettings, SERVER_INFLUENCE_CUT};
use kalibre::dc::hall::AlphaMode;
use kalibre::dc::snapshots::OperatingState;
use kalibre::dc::surrogate::LocalRecirculationSettings;
use kalibre::dc::surrogate::PenaltySettings;
use kalibre::dc::synth::Preset;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{kalibre_surrogate, setup_with_alpha, Result, Setup, Stats};

mod render;

// Used by the fig7 binary and the tests; table4 and fig8 include this module too.
#[allow(unused_imports)]
pub use render::{markdown, svg};

/// Seed of the parameter draws and of the train/test split (fixed: every surrogate and
/// seed sees the same runs).
pub const DATA_SEED: u64 = 7;
/// Shares of the training set.
pub const FRACTIONS: [f64; 4] = [0.05, 0.15, 0.30, 0.50];
/// The surrogates compared.
pub const SURROGATES: [&str; 4] = [
    "thermal graph, fixed adjacency",
    "thermal graph, trainable adjacency",
    "vanilla MLP",
    "thermal graph, fixed adjacency, unregularised Adam",
];

/// How each run's alphas are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlphaDraw {
    /// Uniform between the bounds in cfm/W (the paper's literal reading). With bounds
    /// [0.01, 3] cfm/W, 97% of draws give a server a rise under 18 K and most under 2 K,
    /// so the sensors hardly move between runs.
    #[default]
    Linear,
    /// Uniform on the log scale between the bounds (the calibration's unit box).
    Log,
    /// Alpha at a temperature rise drawn uniformly in the default rise prior's range
    /// ([`PenaltySettings`]: 5-20 K): the plausible band the calibration searches.
    Rise,
}

impl AlphaDraw {
    /// File stem of this draw's results.
    pub fn stem(self) -> &'static str {
        match self {
            AlphaDraw::Linear => "fig7",
            AlphaDraw::Log => "fig7-logbox",
            AlphaDraw::Rise => "fig7-risebox",
        }
    }
    /// One line for the table's caption.
    pub fn describe(self) -> String {
        match self {
            AlphaDraw::Linear => "alpha uniform in cfm/W between its bounds".into(),
            AlphaDraw::Log => "alpha uniform on the log scale between its bounds".into(),
            AlphaDraw::Rise => {
                let p = PenaltySettings::default();
                format!(
                    "alpha at a server temperature rise uniform in [{}, {}] K",
                    p.lower_c, p.upper_c
                )
            }
        }
    }
}

/// Which alphas are drawn independently.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlphaGrain {
    /// One alpha per server type (the calibration's parameters: 11 on `hall-a`).
    #[default]
    Type,
    /// One alpha per rack, shared by its servers.
    Rack,
    /// One alpha per server: the paper's `alpha = (alpha_1, ..., alpha_m)` over its `m`
    /// servers, "each of its elements sampled randomly and uniformly".
    Server,
}

impl AlphaGrain {
    /// Suffix of this grain's file stem.
    pub fn suffix(self) -> &'static str {
        match self {
            AlphaGrain::Type => "",
            AlphaGrain::Rack => "-per-rack",
            AlphaGrain::Server => "-per-server",
        }
    }
    /// One phrase for the table's caption.
    pub fn describe(self) -> &'static str {
        match self {
            AlphaGrain::Type => "one draw per server type",
            AlphaGrain::Rack => "one draw per rack",
            AlphaGrain::Server => "one draw per server",
        }
    }
}

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fig7Config {
    /// Hall preset.
    #[serde(
        serialize_with = "super::ser_preset",
        deserialize_with = "super::de_preset"
    )]
    pub preset: Preset,
    /// Model runs (the paper: 213).
    pub samples: usize,
    /// Seeds of the subsets and fits.
    pub seeds: usize,
    /// How alpha is drawn.
    #[serde(default)]
    pub draw: AlphaDraw,
    /// Which alphas are drawn independently.
    #[serde(default)]
    pub grain: AlphaGrain,
    /// Both graphs' server-sensor edges `1 / d^4` with the height difference halved
    /// (`docs/experiments.md`, Fig. 7, session 17), instead of the default `1 / d`.
    #[serde(default)]
    pub sharp_adjacency: bool,
    /// Both graphs take the local recirculation term on their cold-aisle sensors
    /// (`LocalRecirculationSettings::default`: the whole hall weighed by 1/d; session 18).
    #[serde(default)]
    pub local_recirculation: bool,
    /// Both graphs' hot-aisle edges from the model's own air flow at the initial alphas
    /// (`HallCalibrationSettings::server_influence`; session 20), instead of `1 / d`.
    #[serde(default)]
    pub influence_adjacency: bool,
}

impl Fig7Config {
    /// The experiment: 213 runs of `hall-a`, 3 seeds.
    pub fn full() -> Self {
        Fig7Config {
            preset: Preset::HallA,
            samples: 213,
            seeds: 3,
            draw: AlphaDraw::Linear,
            grain: AlphaGrain::Type,
            sharp_adjacency: false,
            local_recirculation: false,
            influence_adjacency: false,
        }
    }
    /// Seconds-long: 40 runs of `demo`, 1 seed.
    pub fn quick() -> Self {
        Fig7Config {
            preset: Preset::Demo,
            samples: 40,
            seeds: 1,
            draw: AlphaDraw::Linear,
            grain: AlphaGrain::Type,
            sharp_adjacency: false,
            local_recirculation: false,
            influence_adjacency: false,
        }
    }
}

/// Test MAE over all sensors and per aisle (C).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AisleMae {
    /// Over every test run and sensor.
    pub all_c: f64,
    /// Over the cold-aisle sensors; none without any.
    pub cold_c: Option<f64>,
    /// Over the hot-aisle sensors; none without any.
    pub hot_c: Option<f64>,
}

impl AisleMae {
    /// The MAE of `(predicted, measured)` pairs of output vectors; `hot[k]` says whether
    /// output `k` is a hot-aisle sensor.
    pub fn of<'a>(pairs: impl Iterator<Item = (Vec<f64>, &'a [f64])>, hot: &[bool]) -> Self {
        let mut sum = 0.0;
        let mut n = 0usize;
        let mut by_aisle = [(0.0, 0usize); 2];
        for (predicted, measured) in pairs {
            for ((a, b), &h) in predicted.iter().zip(measured).zip(hot) {
                let e = (a - b).abs();
                sum += e;
                n += 1;
                by_aisle[h as usize].0 += e;
                by_aisle[h as usize].1 += 1;
            }
        }
        let mean = |(s, n): (f64, usize)| (n > 0).then(|| s / n as f64);
        AisleMae {
            all_c: sum / n as f64,
            cold_c: mean(by_aisle[0]),
            hot_c: mean(by_aisle[1]),
        }
    }
}

/// One surrogate at one share of the training set.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Point {
    /// Share of the training set.
    pub fraction: f64,
    /// Training samples used.
    pub train_samples: usize,
    /// Test MAE per seed (C).
    pub per_seed_mae_c: Vec<f64>,
    /// Test MAE over seeds (C).
    pub mae_c: Stats,
    /// Test MAE over the cold-aisle sensors, over seeds (C); absent in results written
    /// before session 16.
    #[serde(default)]
    pub cold_mae_c: Option<Stats>,
    /// Test MAE over the hot-aisle sensors, over seeds (C).
    #[serde(default)]
    pub hot_mae_c: Option<Stats>,
    /// Fit wall time over seeds, seconds.
    pub fit_s: Stats,
}

/// One surrogate's curve.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Curve {
    /// Surrogate name.
    pub surrogate: String,
    /// One point per share.
    pub points: Vec<Point>,
}

/// The figure's data.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Fig7Result {
    /// What was run.
    pub config: Fig7Config,
    /// Calibrated parameters (the dimension of the draws).
    pub params: usize,
    /// Runs that failed (dropped).
    pub failed_runs: usize,
    /// Training and test set sizes.
    pub train: usize,
    /// Test set size.
    pub test: usize,
    /// Test MAE of predicting every sensor's training mean (C): the bar a surrogate
    /// must clear to have learned anything.
    pub mean_predictor_mae_c: f64,
    /// The same over the cold-aisle and over the hot-aisle sensors (C); absent in results
    /// written before session 16.
    #[serde(default)]
    pub mean_predictor_by_aisle_c: Option<[Option<f64>; 2]>,
    /// Wall time of the model runs, seconds.
    pub runs_s: f64,
    /// Curves in [`SURROGATES`] order.
    pub curves: Vec<Curve>,
    /// Fixed-adjacency test MAE over the MLP's at the smallest share (target <= 0.5).
    pub fixed_over_mlp_at_5pct: f64,
    /// Whether that target holds.
    pub target_met: bool,
}

fn surrogate_mae(
    name: &str,
    s: &Setup,
    state: &OperatingState,
    train: &[Sample],
    test: &[Sample],
    seed: u64,
    cfg: &Fig7Config,
) -> Result<(AisleMae, f64)> {
    let grain = cfg.grain;
    let mut settings = HallCalibrationSettings::default();
    if cfg.local_recirculation {
        settings.local_recirculation = Some(LocalRecirculationSettings::default());
    }
    if cfg.influence_adjacency {
        settings.server_influence = Some(SERVER_INFLUENCE_CUT);
    }
    if cfg.sharp_adjacency {
        settings.surrogate.adjacency = settings
            .surrogate
            .adjacency
            .with_server_distance_power(4.0)
            .with_server_vertical_scale(0.5);
    }
    let data = TrainingSet {
        scenarios: std::slice::from_ref(state),
        samples: train,
    };
    let t = Instant::now();
    let hot = s.hot_sensors();
    let score = |p: &dyn Fn(&[f64]) -> Vec<f64>| {
        let pairs = test.iter().map(|x| (p(&x.params), x.outputs.as_slice()));
        AisleMae::of(pairs, &hot)
    };
    let mae = match name {
        "vanilla MLP" => {
            let mut m = Mlp::new(
                &s.hall,
                s.model.layout().clone(),
                // Every alpha drawn reaches the MLP: per rack for the rack and type draws
                // (the paper's 518 inputs on its hall A), per server for the server draw.
                MlpSettings::default().with_inputs(if grain == AlphaGrain::Server {
                    InputLevel::Server
                } else {
                    InputLevel::Rack
                }),
            )?;
            m.fit(data, seed)?;
            score(&|p| m.predict(state, p))
        }
        _ => {
            let mut st = settings.clone();
            st.surrogate.trainable_adjacency = name.contains("trainable");
            if name.contains("unregularised") {
                // The training before the ridges were kept in Adam's loss.
                st.surrogate.adam_ridge = false;
                st.surrogate.hall_wide_ridge = st.surrogate.ridge;
            }
            let mut g = kalibre_surrogate(s, &st)?;
            g.fit(data, seed)?;
            score(&|p| g.predict(state, p))
        }
    };
    Ok((mae, t.elapsed().as_secs_f64()))
}

/// The `cfg.samples` parameter points (unit box) of the runs. `rack_of[i]` is the rack of
/// server `i`; with [`AlphaGrain::Rack`] the space must hold one alpha per server, in
/// hall order, and servers of one rack take one draw.
pub fn draw_alphas(
    cfg: &Fig7Config,
    space: &ParamSpace,
    rack_of: &[usize],
    rng: &mut Xoshiro256PlusPlus,
) -> Result<Vec<Vec<f64>>> {
    if cfg.grain == AlphaGrain::Rack && rack_of.len() != space.dim() {
        return Err(format!(
            "a per-rack draw needs one alpha per server: {} servers, {} parameters",
            rack_of.len(),
            space.dim()
        )
        .into());
    }
    let racks = rack_of.iter().max().map_or(0, |r| r + 1);
    let rise = PenaltySettings::default();
    (0..cfg.samples)
        .map(|_| -> Result<Vec<f64>> {
            // Per parameter, its uniform number: its own, or its rack's.
            let u: Vec<f64> = match cfg.grain {
                AlphaGrain::Type | AlphaGrain::Server => {
                    (0..space.dim()).map(|_| rng.random::<f64>()).collect()
                }
                AlphaGrain::Rack => {
                    let per_rack: Vec<f64> = (0..racks).map(|_| rng.random::<f64>()).collect();
                    rack_of.iter().map(|&r| per_rack[r]).collect()
                }
            };
            let x: Vec<f64> = match cfg.draw {
                AlphaDraw::Log => return Ok(u),
                // Uniform in physical units, expressed in the unit box for `from_unit`.
                AlphaDraw::Linear => space
                    .params()
                    .iter()
                    .zip(&u)
                    .map(|(p, u)| p.lower + u * (p.upper - p.lower))
                    .collect(),
                AlphaDraw::Rise => space
                    .params()
                    .iter()
                    .zip(&u)
                    .map(|(p, u)| {
                        let rise_k = rise.lower_c + u * (rise.upper_c - rise.lower_c);
                        (rise.rise_coefficient() / rise_k).clamp(p.lower, p.upper)
                    })
                    .collect(),
            };
            Ok(space.to_unit(&x)?)
        })
        .collect()
}

/// Runs the experiment; `progress` receives a line per finished step.
pub fn run_fig7(cfg: &Fig7Config, progress: &dyn Fn(&str)) -> Result<Fig7Result> {
    // The rack and server draws need one alpha per server in the model and the graph.
    let per_server = (cfg.grain != AlphaGrain::Type).then_some(AlphaMode::PerServer);
    let s = setup_with_alpha(cfg.preset, false, per_server)?;
    let space = s.model.layout().space();
    let state = s.snaps[0].state.clone();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(DATA_SEED);
    let rack_of: Vec<usize> = s.hall.servers().map(|r| r.rack_index).collect();
    let points = draw_alphas(cfg, space, &rack_of, &mut rng)?;
    let t = Instant::now();
    // Runs in parallel, collected in draw order.
    let runs: Vec<Option<Sample>> = points
        .par_iter()
        .map(|u| -> Result<Option<Sample>> {
            let params = space.from_unit(u)?;
            Ok(s.model.evaluate(&state, &params).ok().map(|o| Sample {
                snapshot: 0,
                params,
                outputs: o.values,
                weight: 1.0,
            }))
        })
        .collect::<Result<_>>()?;
    let runs_s = t.elapsed().as_secs_f64();
    let failed_runs = runs.iter().filter(|r| r.is_none()).count();
    let mut samples: Vec<Sample> = runs.into_iter().flatten().collect();
    progress(&format!(
        "{}: {} runs in {runs_s:.0} s ({failed_runs} failed)",
        cfg.preset, cfg.samples
    ));
    samples.shuffle(&mut rng);
    let n_train = (samples.len() * 4).div_ceil(5);
    let test = samples.split_off(n_train);
    let train_all = samples;
    if test.is_empty() || train_all.len() < 4 {
        return Err(format!(
            "{} usable runs are too few to split 8:2",
            train_all.len() + test.len()
        )
        .into());
    }
    let n_out = test[0].outputs.len();
    let mean: Vec<f64> = (0..n_out)
        .map(|k| train_all.iter().map(|x| x.outputs[k]).sum::<f64>() / train_all.len() as f64)
        .collect();
    let mean_predictor = AisleMae::of(
        test.iter().map(|x| (mean.clone(), x.outputs.as_slice())),
        &s.hot_sensors(),
    );
    let mut curves = Vec::new();
    for name in SURROGATES {
        let mut pts = Vec::new();
        for &frac in &FRACTIONS {
            let n = ((frac * train_all.len() as f64).round() as usize).max(2);
            let mut maes = Vec::new();
            let mut fits = Vec::new();
            let (mut colds, mut hots) = (Vec::new(), Vec::new());
            for seed in 1..=cfg.seeds as u64 {
                let mut idx: Vec<usize> = (0..train_all.len()).collect();
                idx.shuffle(&mut Xoshiro256PlusPlus::seed_from_u64(seed));
                let subset: Vec<Sample> = idx[..n].iter().map(|&i| train_all[i].clone()).collect();
                let (mae, fit_s) = surrogate_mae(name, &s, &state, &subset, &test, seed, cfg)?;
                maes.push(mae.all_c);
                colds.extend(mae.cold_c);
                hots.extend(mae.hot_c);
                fits.push(fit_s);
            }
            progress(&format!(
                "{name} at {:.0}% ({n} samples): test MAE {:?} C",
                100.0 * frac,
                maes
            ));
            pts.push(Point {
                fraction: frac,
                train_samples: n,
                mae_c: Stats::of(&maes).expect("a seed"),
                cold_mae_c: Stats::of(&colds),
                hot_mae_c: Stats::of(&hots),
                fit_s: Stats::of(&fits).expect("a seed"),
                per_seed_mae_c: maes,
            });
        }
        curves.push(Curve {
            surrogate: name.into(),
            points: pts,
        });
    }
    let ratio = curves[0].points[0].mae_c.mean / curves[2].points[0].mae_c.mean;
    Ok(Fig7Result {
        config: *cfg,
        params: space.dim(),
        failed_runs,
        train: train_all.len(),
        test: test.len(),
        mean_predictor_mae_c: mean_predictor.all_c,
        mean_predictor_by_aisle_c: Some([mean_predictor.cold_c, mean_predictor.hot_c]),
        runs_s,
        curves,
        fixed_over_mlp_at_5pct: ratio,
        target_met: ratio <= 0.5,
    })
}
