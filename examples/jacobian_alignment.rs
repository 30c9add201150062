//! How well the thermal graph's slopes match the model's: per server type, the cosine
//! between the surrogate's and the built-in simulator's responses of every sensor to that
//! type's alpha, per aisle, at the true alphas.
//!
//! ```sh
//! cargo run --release --example jacobian_alignment [-- --preset hall-b] [--out FILE.json]
//! ```
//!
//! The loop's steps follow the surrogate's slopes near the best run, so where they point
//! elsewhere than the model's, the loop wastes iterations. The graph is fitted as the loop
//! fits it after a few iterations: on the initial design (lower bounds, upper bounds,
//! midpoint, initial values) and 10 runs around the truth (each alpha times `exp(u)`, `u`
//! uniform in [-0.5, 0.5], seed 7), every snapshot. Slopes are central differences (0.005 in the unit box) of the
//! model and of the fitted surrogate, per snapshot and sensor, at the truth. Compared:
//! the default training, the training before session 6 (no ridge in Adam's loss, the
//! mass-balance terms' weights ridged like the rest), and the default with the local
//! recirculation term (`LocalRecirculationSettings::default`, session 18), and the default
//! with hot-aisle edges from the model's air flow at the initial alphas
//! (`HallCalibrationSettings::server_influence`, session 20).

#[path = "experiments/mod.rs"]
mod experiments;

use kalibre::core::{Model, Sample, Surrogate, TrainingSet};
use kalibre::dc::calibration::{HallCalibrationSettings, SERVER_INFLUENCE_CUT};
use kalibre::dc::surrogate::LocalRecirculationSettings;
use kalibre::dc::synth::Preset;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde_json::json;

const AROUND_TRUTH_RUNS: usize = 10;
const STEP_UNIT: f64 = 0.005;

/// Per parameter, per snapshot, per sensor: the central-difference slope in the unit box.
fn slopes(
    dim: usize,
    truth_unit: &[f64],
    predict: &(dyn Fn(usize, &[f64]) -> Vec<f64> + Sync),
    n_snap: usize,
    to_physical: &(dyn Fn(&[f64]) -> Vec<f64> + Sync),
) -> Vec<Vec<Vec<f64>>> {
    (0..dim)
        .into_par_iter()
        .map(|p| {
            let (mut lo, mut hi) = (truth_unit.to_vec(), truth_unit.to_vec());
            lo[p] -= STEP_UNIT;
            hi[p] += STEP_UNIT;
            let (lo, hi) = (to_physical(&lo), to_physical(&hi));
            (0..n_snap)
                .map(|s| {
                    let (a, b) = (predict(s, &lo), predict(s, &hi));
                    a.iter()
                        .zip(&b)
                        .map(|(a, b)| (b - a) / (2.0 * STEP_UNIT))
                        .collect()
                })
                .collect()
        })
        .collect()
}

fn cosine(a: &[f64], b: &[f64]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    dot / (na * nb).max(1e-300)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = experiments::preset_flag(&args, Preset::HallB);
    let out = experiments::flag_value(&args, "--out").map(std::path::PathBuf::from);
    let usage = "usage: jacobian_alignment [--preset hall-a|hall-b|demo] [--out FILE.json]\n(without --out nothing is written; threads: RAYON_NUM_THREADS)";
    experiments::exit_with_help_if_asked(&args, usage);
    experiments::refuse_unknown_flags(&args, &["--preset", "--out"], usage);
    if let Some(Err(e)) = out.as_deref().map(experiments::prepare_out_file) {
        eprintln!("{e}");
        std::process::exit(2);
    }
    let s = experiments::setup(preset, false).expect("synthetic hall");
    let layout = s.model.layout().clone();
    let space = layout.space();
    let dim = space.dim();
    let names: Vec<String> = space.params().iter().map(|p| p.name.clone()).collect();
    let truth_params: Vec<f64> = names
        .iter()
        .map(|n| s.true_alpha_type[n.trim_start_matches("alpha/")])
        .collect();
    let truth_unit = space.to_unit(&truth_params).expect("truth in bounds");
    let to_physical = |u: &[f64]| space.from_unit(u).expect("unit box");

    // The training runs: the loop's design and runs around the truth.
    let mut points: Vec<Vec<f64>> = vec![
        space.params().iter().map(|p| p.lower).collect(),
        space.params().iter().map(|p| p.upper).collect(),
        to_physical(&vec![0.5; dim]),
        space.initial(),
    ];
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
    for _ in 0..AROUND_TRUTH_RUNS {
        points.push(
            truth_params
                .iter()
                .zip(space.params())
                .map(|(t, p)| {
                    let u: f64 = rng.random();
                    (t * (u - 0.5).exp()).clamp(p.lower, p.upper)
                })
                .collect(),
        );
    }
    let states: Vec<_> = s.snaps.iter().map(|x| x.state.clone()).collect();
    let jobs: Vec<(usize, usize)> = (0..points.len())
        .flat_map(|i| (0..states.len()).map(move |k| (i, k)))
        .collect();
    let samples: Vec<Sample> = jobs
        .par_iter()
        .map(|&(i, k)| Sample {
            snapshot: k,
            params: points[i].clone(),
            outputs: s
                .model
                .evaluate(&states[k], &points[i])
                .expect("a run")
                .values,
            weight: 1.0,
        })
        .collect();
    let model_slopes = slopes(
        dim,
        &truth_unit,
        &|k, p| s.model.evaluate(&states[k], p).expect("a run").values,
        states.len(),
        &to_physical,
    );
    let hot = s.hot_sensors();

    let mut results = Vec::new();
    for variant in [
        "default",
        "before session 6",
        "local recirculation",
        "influence edges",
    ] {
        let mut st = HallCalibrationSettings::default();
        match variant {
            "before session 6" => {
                st.surrogate.adam_ridge = false;
                st.surrogate.hall_wide_ridge = st.surrogate.ridge;
            }
            "local recirculation" => {
                st.local_recirculation = Some(LocalRecirculationSettings::default());
            }
            "influence edges" => st.server_influence = Some(SERVER_INFLUENCE_CUT),
            _ => {}
        }
        let mut g = experiments::kalibre_surrogate(&s, &st).expect("graph");
        g.fit(
            TrainingSet {
                scenarios: &states,
                samples: &samples,
            },
            1,
        )
        .expect("fit");
        let sur = slopes(
            dim,
            &truth_unit,
            &|k, p| g.predict(&states[k], p),
            states.len(),
            &to_physical,
        );
        println!("{} ({variant})", preset.as_str());
        println!(
            "  {:<20} {:>9} {:>9} {:>9} {:>11}",
            "type", "cos cold", "cos hot", "cos all", "|sur|/|mod|"
        );
        let mut rows = Vec::new();
        let mut sums = [0.0; 3];
        for p in 0..dim {
            let pick = |j: &[Vec<f64>], aisle: Option<bool>| -> Vec<f64> {
                j.iter()
                    .flat_map(|snap| {
                        snap.iter()
                            .zip(&hot)
                            .filter(move |(_, h)| aisle.is_none_or(|a| **h == a))
                            .map(|(v, _)| *v)
                    })
                    .collect()
            };
            let (m, g) = (&model_slopes[p], &sur[p]);
            let cos = [None, Some(false), Some(true)].map(|a| cosine(&pick(m, a), &pick(g, a)));
            let norm = |v: Vec<f64>| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let ratio = norm(pick(g, None)) / norm(pick(m, None)).max(1e-300);
            println!(
                "  {:<20} {:>9.2} {:>9.2} {:>9.2} {:>11.2}",
                names[p], cos[1], cos[2], cos[0], ratio
            );
            for (s, c) in sums.iter_mut().zip(cos) {
                *s += c / dim as f64;
            }
            rows.push(
                json!({"param": names[p], "cos_all": cos[0], "cos_cold": cos[1],
                "cos_hot": cos[2], "norm_ratio": ratio}),
            );
        }
        println!(
            "  {:<20} {:>9.2} {:>9.2} {:>9.2}",
            "mean", sums[1], sums[2], sums[0]
        );
        results.push(json!({"training": variant, "mean_cos_all": sums[0],
            "mean_cos_cold": sums[1], "mean_cos_hot": sums[2], "types": rows}));
    }
    if let Some(path) = out {
        let doc = json!({"experiment": "jacobian_alignment", "preset": preset.as_str(),
            "training_runs": points.len(), "step_unit": STEP_UNIT, "results": results});
        std::fs::write(&path, serde_json::to_string_pretty(&doc).expect("json"))
            .unwrap_or_else(|e| eprintln!("{}: {e}", path.display()));
    }
}
