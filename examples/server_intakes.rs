//! What the calibrated model says where no sensor measures: every server's intake air,
//! against OpenFOAM's own (`truth.json`'s `server_intake_c`), on the development datasets.
//!
//! ```sh
//! cargo run --release --example server_intakes   # about 3 min; docs/results/server_intakes.json
//! ```
//!
//! Options: `--out FILE` (JSON, default `docs/results/server_intakes.json`), `--data DIR`
//! (default the workspace's `data/openfoam`), `--synthetic-seeds N` (default 2).
//!
//! Then the same on synthetic `demo` halls (seeds 1..N), clean and with each of the
//! demo's hidden effects, against the synthetic truth's intakes (the built-in simulator
//! on a finer grid, with the effect).
//!
//! Per dataset (the stored data), the built-in model on its default grid predicts each
//! server's intake (`kalibre simulate --servers`) at:
//! - the hall's initial alphas (uncalibrated);
//! - the alphas `kalibre calibrate` finds by default;
//! - where the diagnosis names a significant effect: the hall with its suggested entry,
//!   calibrated again under the Student-t likelihood, as `docs/diagnosis.md` advises;
//! - the true alphas (the model's own floor: what its physics cannot do).
//!
//! Scores over servers and snapshots: MAE, bias (model - OpenFOAM), the largest error and
//! where; per snapshot, the rank correlation of the intakes (does the model know which
//! servers draw the warmest air?) and whether its warmest server is OpenFOAM's.

use std::path::{Path, PathBuf};

use kalibre::core::calibrate::Residual;
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::sim::{coldest_under_read, server_air, SimConfig, RECOMMENDED_MAX_INLET_C};
use kalibre::dc::snapshots::HallSnapshot;
use kalibre::dc::synth::{self, parse_effect_arg, Preset, SynthOptions};
use kalibre::dc::HallModel;
use serde_json::{json, Value};

#[path = "openfoam_cases/mod.rs"]
mod openfoam_cases;
use openfoam_cases::{calibrate_as_cli, write_json, Dataset, DATASETS};

/// The model's intakes at `params`, per snapshot in hall server order, with the sensor MAE.
fn predicted_intakes(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
) -> Result<(Vec<Vec<f64>>, f64), String> {
    predicted_intakes_on(hall, snaps, params, SimConfig::default().cell_m)
}

/// As [`predicted_intakes`], on a grid of `cell_m`.
fn predicted_intakes_on(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
    cell_m: f64,
) -> Result<(Vec<Vec<f64>>, f64), String> {
    let model = HallModel::new(hall, SimConfig::default().with_cell_m(cell_m))
        .map_err(|e| e.to_string())?;
    let (mut intakes, mut err, mut count) = (Vec::new(), 0.0, 0usize);
    for snap in snaps {
        let sol = model
            .solve(&snap.state, params)
            .map_err(|e| e.to_string())?;
        for (p, m) in sol.sensor_c().iter().zip(&snap.sensor_c) {
            if let Some(m) = m {
                err += (p - m).abs();
                count += 1;
            }
        }
        let air = server_air(hall, &snap.state, &sol).map_err(|e| e.to_string())?;
        intakes.push(air.iter().map(|s| s.intake_c).collect());
    }
    Ok((intakes, err / count.max(1) as f64))
}

/// OpenFOAM's intakes per snapshot, hall server order.
fn true_intakes(
    hall: &Hall,
    snaps: &[HallSnapshot],
    truth: &Value,
) -> Result<Vec<Vec<f64>>, String> {
    snaps
        .iter()
        .map(|snap| {
            let label = &snap.state.label;
            hall.servers()
                .map(|s| {
                    truth["snapshots"][label]["server_intake_c"][&s.server.id]
                        .as_f64()
                        .ok_or_else(|| {
                            format!(
                                "truth.json: /snapshots/{label}/server_intake_c/{}: missing",
                                s.server.id
                            )
                        })
                })
                .collect()
        })
        .collect()
}

/// Ranks (0 = lowest), ties broken by order: enough for distinct CFD temperatures.
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    for (rank, &i) in idx.iter().enumerate() {
        r[i] = rank as f64;
    }
    r
}

/// Spearman's rank correlation.
fn spearman(a: &[f64], b: &[f64]) -> f64 {
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let mean = (n - 1.0) / 2.0;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        sab += (x - mean) * (y - mean);
        saa += (x - mean) * (x - mean);
        sbb += (y - mean) * (y - mean);
    }
    sab / (saa * sbb).sqrt()
}

fn argmax(v: &[f64]) -> usize {
    (0..v.len()).fold(0, |best, i| if v[i] > v[best] { i } else { best })
}

/// Scores of predicted against true intakes.
fn score(hall: &Hall, snaps: &[HallSnapshot], pred: &[Vec<f64>], truth: &[Vec<f64>]) -> Value {
    let ids: Vec<&str> = hall.servers().map(|s| s.server.id.as_str()).collect();
    let (mut abs, mut bias, mut n) = (0.0, 0.0, 0usize);
    let mut worst = (0.0_f64, String::new());
    let (mut rho, mut same_warmest) = (0.0, 0usize);
    let mut warmest = Vec::new();
    for (s, (p, t)) in pred.iter().zip(truth).enumerate() {
        for (i, (p, t)) in p.iter().zip(t).enumerate() {
            let e = p - t;
            abs += e.abs();
            bias += e;
            n += 1;
            if e.abs() > worst.0.abs() {
                worst = (e, format!("{} in {}", ids[i], snaps[s].state.label));
            }
        }
        rho += spearman(p, t);
        let (wp, wt) = (argmax(p), argmax(t));
        same_warmest += usize::from(wp == wt);
        warmest.push(json!({
            "snapshot": snaps[s].state.label, "model": ids[wp], "openfoam": ids[wt],
            "openfoam_c": t[wt], "model_there_c": p[wt],
        }));
    }
    json!({
        "mae_c": abs / n as f64, "bias_c": bias / n as f64,
        "worst_c": worst.0, "worst_at": worst.1,
        "rank_correlation": rho / pred.len() as f64,
        "same_warmest_server": same_warmest, "snapshots": pred.len(), "warmest": warmest,
    })
}

/// A model scored: name, hall, parameters, and the calibration's residuals where it is one.
type Stage = (String, Hall, Vec<f64>, Option<Vec<Residual>>);

/// The `kalibre simulate --grid-check` factors used here.
const GRID_CHECK: [f64; 2] = [0.75, 0.5];

/// Per snapshot: the model's setpoint headroom under the recommended 27 C (the limit less
/// its hottest intake); the least of it over the finer grids (`simulate --grid-check
/// 0.75,0.5`); each less its calibration's misfit (`kalibre simulate`'s note); and the
/// truth's.
fn headroom(
    hall: &Hall,
    snaps: &[HallSnapshot],
    params: &[f64],
    pred: &[Vec<f64>],
    truth: &[Vec<f64>],
    residuals: Option<&[Residual]>,
) -> Result<Value, String> {
    let limit = RECOMMENDED_MAX_INLET_C;
    let misfit = residuals.and_then(|r| coldest_under_read(hall, r));
    let max = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let base = SimConfig::default().cell_m;
    let mut finest = pred.iter().map(|p| limit - max(p)).collect::<Vec<f64>>();
    for f in GRID_CHECK {
        let (fine, _) = predicted_intakes_on(hall, snaps, params, base * f)?;
        for (room, p) in finest.iter_mut().zip(&fine) {
            *room = room.min(limit - max(p));
        }
    }
    let rows: Vec<Value> = snaps
        .iter()
        .zip(pred.iter().zip(truth))
        .zip(&finest)
        .map(|((snap, (p, t)), grid)| {
            let model = limit - max(p);
            json!({
                "snapshot": snap.state.label, "model_c": model, "true_c": limit - max(t),
                "grid_c": grid,
                "less_misfit_c": misfit.as_ref().map(|(_, m)| model + m),
                "grid_less_misfit_c": misfit.as_ref().map(|(_, m)| grid + m),
                "misfit_sensor": misfit.as_ref().map(|(s, _)| s),
            })
        })
        .collect();
    Ok(json!(rows))
}

/// The uncalibrated model, the default calibration and, where the diagnosis names a
/// significant effect, the hall with its suggested entry calibrated again under the
/// Student-t likelihood (as `docs/diagnosis.md` advises).
fn calibrated_stages(
    hall: &Hall,
    snaps: &[HallSnapshot],
    work: &Path,
) -> Result<Vec<Stage>, String> {
    let space = HallModel::new(hall, SimConfig::default())
        .map_err(|e| e.to_string())?
        .layout()
        .space()
        .clone();
    let mut stages: Vec<Stage> = vec![("uncalibrated".into(), hall.clone(), space.initial(), None)];
    let (cal, _) = calibrate_as_cli(hall, snaps, &work.join("cal"))?;
    let best = cal.report.best.params.values();
    stages.push((
        "calibrated".into(),
        hall.clone(),
        best.clone(),
        Some(cal.report.residuals.clone()),
    ));
    let d = diagnose_hall(
        hall,
        snaps,
        &best,
        &EffectRegistry::builtin(),
        &HallDiagnosisSettings::default(),
    )
    .map_err(|e| e.to_string())?;
    if let Some(i) = d.diagnosis.hypotheses.iter().position(|h| h.significant) {
        let mut next = hall.clone();
        next.effects.push(d.suggestions[i].clone());
        let mut settings = HallCalibrationSettings::default();
        settings.core.robust_nu = Some(4.0);
        let cal =
            kalibre::dc::calibration::calibrate_hall(&next, snaps, &settings, None, Vec::new())
                .map_err(|e| e.to_string())?;
        let name = format!("with {} (Student-t)", d.diagnosis.hypotheses[i].name);
        stages.push((
            name,
            next,
            cal.report.best.params.values(),
            Some(cal.report.residuals.clone()),
        ));
    }
    Ok(stages)
}

/// Scores every stage of one hall against its true intakes: a row of the intake table
/// each (printed), the headroom rows (kept for the second table), and the JSON rows.
fn score_stages(
    dataset: &str,
    snaps: &[HallSnapshot],
    truth: &[Vec<f64>],
    stages: &[Stage],
    rows: &mut Vec<Value>,
    headroom_lines: &mut Vec<String>,
) -> Result<(), String> {
    for (name, h, params, residuals) in stages {
        let (pred, sensor_mae) = predicted_intakes(h, snaps, params)?;
        let mut s = score(h, snaps, &pred, truth);
        s["headroom"] = headroom(h, snaps, params, &pred, truth, residuals.as_deref())?;
        if let Some(hr) = s["headroom"].as_array() {
            headroom_lines.extend(hr.iter().map(|r| {
                let c = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
                format!(
                    "| {dataset} | {name} | {} | {:.2} | {:.2} | {:.2} | {:.2} ({}) | {:.2} |",
                    r["snapshot"].as_str().unwrap_or(""),
                    c("model_c"),
                    c("grid_c"),
                    c("less_misfit_c"),
                    c("grid_less_misfit_c"),
                    r["misfit_sensor"].as_str().unwrap_or("-"),
                    c("true_c"),
                )
            }));
        }
        println!(
            "| {dataset} | {name} | {sensor_mae:.3} | {:.3} | {:+.3} | {:+.2} ({}) | {:.2} | {} of {} |",
            s["mae_c"].as_f64().unwrap_or(f64::NAN),
            s["bias_c"].as_f64().unwrap_or(f64::NAN),
            s["worst_c"].as_f64().unwrap_or(f64::NAN),
            s["worst_at"].as_str().unwrap_or(""),
            s["rank_correlation"].as_f64().unwrap_or(f64::NAN),
            s["same_warmest_server"],
            s["snapshots"],
        );
        s["dataset"] = json!(dataset);
        s["model"] = json!(name);
        s["sensor_mae_c"] = json!(sensor_mae);
        s["params"] = json!(params);
        rows.push(s);
    }
    Ok(())
}

/// The demo's hidden effects (as `kalibre demo --effect` places them), and none.
const SYNTHETIC_EFFECTS: [&str; 5] = [
    "none",
    "rack_recirculation:rack=A05,fraction=0.3",
    "bypass:behind_rack=A03,fraction=0.2",
    "containment_leakage:open_fraction=0.3",
    "crac_supply_offset:offset_c=-1.5",
];

fn run(out: &Path, data_dir: &Path, synthetic_seeds: u64) -> Result<(), String> {
    let mut rows = Vec::new();
    let mut headroom_lines = Vec::new();
    println!("| dataset | model | sensor MAE C | intake MAE C | bias C | worst C (where) | rank correlation | same warmest server |");
    println!("|---|---|---|---|---|---|---|---|");
    for (dataset, _) in DATASETS {
        let data = Dataset::load(&data_dir.join(dataset))?;
        let (hall, snaps) = (&data.hall, &data.snaps);
        let truth = true_intakes(hall, snaps, &data.truth)?;
        let work = std::env::temp_dir().join(format!("kalibre-server-intakes-{dataset}"));
        let mut stages = calibrated_stages(hall, snaps, &work)?;
        let mut at_truth = stages[0].2.clone();
        let space = HallModel::new(hall, SimConfig::default())
            .map_err(|e| e.to_string())?
            .layout()
            .space()
            .clone();
        for (i, name) in space.names().iter().enumerate() {
            if let Some(v) = name
                .strip_prefix("alpha/")
                .and_then(|t| data.truth["alpha_true_cfm_per_w"][t].as_f64())
            {
                at_truth[i] = v;
            }
        }
        stages.push(("true alphas".into(), hall.clone(), at_truth, None));
        score_stages(
            dataset,
            snaps,
            &truth,
            &stages,
            &mut rows,
            &mut headroom_lines,
        )?;
    }
    // Synthetic `demo` halls: the truth is the built-in simulator itself on a finer grid,
    // with one of the demo's hidden effects.
    for seed in 1..=synthetic_seeds {
        for effect in SYNTHETIC_EFFECTS {
            let mut options = SynthOptions::new(Preset::Demo, seed).with_noise_c(0.15);
            if effect != "none" {
                options = options.with_effect(parse_effect_arg(effect).map_err(|e| e.to_string())?);
            }
            let s = synth::generate(&options).map_err(|e| e.to_string())?;
            let truth: Vec<Vec<f64>> = s
                .snapshots
                .iter()
                .map(|snap| {
                    s.hall
                        .servers()
                        .map(|sv| {
                            s.truth
                                .server_intake_c(&snap.state.label, &sv.server.id)
                                .ok_or("a synthetic truth without server intakes")
                        })
                        .collect::<Result<Vec<f64>, _>>()
                })
                .collect::<Result<_, _>>()?;
            let label = format!("demo-{seed} {}", effect.split(':').next().unwrap_or(effect));
            let work = std::env::temp_dir().join(format!(
                "kalibre-server-intakes-demo-{seed}-{}",
                effect.split(':').next().unwrap_or(effect)
            ));
            let stages = calibrated_stages(&s.hall, &s.snapshots, &work)?;
            score_stages(
                &label,
                &s.snapshots,
                &truth,
                &stages,
                &mut rows,
                &mut headroom_lines,
            )?;
        }
    }
    println!("\nSetpoint headroom (27 C less the hottest intake), the model's less its misfit, and the truth's:\n");
    println!(
        "| dataset | model | snapshot | model's headroom C | least over the finer grids C | less the misfit C | both C (misfit sensor) | true C |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for l in &headroom_lines {
        println!("{l}");
    }
    write_json(
        out,
        &json!({ "experiment": "server_intakes", "rows": rows }),
    )?;
    println!("\nwrote {}", out.display());
    Ok(())
}

fn main() {
    let mut out = PathBuf::from("docs/results/server_intakes.json");
    let mut data = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/openfoam"));
    let mut synthetic_seeds = 2;
    let args: Vec<String> = std::env::args().skip(1).collect();
    for pair in args.chunks(2) {
        match (pair[0].as_str(), pair.get(1)) {
            ("--out", Some(v)) => out = PathBuf::from(v),
            ("--data", Some(v)) => data = PathBuf::from(v),
            ("--synthetic-seeds", Some(v)) => {
                synthetic_seeds = v.parse().unwrap_or_else(|_| {
                    eprintln!("--synthetic-seeds needs a whole number, got `{v}`");
                    std::process::exit(2)
                })
            }
            (flag, _) => {
                eprintln!(
                    "unknown argument or missing value `{flag}` (use --out FILE, --data DIR, --synthetic-seeds N)"
                );
                std::process::exit(2)
            }
        }
    }
    if let Err(e) = run(&out, &data, synthetic_seeds) {
        eprintln!("server_intakes: {e}");
        std::process::exit(1);
    }
}
