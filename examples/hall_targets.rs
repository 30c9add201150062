//! Issue 4's targets on the paper-sized synthetic halls: calibrate per-type alpha on
//! `hall-a` and `hall-b` (seed 1, 3 snapshots, noise 0.2 C, no hidden effect) for 10
//! iterations and compare with the model at the true alphas and with the true alphas.
//!
//! ```sh
//! cargo run --release --example hall_targets [-- --out out/hall_targets.json --presets hall-a,hall-b --no-polish --seed 1 --noise-c 0.2]
//! ```
//!
//! `--no-polish` stops after the ten loop iterations, so the report's uncertainty (which
//! types it calls identified) is the loop's own. `--noise-c 0` measures the same halls
//! without noise: what is left of an alpha's error then is the model's own bias (its
//! 0.2 m grid against the measurements' 0.15 m, and the truth's 3% per-server jitter of
//! alpha, which costs almost nothing). `--measurement-cell-m M` simulates the
//! measurements on a grid of `M` metres instead of the preset's finer one (0.15 m); at
//! the model's own 0.2 m the grid's error drops out and only the jitter is left.
//! `--grid-check F,F` replaces the calibration's grid check (default `0.75,0.5`; an
//! empty list, `--grid-check ,`, turns it off, and with it the polish's weighting of the
//! sensors by the grid); `--no-grid-weighting` keeps the check but not the weighting.
//!
//! Prints a table and writes JSON. Targets: best MAE <= 0.45 C and within 0.1 C of the
//! model at truth after the ten iterations; per-type alphas within 10% for types a sensor
//! sees, in the calibration's answer (after the polish; the loop's own are shown too).

use std::path::PathBuf;
use std::time::Instant;

use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre::dc::hall::distance;
use kalibre::dc::sim::{intake_error, server_air};
use kalibre::dc::synth::{self, Preset, SynthOptions};
use serde_json::json;

/// A type counts as seen when one of its servers has an intake or exhaust within this
/// distance of a sensor.
const SEEN_WITHIN_M: f64 = 1.5;

fn main() {
    let mut out = PathBuf::from("out/hall_targets.json");
    let mut presets = vec!["hall-a".to_string(), "hall-b".to_string()];
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let no_polish = args.iter().any(|a| a == "--no-polish");
    let no_grid_weighting = args.iter().any(|a| a == "--no-grid-weighting");
    args.retain(|a| a != "--no-polish" && a != "--no-grid-weighting");
    // The calibration seed (the measurements are always synth seed 1).
    let mut seed = 1u64;
    let mut noise_c = SynthOptions::new(Preset::Demo, 1).noise_c;
    let mut measurement_cell_m: Option<f64> = None;
    let mut grid_check: Option<Vec<f64>> = None;
    let mut i = 0;
    while i < args.len() {
        let value = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--out" => out = PathBuf::from(&value),
            "--presets" => presets = value.split(',').map(str::to_owned).collect(),
            "--seed" => {
                seed = value.parse().unwrap_or_else(|_| {
                    eprintln!("--seed needs a whole number, got `{value}`");
                    std::process::exit(2)
                })
            }
            "--noise-c" => {
                noise_c = value
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite() && *v >= 0.0)
                    .unwrap_or_else(|| {
                        eprintln!("--noise-c needs a number >= 0, got `{value}`");
                        std::process::exit(2)
                    })
            }
            "--measurement-cell-m" => {
                measurement_cell_m = Some(
                    value
                        .parse()
                        .ok()
                        .filter(|v: &f64| v.is_finite() && *v > 0.0)
                        .unwrap_or_else(|| {
                            eprintln!("--measurement-cell-m needs a number > 0, got `{value}`");
                            std::process::exit(2)
                        }),
                )
            }
            "--grid-check" => {
                let factors: Option<Vec<f64>> = value
                    .split(',')
                    .filter(|f| !f.is_empty())
                    .map(|f| f.parse().ok().filter(|v: &f64| *v > 0.0 && *v < 1.0))
                    .collect();
                grid_check = Some(factors.unwrap_or_else(|| {
                    eprintln!("--grid-check needs factors in (0, 1), e.g. 0.75,0.5, got `{value}`");
                    std::process::exit(2)
                }))
            }
            other => {
                eprintln!(
                    "unknown argument `{other}` (use --out FILE, --presets a,b, --no-polish, --no-grid-weighting, --seed N, --noise-c C, --measurement-cell-m M, --grid-check F,F)"
                );
                std::process::exit(2);
            }
        }
        i += 2;
    }
    let mut results = Vec::new();
    for name in &presets {
        let preset: Preset = name.parse().unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(2)
        });
        let t = Instant::now();
        let mut options = SynthOptions::new(preset, 1).with_noise_c(noise_c);
        if let Some(cell_m) = measurement_cell_m {
            options = options.with_measurement_cell_m(cell_m);
        }
        let s = synth::generate(&options).expect("synth");
        let synth_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut settings = HallCalibrationSettings::default();
        settings.core.seed = seed;
        if no_polish {
            settings.core.polish_iterations = 0;
        }
        if no_grid_weighting {
            settings.core.numerical_weighting = false;
        }
        if let Some(g) = &grid_check {
            settings.grid_check = g.clone();
        }
        let cal = calibrate_hall(&s.hall, &s.snapshots, &settings, None, Vec::new())
            .expect("calibration");
        let cal_s = t.elapsed().as_secs_f64();
        let r = &cal.report;
        let reference = s.truth.reference.as_ref().expect("reference runs");
        // The issue's target counts the ten four-step iterations only (at most 14 runs per
        // snapshot): the best loop iteration, before the polish stage's model runs.
        let loop_iterations = settings.core.max_iterations;
        let loop_best = r
            .history
            .iter()
            .filter(|h| h.iteration <= loop_iterations && h.mae_c.is_some())
            .min_by(|a, b| {
                a.mae_c
                    .unwrap_or(f64::MAX)
                    .total_cmp(&b.mae_c.unwrap_or(f64::MAX))
            })
            .expect("at least one loop iteration");
        let loop_mae = loop_best.mae_c.unwrap_or(f64::NAN);
        let loop_runs_per_snapshot = loop_best.model_runs / s.snapshots.len();
        let mut types = Vec::new();
        for (ty, truth) in &s.truth.alpha_type_cfm_per_w {
            let seen = s.hall.servers().any(|sv| {
                sv.server.server_type == *ty
                    && s.hall.sensors.iter().any(|sensor| {
                        distance(sv.intake_centre(), sensor.position_m) < SEEN_WITHIN_M
                            || distance(sv.exhaust_centre(), sensor.position_m) < SEEN_WITHIN_M
                    })
            });
            let key = format!("alpha/{ty}");
            let found = loop_best.params.get(&key).unwrap_or(f64::NAN);
            let polished = r.best.params.get(&key).unwrap_or(f64::NAN);
            // What the report itself claims: the linearised uncertainty at its best run.
            let u = r.uncertainty.iter().find(|u| u.name == key);
            types.push(json!({
                "type": ty, "true": truth, "found": found,
                "error_pct": 100.0 * (found - truth) / truth, "seen": seen,
                "polished": polished, "polished_error_pct": 100.0 * (polished - truth) / truth,
                "identified": u.is_some_and(|u| u.identified),
                "rel_std_pct": u.and_then(|u| u.rel_std).map(|r| 100.0 * r),
                "shift_pct": u.and_then(|u| u.rel_shift()).map(|r| 100.0 * r),
                "numerical_pct": u.and_then(|u| u.rel_numerical()).map(|r| 100.0 * r),
            }));
        }
        // Where no sensor measures: every server's intake against the truth's, at the
        // loop's best alphas, at the polished ones, and at the true per-server alphas.
        let intakes = |alpha_per_server: &[f64]| -> serde_json::Value {
            let mut rows = Vec::new();
            for snap in &s.snapshots {
                let sol = cal
                    .model
                    .simulator()
                    .solve(&snap.state, alpha_per_server, &[])
                    .expect("solve");
                rows.extend(server_air(&s.hall, &snap.state, &sol).expect("server air"));
            }
            let truth_of = |label: &str, server: &str| s.truth.server_intake_c(label, server);
            let e = intake_error(&rows, &truth_of).expect("true intakes");
            let (w, t) = &e.worst;
            json!({ "mae_c": e.mae_c, "worst_error_c": w.intake_c - t, "worst_at": format!("{} in {}", w.server, w.snapshot) })
        };
        let layout = cal.model.layout();
        let intakes_loop = intakes(&layout.alpha_per_server(&loop_best.params.values()));
        let intakes_polished = intakes(&layout.alpha_per_server(&r.best.params.values()));
        let intakes_truth = intakes(&s.truth.alpha_per_server());
        println!(
            "  server intakes against the truth (MAE, worst): after 10 iterations {:.3} C ({:+.2} C), \
             after the polish {:.3} C ({:+.2} C), the model at the true alphas {:.3} C ({:+.2} C)",
            intakes_loop["mae_c"].as_f64().unwrap_or(f64::NAN),
            intakes_loop["worst_error_c"].as_f64().unwrap_or(f64::NAN),
            intakes_polished["mae_c"].as_f64().unwrap_or(f64::NAN),
            intakes_polished["worst_error_c"].as_f64().unwrap_or(f64::NAN),
            intakes_truth["mae_c"].as_f64().unwrap_or(f64::NAN),
            intakes_truth["worst_error_c"].as_f64().unwrap_or(f64::NAN),
        );
        let runs_per_snapshot = r.runs.total / s.snapshots.len();
        println!(
            "{name}: initial MAE {:.3} C, after 10 iterations {loop_mae:.3} C ({loop_runs_per_snapshot} \
             runs per snapshot), after the polish {:.3} C (iteration {}), model at truth {:.3} C, \
             noise only {:.3} C, {} runs per snapshot, synth {synth_s:.0} s, calibration {cal_s:.0} s",
            r.initial.mae_c.unwrap_or(f64::NAN),
            r.best.mae_c,
            r.best.iteration,
            reference.model_at_truth_mae_c,
            reference.noise_only_mae_c,
            runs_per_snapshot
        );
        for t in &types {
            let spread = match t["rel_std_pct"].as_f64() {
                Some(r) => format!("+/-{r:.0}%"),
                None => "free".to_string(),
            };
            let spread = match t["shift_pct"].as_f64() {
                Some(d) => format!("{spread}, shift {d:+.0}%"),
                None => spread,
            };
            let spread = match t["numerical_pct"].as_f64() {
                Some(n) => format!("{spread}, grid {n:.1}%"),
                None => spread,
            };
            println!(
                "  {:<16} true {:.4} found {:.4} ({:+.1}%), polished {:.4} ({:+.1}%), report: {} ({spread}){}",
                t["type"].as_str().unwrap_or(""),
                t["true"].as_f64().unwrap_or(f64::NAN),
                t["found"].as_f64().unwrap_or(f64::NAN),
                t["error_pct"].as_f64().unwrap_or(f64::NAN),
                t["polished"].as_f64().unwrap_or(f64::NAN),
                t["polished_error_pct"].as_f64().unwrap_or(f64::NAN),
                if t["identified"].as_bool() == Some(true) {
                    "identified"
                } else {
                    "poorly identified"
                },
                if t["seen"].as_bool() == Some(true) {
                    ""
                } else {
                    "  (no sensor nearby)"
                }
            );
        }
        let pass_mae = loop_mae <= 0.45 && loop_mae <= reference.model_at_truth_mae_c + 0.1;
        let alphas_within = |key: &str| {
            types.iter().all(|t| {
                t["seen"].as_bool() != Some(true)
                    || t[key].as_f64().is_some_and(|e| e.abs() <= 10.0)
            })
        };
        // The calibration's answer (the polished alphas), and the loop's alone.
        let pass_alpha = alphas_within("polished_error_pct");
        let pass_alpha_loop = alphas_within("error_pct");
        // The report's own claims: every type it calls identified within 10% of truth.
        let identified: Vec<&serde_json::Value> = types
            .iter()
            .filter(|t| t["identified"].as_bool() == Some(true))
            .collect();
        let within = |key: &str| {
            identified
                .iter()
                .filter(|t| t[key].as_f64().is_some_and(|e| e.abs() <= 10.0))
                .count()
        };
        let claims_loop = within("error_pct");
        let claims_polished = within("polished_error_pct");
        println!(
            "  target MAE <= 0.45 C and within 0.1 C of model at truth: {}; alphas within 10%: {} \
             (after the loop alone: {}); types the report calls identified: {}, within 10% after \
             the loop {claims_loop}, after the polish {claims_polished}",
            if pass_mae { "met" } else { "NOT met" },
            if pass_alpha { "met" } else { "NOT met" },
            if pass_alpha_loop { "met" } else { "NOT met" },
            identified.len()
        );
        results.push(json!({
            "preset": name, "seed": seed, "noise_c": noise_c,
            "measurement_cell_m": options.measurement_cell(),
            "grid_check": settings.grid_check,
            "initial_mae_c": r.initial.mae_c, "loop_best_mae_c": loop_mae,
            "loop_runs_per_snapshot": loop_runs_per_snapshot, "best_mae_c": r.best.mae_c,
            "best_iteration": r.best.iteration, "model_at_truth_mae_c": reference.model_at_truth_mae_c,
            "noise_only_mae_c": reference.noise_only_mae_c, "model_runs": r.runs.total,
            "runs_per_snapshot": runs_per_snapshot, "synth_s": synth_s, "calibration_s": cal_s,
            "identified_types": identified.len(), "identified_within_10pct_loop": claims_loop,
            "identified_within_10pct_polished": claims_polished,
            "types": types, "target_mae_met": pass_mae, "target_alpha_met": pass_alpha,
            "loop_alpha_within_10pct": pass_alpha_loop,
            "numerical_weighting": settings.core.numerical_weighting,
            "numerical_checks": r.numerical_checks,
            "intakes": { "loop": intakes_loop, "polished": intakes_polished, "true_alphas": intakes_truth },
            "history": r.history.iter().map(|h| json!({"iteration": h.iteration, "mae_c": h.mae_c})).collect::<Vec<_>>(),
        }));
    }
    if let Some(dir) = out.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let text =
        serde_json::to_string_pretty(&json!({ "experiment": "hall_targets", "results": results }))
            .expect("json");
    if let Err(e) = std::fs::write(&out, text) {
        eprintln!("{}: {e}", out.display());
        std::process::exit(1);
    }
    println!("wrote {}", out.display());
}
