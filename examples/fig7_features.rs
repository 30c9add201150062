//! Where Fig. 7's surrogate error comes from: per-aisle test MAE of simple per-sensor
//! least-squares fits on candidate features, and of the thermal graph itself, on runs of
//! `hall-a`'s first snapshot.
//!
//! ```sh
//! cargo run --release --example fig7_features [-- --log-box] [--out docs/results/fig7_features.json]
//! ```
//!
//! 130 runs, alpha per server type drawn as Fig. 7's `--rise-box` draws it (server rise
//! uniform in 5-20 K; `--log-box`: alpha log-uniform in its bounds), seed 7; the first 9 or
//! 100 train, the last 30 test. Per-sensor least squares (ridge 1e-3 per sample on
//! standardised features, as the graph's start) on:
//! - the 11 per-type rises (how much a per-sensor linear model of the rises explains);
//! - the paper's heating block `sum_j Wss_jk P_j / alpha_j`, or the mixing law
//!   `sum_j Wss_jk P_j / sum_j Wss_jk P_j alpha_j`, each alone and with the recirculation
//!   and bypass features, with the features' scale floored at 0.1 K (the graph's
//!   `min_scale`) or not.
//!
//! Cold-aisle sensors always take the mass-balance features only (one operating state:
//! the cooling block is constant). Then the thermal graph as Kalibre fits it, without its
//! mass-balance terms, with the local recirculation term, and with the training before
//! session 6 (no ridge in Adam's loss, the mass-balance terms ridged like the rest).

#[path = "experiments/mod.rs"]
mod experiments;

use kalibre::core::{Model, Sample, Surrogate, TrainingSet};
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::surrogate::{
    Adjacency, AdjacencySettings, FlowBalance, FlowBalanceTerm, LocalRecirculationSettings,
    LocalRecirculationTerm, PenaltySettings, SurrogateTerm, LOCAL_RADIUS_M,
};
use kalibre::dc::synth::Preset;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde_json::json;

const RUNS: usize = 130;
const TRAIN_SIZES: [usize; 2] = [9, 100];
const TEST_FROM: usize = 100;

/// Per sample and sensor: paper block, mixing block, recirculation, bypass.
type Features = Vec<Vec<[f64; 4]>>;

/// Ridge least squares of `y` on standardised `cols` (plus an intercept) over the first
/// `n` samples; test MAE over samples `TEST_FROM..`. `floor` per column.
fn fit_and_score(cols: &[Vec<f64>], floors: &[f64], y: &[f64], n: usize) -> (f64, usize) {
    let d = cols.len();
    let mean: Vec<f64> = cols
        .iter()
        .map(|c| c[..n].iter().sum::<f64>() / n as f64)
        .collect();
    let scale: Vec<f64> = cols
        .iter()
        .zip(&mean)
        .zip(floors)
        .map(|((c, m), f)| {
            let var = c[..n].iter().map(|v| (v - m) * (v - m)).sum::<f64>() / n as f64;
            var.sqrt().max(*f).max(1e-12)
        })
        .collect();
    let z = |i: usize, j: usize| (cols[j][i] - mean[j]) / scale[j];
    let ybar = y[..n].iter().sum::<f64>() / n as f64;
    let mut a = vec![vec![0.0; d]; d];
    let mut b = vec![0.0; d];
    for (i, yi) in y.iter().enumerate().take(n) {
        let zi: Vec<f64> = (0..d).map(|j| z(i, j)).collect();
        for (p, row) in a.iter_mut().enumerate() {
            for (q, v) in row.iter_mut().enumerate() {
                *v += zi[p] * zi[q];
            }
            b[p] += zi[p] * (yi - ybar);
        }
    }
    for (p, row) in a.iter_mut().enumerate() {
        row[p] += 1e-3 * n as f64;
    }
    let w = experiments::solve_spd(a, b);
    let err: f64 = (TEST_FROM..y.len())
        .map(|i| (ybar + (0..d).map(|p| w[p] * z(i, p)).sum::<f64>() - y[i]).abs())
        .sum();
    (err, y.len() - TEST_FROM)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let log_box = args.iter().any(|a| a == "--log-box");
    let out = args
        .iter()
        .position(|a| a == "--out")
        .and_then(|i| args.get(i + 1))
        .map(std::path::PathBuf::from);
    let usage = "usage: fig7_features [--log-box] [--out FILE.json]\n(without --out nothing is written; threads: RAYON_NUM_THREADS)";
    experiments::exit_with_help_if_asked(&args, usage);
    experiments::refuse_unknown_flags(&args, &["--log-box", "--out"], usage);
    if let Some(Err(e)) = out.as_deref().map(experiments::prepare_out_file) {
        eprintln!("{e}");
        std::process::exit(2);
    }
    let s = experiments::setup(Preset::HallA, false).expect("hall-a");
    let layout = s.model.layout().clone();
    let dim = layout.space().dim();
    let state = s.snaps[0].state.clone();
    let rise = PenaltySettings::default();
    let (lo, hi) = (
        layout.space().params()[0].lower,
        layout.space().params()[0].upper,
    );
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
    let alphas: Vec<Vec<f64>> = (0..RUNS)
        .map(|_| {
            (0..dim)
                .map(|_| {
                    let u: f64 = rng.random();
                    if log_box {
                        lo * (hi / lo).powf(u)
                    } else {
                        rise.rise_coefficient() / (rise.lower_c + u * (rise.upper_c - rise.lower_c))
                    }
                })
                .collect()
        })
        .collect();
    let outputs: Vec<Vec<f64>> = alphas
        .par_iter()
        .map(|a| s.model.evaluate(&state, a).expect("a run").values)
        .collect();
    let n_out = s.hall.sensors.len();
    let hot = s.hot_sensors();
    let adj = Adjacency::from_hall(&s.hall, &AdjacencySettings::default()).expect("adjacency");
    let terms = [FlowBalance::Recirculation, FlowBalance::Bypass]
        .map(|k| FlowBalanceTerm::new(&s.hall, &layout, k));
    let features: Features = alphas
        .iter()
        .map(|a| {
            let alpha = layout.alpha_per_server(a);
            let mut t = [vec![0.0; n_out], vec![0.0; n_out]];
            for (term, out) in terms.iter().zip(t.iter_mut()) {
                term.features(&state, a, out);
            }
            (0..n_out)
                .map(|k| {
                    let (mut paper, mut num, mut den) = (0.0, 0.0, 0.0);
                    for e in adj.ss.range(k) {
                        let j = adj.ss.col[e] as usize;
                        let wp = adj.ss.val[e] * state.power_w[j];
                        paper += wp / alpha[j];
                        num += wp;
                        den += wp * alpha[j];
                    }
                    let mix = if den > 0.0 { num / den } else { 0.0 };
                    [paper, mix, t[0][k], t[1][k]]
                })
                .collect()
        })
        .collect();
    let rises: Vec<Vec<f64>> = alphas
        .iter()
        .map(|a| a.iter().map(|x| rise.rise_coefficient() / x).collect())
        .collect();
    // (name, hot-aisle feature columns; None: the per-type rises, floored terms)
    let fits: [(&str, Option<&[usize]>, bool); 8] = [
        ("training mean", Some(&[]), true),
        ("least squares on the 11 per-type rises", None, true),
        ("paper heating block alone", Some(&[0]), true),
        ("mixing-law heating block alone", Some(&[1]), true),
        ("paper block + mass-balance terms", Some(&[0, 2, 3]), true),
        ("mixing block + mass-balance terms", Some(&[1, 2, 3]), true),
        (
            "paper block + mass-balance terms, scale not floored",
            Some(&[0, 2, 3]),
            false,
        ),
        (
            "mixing block + mass-balance terms, scale not floored",
            Some(&[1, 2, 3]),
            false,
        ),
    ];
    let mut rows = Vec::new();
    let mut print = |name: &str, n: usize, cold: f64, hot_mae: f64| {
        println!("{name:<58} n={n:<3} cold {cold:>10.3} C  hot {hot_mae:>10.3} C");
        rows.push(
            json!({"model": name, "train_runs": n, "cold_mae_c": cold, "hot_mae_c": hot_mae}),
        );
    };
    for &n in &TRAIN_SIZES {
        for (name, hot_cols, floored) in fits {
            let (mut err, mut cnt) = ([0.0; 2], [0usize; 2]);
            for k in 0..n_out {
                let y: Vec<f64> = outputs.iter().map(|o| o[k]).collect();
                let (cols, floors): (Vec<Vec<f64>>, Vec<f64>) = match (hot_cols, name) {
                    (_, "training mean") => (Vec::new(), Vec::new()),
                    (None, _) => (
                        (0..dim)
                            .map(|p| rises.iter().map(|r| r[p]).collect())
                            .collect(),
                        vec![0.0; dim],
                    ),
                    (Some(c), _) => {
                        let chosen: Vec<usize> = if hot[k] { c.to_vec() } else { vec![2, 3] };
                        let floor = |f: usize| if floored && f >= 2 { 0.1 } else { 0.0 };
                        chosen
                            .iter()
                            .map(|&f| (features.iter().map(|x| x[k][f]).collect(), floor(f)))
                            .unzip()
                    }
                };
                let (e, c) = fit_and_score(&cols, &floors, &y, n);
                err[hot[k] as usize] += e;
                cnt[hot[k] as usize] += c;
            }
            print(name, n, err[0] / cnt[0] as f64, err[1] / cnt[1] as f64);
        }
        // The thermal graph as Kalibre fits it, and three variants.
        for variant in [
            "thermal graph",
            "thermal graph without mass-balance terms",
            "thermal graph + local recirculation term",
            "thermal graph, unregularised Adam",
        ] {
            let mut st = HallCalibrationSettings {
                flow_balance_terms: !variant.contains("without"),
                ..Default::default()
            };
            if variant.contains("unregularised") {
                // The training before session 6: no ridge in Adam's loss, the mass-balance
                // terms' weights ridged like the rest.
                st.surrogate.adam_ridge = false;
                st.surrogate.hall_wide_ridge = st.surrogate.ridge;
            }
            let mut g = experiments::kalibre_surrogate(&s, &st).expect("graph");
            if variant.contains("local") {
                // The term's first form (3 m, every sensor), as these results were made.
                g = g.with_term(Box::new(
                    LocalRecirculationTerm::with_settings(
                        &s.hall,
                        &layout,
                        LocalRecirculationSettings::within(LOCAL_RADIUS_M),
                    )
                    .expect("the 3 m reach"),
                ));
            }
            let train: Vec<Sample> = (0..n)
                .map(|i| Sample {
                    snapshot: 0,
                    params: alphas[i].clone(),
                    outputs: outputs[i].clone(),
                    weight: 1.0,
                })
                .collect();
            let data = TrainingSet {
                scenarios: std::slice::from_ref(&state),
                samples: &train,
            };
            g.fit(data, 1).expect("fit");
            let (mut err, mut cnt) = ([0.0; 2], [0usize; 2]);
            for i in TEST_FROM..RUNS {
                for (k, p) in g.predict(&state, &alphas[i]).iter().enumerate() {
                    err[hot[k] as usize] += (p - outputs[i][k]).abs();
                    cnt[hot[k] as usize] += 1;
                }
            }
            print(variant, n, err[0] / cnt[0] as f64, err[1] / cnt[1] as f64);
        }
    }
    if let Some(path) = out {
        let doc = json!({"experiment": "fig7_features", "draw": if log_box { "log" } else { "rise" }, "runs": RUNS, "rows": rows});
        std::fs::write(&path, serde_json::to_string_pretty(&doc).expect("json"))
            .unwrap_or_else(|e| eprintln!("{}: {e}", path.display()));
    }
}
