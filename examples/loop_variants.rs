//! Issue 4's loop on the paper-sized synthetic halls, one setting changed at a time: the
//! best MAE within 10 iterations (14 runs per snapshot, no polish stage) over several
//! calibration seeds, per variant and hall. This is how the loop's defaults were chosen.
//!
//! ```sh
//! cargo run --release --example loop_variants [-- --seeds 8 --presets hall-a,hall-b \
//!     --variants default,wide-adjacency,paper-prior,no-geometry-steps --out out/loop_variants.json]
//! ```
//!
//! The measurements are `kalibre synth --preset P --seed 1` (3 snapshots, noise 0.2 C),
//! per-type alpha; calibration seeds 1..=N. Prints, per variant and hall, the MAE line
//! and how many server types' alphas are within 10% of the truth (per seed, and per type
//! the seeds that have it within 10%), and writes JSON.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings, SERVER_INFLUENCE_CUT};
use kalibre::dc::surrogate::{LocalRecirculationSettings, PenaltySettings, LOCAL_RADIUS_M};
use kalibre::dc::synth::{self, Preset, SynthOptions};
use serde_json::json;

/// The variants: a name, what it changes, and the change.
const VARIANTS: &[(&str, &str)] = &[
    (
        "default",
        "HallCalibrationSettings::default() without the polish stage",
    ),
    ("wide-adjacency", "server-sensor cut 0.3 instead of 0.6"),
    (
        "sharp-adjacency",
        "server-sensor weight 1/d^4 with the height difference halved",
    ),
    ("power-4-adjacency", "server-sensor weight 1/d^4"),
    (
        "mild-adjacency",
        "server-sensor weight 1/d^2 with the height difference halved",
    ),
    (
        "vertical-0.5-adjacency",
        "server-sensor distance with the height difference halved",
    ),
    (
        "paper-prior",
        "temperature-rise prior [5, 15] K instead of [5, 20] K",
    ),
    ("no-prior", "no temperature-rise prior"),
    (
        "best-by-mae",
        "the best run judged by its MAE alone, not MAE plus the weighted rise prior (before session 25)",
    ),
    (
        "no-geometry-steps",
        "no geometry step when the search stalls",
    ),
    (
        "trust-region-0.3",
        "initial trust region 0.3 instead of 0.1",
    ),
    (
        "local-recirculation",
        "the local recirculation term added to the surrogate: cold-aisle sensors, the whole hall weighed by 1/d (session 18)",
    ),
    (
        "local-recirculation-3m",
        "the local recirculation term's first form added: every sensor, servers and openings within 3 m",
    ),
    (
        "trainable-adjacency",
        "every server-sensor and CRAC-sensor edge trained with the rest",
    ),
    (
        "zero-order-correction",
        "the output correction's constant term only (no linear term, no geometry steps)",
    ),
    ("focus-0.5", "fit focus 0.5 instead of 1"),
    ("focus-2", "fit focus 2 instead of 1"),
    ("geometry-step-0.01", "geometry step 0.01 instead of 0.03"),
    (
        "augment-sigma-0.1",
        "design augmentation noise 0.1 instead of 0.05",
    ),
    (
        "prior-design",
        "initial design within the rise prior's alphas instead of the whole bounds",
    ),
    (
        "no-adam-ridge",
        "Adam without the least-squares start's ridges in its loss",
    ),
    (
        "hall-wide-ridge-0.01",
        "ridge on the mass-balance terms' weights 0.01 instead of 0.03",
    ),
    (
        "hall-wide-ridge-0.1",
        "ridge on the mass-balance terms' weights 0.1 instead of 0.03",
    ),
    (
        "influence-adjacency",
        "hot-aisle server-sensor edges from the model's air flow at the initial alphas, cut at 1 % (session 20)",
    ),
    (
        "influence-local",
        "influence-adjacency and local-recirculation together",
    ),
    (
        "hall-wide-ridge-0.3",
        "ridge on the mass-balance terms' weights 0.3 instead of 0.03",
    ),
    (
        "unregularised-surrogate",
        "the surrogate's training before session 6: no ridge in Adam, the mass-balance terms' weights ridged like the rest (0.001)",
    ),
];

fn variant(name: &str) -> Option<HallCalibrationSettings> {
    let mut s = HallCalibrationSettings::default();
    s.core.polish_iterations = 0;
    match name {
        "default" => {}
        "wide-adjacency" => s.surrogate.adjacency.server_threshold = 0.3,
        "sharp-adjacency" => {
            s.surrogate.adjacency.server_distance_power = 4.0;
            s.surrogate.adjacency.server_vertical_scale = 0.5;
        }
        "power-4-adjacency" => s.surrogate.adjacency.server_distance_power = 4.0,
        "mild-adjacency" => {
            s.surrogate.adjacency.server_distance_power = 2.0;
            s.surrogate.adjacency.server_vertical_scale = 0.5;
        }
        "vertical-0.5-adjacency" => s.surrogate.adjacency.server_vertical_scale = 0.5,
        "paper-prior" => s.penalty = PenaltySettings::paper(),
        "no-prior" => s.penalty.weight = 0.0,
        "best-by-mae" => s.core.prior_in_best = false,
        "no-geometry-steps" => s.core.stall_step = None,
        "trust-region-0.3" => s.core.trust_region = Some(0.3),
        "local-recirculation" => {
            s.local_recirculation = Some(LocalRecirculationSettings::default())
        }
        "local-recirculation-3m" => {
            s.local_recirculation = Some(LocalRecirculationSettings::within(LOCAL_RADIUS_M))
        }
        "influence-adjacency" => s.server_influence = Some(SERVER_INFLUENCE_CUT),
        "influence-local" => {
            s.server_influence = Some(SERVER_INFLUENCE_CUT);
            s.local_recirculation = Some(LocalRecirculationSettings::default());
        }
        "focus-0.5" => s.core.focus = Some(0.5),
        "focus-2" => s.core.focus = Some(2.0),
        "geometry-step-0.01" => s.core.stall_step = Some(0.01),
        "augment-sigma-0.1" => s.core.augment_sigma = 0.1,
        "prior-design" => s.design_within_prior = true,
        "trainable-adjacency" => s.surrogate.trainable_adjacency = true,
        "no-adam-ridge" => s.surrogate.adam_ridge = false,
        "hall-wide-ridge-0.01" => s.surrogate.hall_wide_ridge = 0.01,
        "hall-wide-ridge-0.1" => s.surrogate.hall_wide_ridge = 0.1,
        "hall-wide-ridge-0.3" => s.surrogate.hall_wide_ridge = 0.3,
        "unregularised-surrogate" => {
            s.surrogate.adam_ridge = false;
            s.surrogate.hall_wide_ridge = s.surrogate.ridge;
        }
        "zero-order-correction" => {
            s.core.linear_correction = false;
            s.core.stall_step = None;
        }
        _ => return None,
    }
    Some(s)
}

fn fail(message: String) -> ! {
    eprintln!("loop_variants: {message}");
    std::process::exit(2)
}

fn main() {
    let mut out = PathBuf::from("out/loop_variants.json");
    let mut presets = vec!["hall-a".to_string(), "hall-b".to_string()];
    let mut variants: Vec<String> = VARIANTS.iter().map(|v| v.0.to_string()).collect();
    let mut seeds = 8u64;
    let args: Vec<String> = std::env::args().skip(1).collect();
    for pair in args.chunks(2) {
        let value = pair
            .get(1)
            .unwrap_or_else(|| fail(format!("`{}` needs a value", pair[0])));
        match pair[0].as_str() {
            "--out" => out = PathBuf::from(value),
            "--presets" => presets = value.split(',').map(str::to_owned).collect(),
            "--variants" => variants = value.split(',').map(str::to_owned).collect(),
            "--seeds" => {
                seeds = value
                    .parse()
                    .ok()
                    .filter(|&n| n >= 1)
                    .unwrap_or_else(|| fail(format!("--seeds: expected a count >= 1, got `{value}`")))
            }
            other => fail(format!(
                "unknown argument `{other}` (use --out FILE, --presets a,b, --variants a,b, --seeds N)"
            )),
        }
    }
    let known: Vec<&str> = VARIANTS.iter().map(|v| v.0).collect();
    for v in &variants {
        if variant(v).is_none() {
            fail(format!(
                "unknown variant `{v}` (known: {})",
                known.join(", ")
            ));
        }
    }
    let mut results = Vec::new();
    for name in &presets {
        let preset: Preset = name.parse().unwrap_or_else(|e| fail(format!("{e}")));
        let s = synth::generate(&SynthOptions::new(preset, 1))
            .unwrap_or_else(|e| fail(format!("synth {name}: {e}")));
        let truth = s
            .truth
            .reference
            .as_ref()
            .map_or(f64::NAN, |r| r.model_at_truth_mae_c);
        for v in &variants {
            let base = variant(v).expect("checked above");
            let t = Instant::now();
            let mut per_seed = Vec::new();
            // Per seed: the server types whose alpha is within 10% of the truth.
            let mut alpha_within = Vec::new();
            let mut type_hits: BTreeMap<&str, usize> = s
                .truth
                .alpha_type_cfm_per_w
                .keys()
                .map(|ty| (ty.as_str(), 0))
                .collect();
            for seed in 1..=seeds {
                let mut st = base.clone();
                st.core.seed = seed;
                let cal = calibrate_hall(&s.hall, &s.snapshots, &st, None, Vec::new())
                    .unwrap_or_else(|e| fail(format!("{name}, {v}, seed {seed}: {e}")));
                per_seed.push(cal.report.best.mae_c);
                let mut within = 0;
                for (ty, truth) in &s.truth.alpha_type_cfm_per_w {
                    let found = cal.report.best.params.get(&format!("alpha/{ty}"));
                    if found.is_some_and(|a| ((a - truth) / truth).abs() <= 0.1) {
                        within += 1;
                        *type_hits.entry(ty.as_str()).or_default() += 1;
                    }
                }
                alpha_within.push(within);
            }
            let n_types = type_hits.len();
            let alpha_mean = alpha_within.iter().sum::<usize>() as f64 / alpha_within.len() as f64;
            let mean = per_seed.iter().sum::<f64>() / per_seed.len() as f64;
            let within = per_seed.iter().filter(|&&m| m <= truth + 0.1).count();
            let wall_s = t.elapsed().as_secs_f64();
            println!(
                "{name:<7} {v:<18} mean {mean:.3} C over {seeds} seeds, {within}/{seeds} within \
                 0.1 C of the model at truth ({truth:.3} C)  [{}]  {wall_s:.0} s",
                per_seed
                    .iter()
                    .map(|m| format!("{m:.2}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
            println!(
                "        alpha within 10%: mean {alpha_mean:.1}/{n_types} [{}]; seeds per type: {}",
                alpha_within
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
                type_hits
                    .iter()
                    .map(|(ty, h)| format!("{ty} {h}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            results.push(json!({
                "preset": name, "variant": v, "seeds": seeds, "mean_best_mae_c": mean,
                "best_mae_c": per_seed, "model_at_truth_mae_c": truth,
                "seeds_within_0.1_of_truth": within, "wall_s": wall_s,
                "alpha_types_within_10pct": alpha_within, "mean_alpha_types_within_10pct": alpha_mean,
                "seeds_within_10pct_per_type": type_hits,
            }));
        }
    }
    if let Some(dir) = out.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let text = serde_json::to_string_pretty(&json!({
        "experiment": "loop_variants",
        "variants": VARIANTS.iter().map(|(n, d)| json!({"name": n, "change": d})).collect::<Vec<_>>(),
        "results": results,
    }))
    .expect("json");
    if let Err(e) = std::fs::write(&out, text) {
        fail(format!("{}: {e}", out.display()));
    }
    println!("wrote {}", out.display());
}
