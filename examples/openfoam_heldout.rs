//! Held-out halls for the diagnosis: the OpenFOAM development hall with hidden effects
//! at places, sizes and true alphas that the development data do not have, measured by
//! kalibre's own OpenFOAM adapter, then calibrated and diagnosed as `kalibre calibrate`
//! and `kalibre diagnose` do by default (built-in simulator).
//!
//! ```sh
//! cargo run --release --example openfoam_heldout [-- --np 2]
//! ```
//!
//! Options: `--work DIR` (datasets and calibrations, default `out/openfoam_heldout/`),
//! `--out FILE` (JSON, default `out/openfoam_heldout.json`), `--np N` (OpenFOAM
//! processes per solve, default 1), `--only NAME[,NAME]` (a subset of the cases),
//! `--variants N` (default 0: per dataset also N fresh noise draws from the noise-free
//! readings, and the same draws with 4 seeded random sensors removed, as
//! `diagnosis_variants` does for the development data; no OpenFOAM solve), `--sweep
//! blanking` (instead of the cases: the development hall's blanking slot at each rack),
//! `--refit K` (the diagnosis refits its K leading hypotheses with the built-in model,
//! `HallDiagnosisSettings::refit_top`; default 0, as `kalibre diagnose`), `--ambiguity
//! on|off`, `--model-form on|off` and `--single-output-check on|off` (the diagnosis's
//! ambiguity check, model-form uncertainty and single-output check:
//! `DiagnoseSettings::ambiguity_check`, `HallDiagnosisSettings::model_form` and
//! `DiagnoseSettings::single_output_check`; default: as `kalibre diagnose`),
//! `--sensor-bias-rival T` (`DiagnoseSettings::sensor_bias_rival_bic`: a hypothesis
//! resting on one sensor passes when its BIC is T below a bias of that sensor).
//!
//! The development data (`data/openfoam/of-dev-*`) were tuned against: the diagnosis's
//! settings were chosen on them. These cases were not. Each is written as a dataset in
//! the formats of `docs/formats.md` (`hall.json` without the effect, `snapshots.csv`,
//! `truth.json` with the effect entry, the true alphas and the noise-free readings), so
//! the CLI can be run on it by hand. A dataset already in `--work` is reused: its
//! OpenFOAM solves are not repeated (about 30 s each serially, 12 s at `--np 2`; 3 per
//! clean dataset, 6 per dataset with an effect: with it and without it, for its footprint).
//!
//! Measurements: the development hall's three snapshots (setpoints, fan speeds, powers),
//! OpenFOAM at the case's true alphas with its effect, 1000 SIMPLE iterations as in the
//! development data, plus N(0, 0.15 C) noise (seeded per case). Verdicts as in
//! `diagnosis_variants`: `pass` when the top significant hypothesis is the expected one
//! (for a clean hall: nothing significant), `miss` when nothing is significant but an
//! effect was hidden, `wrong` when another hypothesis is the top significant one. The
//! expected name's rank among all hypotheses is recorded too.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use kalibre::core::Model;
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::openfoam::{OpenFoamModel, OpenFoamSettings};
use kalibre::dc::snapshots::{self, HallSnapshot};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde_json::{json, Value};

#[path = "openfoam_cases/heldout.rs"]
mod heldout;
#[path = "openfoam_cases/mod.rs"]
mod openfoam_cases;
use heldout::{blanking_sweep, cases, HeldOut};
use openfoam_cases::{
    calibrate_as_cli, cases as variant_cases, gauss, write_json, Case, CaseData, Dataset, NOISE_C,
    REMOVED_SENSORS,
};

const TYPES: [&str; 3] = ["web", "db", "gpu"];

/// The seed of a case's noise.
fn noise_seed(index: usize) -> u64 {
    (2 << 40) | index as u64
}

/// Makes (or reuses) the dataset of `case` in `dir` and loads it.
fn dataset(
    case: &HeldOut,
    index: usize,
    dev: &Dataset,
    dir: &Path,
    settings: &OpenFoamSettings,
) -> Result<Dataset, String> {
    if dir.join("truth.json").is_file() {
        return Dataset::load(dir);
    }
    let mut hall: Hall = dev.hall.clone();
    hall.name = case.name.to_string();
    if let Some(containment) = case.containment {
        let mut h = serde_json::to_value(&hall).map_err(|e| e.to_string())?;
        h["containment"] = containment();
        hall = Hall::from_json_str(&h.to_string(), "contained hall.json")
            .map_err(|e| format!("{}: {e}", case.name))?;
    }
    let mut truth_hall = hall.clone();
    if let Some(effect) = &case.effect {
        let entry = serde_json::from_value(effect.clone())
            .map_err(|e| format!("{}: effect entry: {e}", case.name))?;
        truth_hall.effects.push(entry);
    }
    let free_c = openfoam_readings(&truth_hall, case, &dev.snaps, settings)?;
    // The footprint: the same alphas without the effect (three more solves).
    let clean_c = match case.effect {
        Some(_) => openfoam_readings(&hall, case, &dev.snaps, settings)?,
        None => free_c.clone(),
    };
    let seed = noise_seed(index);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut snaps: Vec<HallSnapshot> = Vec::new();
    let mut per_snapshot = serde_json::Map::new();
    let mut diff_sum = vec![0.0; hall.sensors.len()];
    for ((s, free), clean) in dev.snaps.iter().zip(&free_c).zip(&clean_c) {
        let by_id = |values: &[f64]| -> serde_json::Map<String, Value> {
            let pairs = hall.sensors.iter().zip(values);
            pairs
                .map(|(sensor, v)| (sensor.id.clone(), json!(v)))
                .collect()
        };
        per_snapshot.insert(
            s.state.label.clone(),
            json!({ "sensor_c_noise_free": by_id(free), "sensor_c_without_effect": by_id(clean) }),
        );
        for (d, (f, c)) in diff_sum.iter_mut().zip(free.iter().zip(clean)) {
            *d += (f - c) / dev.snaps.len() as f64;
        }
        let sensor_c = free
            .iter()
            .map(|v| Some(v + NOISE_C * gauss(&mut rng)))
            .collect();
        snaps.push(HallSnapshot {
            state: s.state.clone(),
            sensor_c,
        });
    }
    let footprint_mae = free_c
        .iter()
        .flatten()
        .zip(clean_c.iter().flatten())
        .map(|(f, c)| (f - c).abs())
        .sum::<f64>()
        / free_c.iter().map(Vec::len).sum::<usize>() as f64;
    let per_sensor: serde_json::Map<String, Value> = hall
        .sensors
        .iter()
        .zip(&diff_sum)
        .map(|(sensor, d)| (sensor.id.clone(), json!((d * 1000.0).round() / 1000.0)))
        .collect();
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    hall.save(&dir.join("hall.json"))
        .map_err(|e| e.to_string())?;
    let csv = dir.join("snapshots.csv");
    std::fs::write(&csv, snapshots::write_snapshots(&hall, &snaps))
        .map_err(|e| format!("{}: {e}", csv.display()))?;
    let alpha: serde_json::Map<String, Value> = TYPES
        .iter()
        .zip(case.alpha)
        .map(|(t, a)| (t.to_string(), json!(a)))
        .collect();
    let truth = json!({
        "dataset": case.name,
        "made_by": "kalibre examples/openfoam_heldout.rs: kalibre's OpenFOAM adapter at the true alphas with the hidden effect",
        "alpha_true_cfm_per_w": alpha,
        "hidden_effect": case.effect,
        "expected_hypothesis": case.expected,
        "noise": {"distribution": "gaussian", "sigma_c": NOISE_C, "seed": seed},
        "openfoam": {"iterations": settings.iterations, "grid_m": settings.grid_m, "np": settings.np},
        "footprint": {
            "mae_c": footprint_mae,
            "per_sensor_mean_diff_c": per_sensor,
            "reference": "the same OpenFOAM runs without the effect, at the same true alphas",
        },
        "snapshots": per_snapshot,
    });
    // truth.json last: its presence marks a finished dataset.
    write_json(&dir.join("truth.json"), &truth)?;
    Dataset::load(dir)
}

/// OpenFOAM's noise-free readings of `hall` (its effects included) at the case's true
/// alphas, per snapshot of `snaps`.
fn openfoam_readings(
    hall: &Hall,
    case: &HeldOut,
    snaps: &[HallSnapshot],
    settings: &OpenFoamSettings,
) -> Result<Vec<Vec<f64>>, String> {
    let model = OpenFoamModel::new(hall, settings.clone()).map_err(|e| e.to_string())?;
    let space = model.layout().space();
    // Alphas at the case's truth; an effect's parameter at the value its entry gives.
    let params: Vec<f64> = space
        .names()
        .iter()
        .zip(space.initial())
        .map(|(n, init)| match n.strip_prefix("alpha/") {
            Some(t) => TYPES
                .iter()
                .position(|k| *k == t)
                .map(|i| case.alpha[i])
                .ok_or_else(|| format!("{}: unknown alpha parameter `{n}`", case.name)),
            None => Ok(init),
        })
        .collect::<Result<_, _>>()?;
    let what = if hall.effects.is_empty() {
        "without the effect"
    } else {
        "with the effect"
    };
    snaps
        .iter()
        .map(|s| {
            let t = Instant::now();
            let out = model
                .evaluate(&s.state, &params)
                .map_err(|e| format!("{}, snapshot {}: {e}", case.name, s.state.label))?;
            eprintln!(
                "  {} {} {what}: OpenFOAM {:.0} s",
                case.name,
                s.state.label,
                t.elapsed().as_secs_f64()
            );
            Ok(out.values)
        })
        .collect()
}

/// Calibrates and diagnoses one dataset as the CLI does by default; the case's record.
fn evaluate(
    case: &HeldOut,
    hall: &Hall,
    snaps: &[HallSnapshot],
    footprint_mae_c: &Value,
    work: &Path,
    o: &Options,
) -> Result<Value, String> {
    let (cal, cal_settings) = calibrate_as_cli(hall, snaps, work)?;
    let params = cal.report.best.params.values();
    let mut ds = HallDiagnosisSettings {
        sim: cal_settings.sim.clone(),
        refit_top: o.refit_top,
        ..HallDiagnosisSettings::default()
    };
    if let Some(on) = o.ambiguity {
        ds.diagnose.ambiguity_check = on;
    }
    if let Some(on) = o.model_form {
        ds.model_form = on;
    }
    if let Some(on) = o.single_output_check {
        ds.diagnose.single_output_check = on;
    }
    ds.diagnose.sensor_bias_rival_bic = o.sensor_bias_rival_bic;
    let d = diagnose_hall(hall, snaps, &params, &EffectRegistry::builtin(), &ds)
        .map_err(|e| format!("diagnosis: {e}"))?;
    let top = d.diagnosis.significant().next();
    let verdict = match (top, case.expected.as_deref()) {
        (None, None) => "pass",
        (None, Some(_)) => "miss",
        (Some(h), Some(e)) if h.name == e => "pass",
        (Some(_), _) => "wrong",
    };
    let hyps = &d.diagnosis.hypotheses;
    let rank = case
        .expected
        .as_deref()
        .and_then(|e| hyps.iter().position(|h| h.name == e).map(|i| i + 1));
    let expected = case
        .expected
        .as_deref()
        .and_then(|e| hyps.iter().find(|h| h.name == e));
    let summary = |h: &kalibre::core::diagnose::HypothesisResult| {
        json!({
            "name": h.name, "fitted": h.fitted, "explained_fraction": h.explained_fraction,
            "delta_bic": h.delta_bic, "significant": h.significant,
            "carried_by": h.carried_by, "sensor_bias_delta_bic": h.sensor_bias_delta_bic,
        })
    };
    Ok(json!({
        "dataset": case.name,
        "expected": case.expected,
        "verdict": verdict,
        "top_significant": top.map(summary),
        "significant": d.diagnosis.significant().count(),
        "expected_rank": rank,
        "close_alternatives": d.diagnosis.close_alternatives().iter().map(|h| &h.name).collect::<Vec<_>>(),
        "expected_hypothesis": expected.map(summary),
        "first_three": hyps.iter().take(3).map(summary).collect::<Vec<_>>(),
        "footprint_mae_c": footprint_mae_c,
        "diagnosis_mae_c": d.diagnosis.mae,
        "refit_top": ds.refit_top,
        "ambiguity_check": ds.diagnose.ambiguity_check,
        "model_form": ds.model_form,
        "single_output_check": ds.diagnose.single_output_check,
        "sensor_bias_rival_bic": ds.diagnose.sensor_bias_rival_bic,
        "model_form_share": d.diagnosis.model_form_share,
        // The close set the ambiguity check left undecided: its best, then the others.
        "undecided": d.diagnosis.undecided(),
        "refits": d.refits,
        "calibration": {
            "best_mae_c": cal.report.best.mae_c, "model_runs": cal.report.runs.total,
            "params": cal.report.best.params,
        },
    }))
}

struct Options {
    work: PathBuf,
    out: PathBuf,
    np: u32,
    only: Option<Vec<String>>,
    variants: usize,
    sweep: bool,
    refit_top: usize,
    ambiguity: Option<bool>,
    model_form: Option<bool>,
    single_output_check: Option<bool>,
    sensor_bias_rival_bic: Option<f64>,
}

fn on_off(flag: &str, value: &str) -> Result<bool, String> {
    match value {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("{flag} needs `on` or `off`, got `{value}`")),
    }
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        work: PathBuf::from("out/openfoam_heldout"),
        out: PathBuf::from("out/openfoam_heldout.json"),
        np: 1,
        only: None,
        variants: 0,
        sweep: false,
        refit_top: 0,
        ambiguity: None,
        model_form: None,
        single_output_check: None,
        sensor_bias_rival_bic: None,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    for pair in args.chunks(2) {
        let [flag, value] = pair else {
            return Err(format!("{} needs a value", pair[0]));
        };
        match flag.as_str() {
            "--work" => o.work = PathBuf::from(value),
            "--out" => o.out = PathBuf::from(value),
            "--np" => {
                o.np = value
                    .parse()
                    .ok()
                    .filter(|n| *n >= 1)
                    .ok_or_else(|| format!("--np needs a whole number >= 1, got `{value}`"))?
            }
            "--only" => o.only = Some(value.split(',').map(str::to_string).collect()),
            "--sweep" if value == "blanking" => o.sweep = true,
            "--sweep" => return Err(format!("--sweep: only `blanking` is known, got `{value}`")),
            "--variants" => {
                o.variants = value
                    .parse()
                    .map_err(|_| format!("--variants needs a whole number >= 0, got `{value}`"))?
            }
            "--refit" => {
                o.refit_top = value
                    .parse()
                    .map_err(|_| format!("--refit needs a whole number >= 0, got `{value}`"))?
            }
            "--ambiguity" => o.ambiguity = Some(on_off(flag, value)?),
            "--model-form" => o.model_form = Some(on_off(flag, value)?),
            "--single-output-check" => o.single_output_check = Some(on_off(flag, value)?),
            "--sensor-bias-rival" => {
                o.sensor_bias_rival_bic = Some(
                    value
                        .parse()
                        .ok()
                        .filter(|t: &f64| t.is_finite() && *t >= 0.0)
                        .ok_or_else(|| {
                            format!("--sensor-bias-rival needs a BIC margin >= 0, got `{value}`")
                        })?,
                )
            }
            _ => {
                return Err(format!(
                    "unknown argument `{flag}` (use --work DIR, --out FILE, --np N, --only NAMES, --variants N, --sweep blanking, --refit K, --ambiguity on|off, --model-form on|off, --single-output-check on|off, --sensor-bias-rival T)"
                ))
            }
        }
    }
    Ok(o)
}

fn run(o: &Options) -> Result<(), String> {
    let started = Instant::now();
    let data_root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/openfoam"));
    let dev = Dataset::load(&data_root.join("of-dev-clean"))?;
    let of_root = std::fs::canonicalize(&o.work)
        .or_else(|_| {
            std::fs::create_dir_all(&o.work)?;
            std::fs::canonicalize(&o.work)
        })
        .map_err(|e| format!("{}: {e}", o.work.display()))?
        .join("openfoam-cases");
    let settings = OpenFoamSettings::default()
        .with_np(o.np)
        .with_cache_root(of_root)
        .check()
        .map_err(|e| e.to_string())?;
    // The sweep's datasets take other noise seeds than the cases'.
    let (all, first_index) = if o.sweep {
        (blanking_sweep(&dev.hall), 1000)
    } else {
        (cases(), 0)
    };
    if let Some(only) = &o.only {
        if let Some(bad) = only.iter().find(|n| !all.iter().any(|c| c.name == **n)) {
            let names: Vec<&str> = all.iter().map(|c| c.name.as_str()).collect();
            return Err(format!(
                "--only: no case `{bad}` (cases: {})",
                names.join(", ")
            ));
        }
    }
    let mut records = Vec::new();
    for (k, case) in all.iter().enumerate() {
        let i = first_index + k;
        if o.only
            .as_ref()
            .is_some_and(|only| !only.contains(&case.name))
        {
            continue;
        }
        let dir = o.work.join(&case.name);
        let data = dataset(case, i, &dev, &dir, &settings)?;
        for variant in variant_cases(o.variants) {
            let t = Instant::now();
            // Dataset indices from 100: no noise seed of the development variants recurs.
            let CaseData {
                hall,
                snaps,
                noise_seed,
                removed,
                ..
            } = data.case(100 + i, variant)?;
            let work = match variant {
                Case::Original => dir.join("calibration"),
                _ => dir.join(variant.slug()),
            };
            let footprint = &data.truth["footprint"]["mae_c"];
            let mut record = evaluate(case, &hall, &snaps, footprint, &work, o)
                .map_err(|e| format!("{}, {}: {e}", case.name, variant.label()))?;
            eprintln!(
                "{}, {}: {} (top {}, expected rank {}), {:.0} s",
                case.name,
                variant.label(),
                record["verdict"].as_str().unwrap_or(""),
                record["top_significant"]["name"].as_str().unwrap_or("-"),
                record["expected_rank"],
                t.elapsed().as_secs_f64()
            );
            record["case"] = json!(variant.label());
            record["noise_seed"] = json!(noise_seed);
            record["removed_sensors"] = json!(removed);
            records.push(record);
        }
    }
    let originals: Vec<&Value> = records
        .iter()
        .filter(|r| r["case"] == Case::Original.label())
        .collect();
    println!("| dataset | hidden | footprint C | verdict | top significant (fitted) | close alternatives | expected's rank | calibrated MAE C |");
    println!("|---|---|---|---|---|---|---|---|");
    for r in &originals {
        let top = match r["top_significant"]["name"].as_str() {
            Some(n) => format!("{n} ({})", r["top_significant"]["fitted"]),
            None => "nothing".into(),
        };
        println!(
            "| {} | {} | {:.3} | {} | {top} | {} | {} | {:.3} |",
            r["dataset"].as_str().unwrap_or(""),
            r["expected"].as_str().unwrap_or("none"),
            r["footprint_mae_c"].as_f64().unwrap_or(0.0),
            r["verdict"].as_str().unwrap_or(""),
            r["close_alternatives"],
            r["expected_rank"],
            r["calibration"]["best_mae_c"].as_f64().unwrap_or(f64::NAN)
        );
    }
    let count = |rs: &[&Value], v: &str| rs.iter().filter(|r| r["verdict"] == v).count();
    let (pass, miss, wrong) = (
        count(&originals, "pass"),
        count(&originals, "miss"),
        count(&originals, "wrong"),
    );
    println!(
        "\nas stored: pass {pass}, miss {miss}, wrong {wrong} of {}",
        originals.len()
    );
    let mut summary = Vec::new();
    if o.variants > 0 {
        println!("\n| dataset | cases | pass | miss | wrong | wrong names |");
        println!("|---|---|---|---|---|---|");
        for case in &all {
            let rs: Vec<&Value> = records
                .iter()
                .filter(|r| r["dataset"] == case.name)
                .collect();
            if rs.is_empty() {
                continue;
            }
            let mut wrong: BTreeMap<&str, usize> = BTreeMap::new();
            let names = rs.iter().filter(|r| r["verdict"] == "wrong");
            for name in names.filter_map(|r| r["top_significant"]["name"].as_str()) {
                *wrong.entry(name).or_default() += 1;
            }
            let wrong_names: Vec<String> = wrong.iter().map(|(n, c)| format!("{n} x{c}")).collect();
            let (p, m, w) = (count(&rs, "pass"), count(&rs, "miss"), count(&rs, "wrong"));
            println!(
                "| {} | {} | {p} | {m} | {w} | {} |",
                case.name,
                rs.len(),
                wrong_names.join(", ")
            );
            summary.push(json!({
                "dataset": case.name, "cases": rs.len(), "pass": p, "miss": m, "wrong": w,
                "wrong_names": wrong_names,
            }));
        }
    }
    // No wall times in the JSON: the same options give the same file.
    let doc = json!({
        "experiment": "openfoam_heldout", "noise_c": NOISE_C,
        "variants": o.variants, "removed_sensors": REMOVED_SENSORS,
        "as_stored": {"pass": pass, "miss": miss, "wrong": wrong},
        "per_dataset": summary,
        "cases": records,
    });
    write_json(&o.out, &doc)?;
    println!(
        "wrote {} ({:.0} s)",
        o.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn main() {
    let result = parse_args().and_then(|o| run(&o));
    if let Err(e) = result {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
