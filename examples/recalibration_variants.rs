//! The calibration under least squares and under the Student-t likelihood
//! (`kalibre calibrate --likelihood student-t`) on the OpenFOAM development data and its
//! variants, before and after adding the effect the diagnosis suggests.
//!
//! ```sh
//! cargo run --release --example recalibration_variants [-- --variants 6]
//! ```
//!
//! Options: `--out FILE` (JSON, default `out/recalibration_variants.json`), `--variants N`
//! (default 6), `--data DIR` (default the workspace's `data/openfoam`).
//!
//! Cases per dataset as in `diagnosis_variants` (the stored data; N fresh noise draws;
//! the same draws with 4 sensors removed). Per case:
//! - the hall as given is calibrated as `kalibre calibrate` does by default (least
//!   squares) and under the Student-t likelihood (nu 4), and each type's alpha is compared
//!   with `truth.json`'s;
//! - the least-squares calibration is diagnosed as `kalibre diagnose` does; when its top
//!   significant hypothesis is the hidden effect, its suggested entry is added to the
//!   hall's effects (as a user pastes it) and the hall calibrated again under both
//!   likelihoods: the effect's fitted value and the MAE.
//!
//! Prints markdown tables and writes JSON (no wall times: the same options give the same
//! file at any thread count); per-case progress goes to stderr.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use kalibre::dc::calibration::{calibrate_hall, HallCalibration, HallCalibrationSettings};
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::snapshots::HallSnapshot;
use serde_json::{json, Value};

#[path = "openfoam_cases/mod.rs"]
mod openfoam_cases;
use openfoam_cases::{cases, write_json, CaseData, Dataset, DATASETS};

/// The likelihoods compared: name and `Settings::robust_nu`.
const LIKELIHOODS: [(&str, Option<f64>); 2] = [("least squares", None), ("student-t 4", Some(4.0))];

/// The hidden effect's parameter and its true value, where `truth.json` states one.
fn effect_truth(dataset: &str) -> Option<(&'static str, Option<f64>)> {
    match dataset {
        "of-dev-crac-offset" => Some(("crac_supply_offset/offset_c", Some(-1.0))),
        // 0.055 m3/s of B4's 0.32-0.37 m3/s: about 0.16, varying with the snapshot.
        "of-dev-blanking" => Some(("rack_recirculation/fraction", None)),
        _ => None,
    }
}

fn calibrate(
    hall: &Hall,
    snaps: &[HallSnapshot],
    robust_nu: Option<f64>,
) -> Result<HallCalibration, String> {
    let mut settings = HallCalibrationSettings::default();
    settings.core.robust_nu = robust_nu;
    calibrate_hall(hall, snaps, &settings, None, Vec::new()).map_err(|e| e.to_string())
}

/// Per server type: the calibrated alpha's relative error against the truth.
fn alpha_errors(cal: &HallCalibration, truth: &Value) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    if let Some(types) = truth["alpha_true_cfm_per_w"].as_object() {
        for (t, v) in types {
            let got = cal.report.best.params.get(&format!("alpha/{t}"));
            if let (Some(got), Some(v)) = (got, v.as_f64()) {
                out.insert(t.clone(), got / v - 1.0);
            }
        }
    }
    out
}

/// Running sums of one (dataset, likelihood, stage) row.
#[derive(Default)]
struct Row {
    cases: usize,
    mae: f64,
    alpha_abs_err: f64,
    alpha_within_10: usize,
    alpha_types: usize,
    fitted: Vec<f64>,
}

impl Row {
    fn add(&mut self, cal: &HallCalibration, truth: &Value, effect: Option<&str>) {
        self.cases += 1;
        self.mae += cal.report.best.mae_c;
        for e in alpha_errors(cal, truth).values() {
            self.alpha_abs_err += e.abs();
            self.alpha_types += 1;
            self.alpha_within_10 += usize::from(e.abs() <= 0.1);
        }
        if let Some(v) = effect.and_then(|p| cal.report.best.params.get(p)) {
            self.fitted.push(v);
        }
    }

    fn mean_mae(&self) -> f64 {
        self.mae / self.cases.max(1) as f64
    }

    fn mean_alpha_abs_rel_err(&self) -> f64 {
        self.alpha_abs_err / self.alpha_types.max(1) as f64
    }

    /// Mean, minimum and maximum of the fitted effect values; none without any.
    fn fitted_range(&self) -> Option<(f64, f64, f64)> {
        let f = &self.fitted;
        let min = f.iter().copied().reduce(f64::min)?;
        let max = f.iter().copied().reduce(f64::max)?;
        Some((f.iter().sum::<f64>() / f.len() as f64, min, max))
    }

    fn json(&self) -> Value {
        let range = self.fitted_range();
        json!({
            "cases": self.cases, "mean_mae_c": self.mean_mae(),
            "mean_alpha_abs_rel_err": self.mean_alpha_abs_rel_err(),
            "alpha_within_10_percent": self.alpha_within_10, "alpha_types": self.alpha_types,
            "fitted": self.fitted, "mean_fitted": range.map(|r| r.0),
            "fitted_min": range.map(|r| r.1), "fitted_max": range.map(|r| r.2),
        })
    }
}

struct Options {
    out: PathBuf,
    data: PathBuf,
    variants: usize,
}

fn parse_args() -> Options {
    let mut o = Options {
        out: PathBuf::from("out/recalibration_variants.json"),
        data: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/openfoam")),
        variants: 6,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    for pair in args.chunks(2) {
        let (flag, value) = (pair[0].as_str(), pair.get(1));
        let Some(value) = value else {
            eprintln!("{flag} needs a value (use --out FILE, --data DIR, --variants N)");
            std::process::exit(2)
        };
        match flag {
            "--out" => o.out = PathBuf::from(value),
            "--data" => o.data = PathBuf::from(value),
            "--variants" => {
                o.variants = value.parse().unwrap_or_else(|_| {
                    eprintln!("--variants needs a whole number >= 0, got `{value}`");
                    std::process::exit(2)
                })
            }
            _ => {
                eprintln!("unknown argument `{flag}` (use --out FILE, --data DIR, --variants N)");
                std::process::exit(2)
            }
        }
    }
    o
}

fn run(o: &Options) -> Result<(), String> {
    let started = Instant::now();
    let registry = EffectRegistry::builtin();
    let cases = cases(o.variants);
    let mut records = Vec::new();
    // (dataset, stage, likelihood) -> row; stage 0: the hall as given, 1: with the effect.
    let mut rows: BTreeMap<(usize, usize, usize), Row> = BTreeMap::new();
    let mut named: BTreeMap<usize, usize> = BTreeMap::new();
    for (di, (dataset, expected)) in DATASETS.iter().enumerate() {
        let data = Dataset::load(&o.data.join(dataset))?;
        let effect = effect_truth(dataset).map(|(p, _)| p);
        for &case in &cases {
            let t = Instant::now();
            let CaseData {
                hall,
                snaps,
                noise_seed,
                removal_seed,
                removed,
            } = data.case(di, case)?;
            let what = |e: String| format!("{dataset}, {}: {e}", case.label());
            // The hall calibrated under each likelihood, counted in its stage's rows.
            let mut calibrate_all = |hall: &Hall, stage: usize| -> Result<Vec<_>, String> {
                let mut cals = Vec::new();
                for (li, (_, nu)) in LIKELIHOODS.iter().enumerate() {
                    let cal = calibrate(hall, &snaps, *nu).map_err(what)?;
                    let param = if stage == 1 { effect } else { None };
                    rows.entry((di, stage, li))
                        .or_default()
                        .add(&cal, &data.truth, param);
                    cals.push(cal);
                }
                Ok(cals)
            };
            let plain = calibrate_all(&hall, 0)?;
            let params = plain[0].report.best.params.values();
            let d = diagnose_hall(
                &hall,
                &snaps,
                &params,
                &registry,
                &HallDiagnosisSettings::default(),
            )
            .map_err(|e| what(e.to_string()))?;
            let top = d.diagnosis.significant().next().map(|h| h.name.clone());
            let mut with_effect = Vec::new();
            if top.is_some() && top.as_deref() == *expected {
                *named.entry(di).or_default() += 1;
                let i = d
                    .diagnosis
                    .hypotheses
                    .iter()
                    .position(|h| Some(&h.name) == top.as_ref());
                let mut next = hall.clone();
                next.effects
                    .push(d.suggestions[i.expect("the top is a hypothesis")].clone());
                with_effect = calibrate_all(&next, 1)?;
            }
            let summary = |cal: &HallCalibration| {
                json!({
                    "mae_c": cal.report.best.mae_c, "params": cal.report.best.params,
                    "alpha_rel_err": alpha_errors(cal, &data.truth),
                })
            };
            let mut line = format!("{dataset}, {}:", case.label());
            for (li, (name, _)) in LIKELIHOODS.iter().enumerate() {
                line += &format!(" {name} {:.3} C", plain[li].report.best.mae_c);
                if let Some(c) = with_effect.get(li) {
                    let v = effect
                        .and_then(|p| c.report.best.params.get(p))
                        .unwrap_or(f64::NAN);
                    line += &format!(" -> {:.3} C ({v:.3})", c.report.best.mae_c);
                }
                line += ";";
            }
            eprintln!("{line} {:.1} s", t.elapsed().as_secs_f64());
            records.push(json!({
                "dataset": dataset, "case": case.label(), "noise_seed": noise_seed,
                "removal_seed": removal_seed, "removed_sensors": removed,
                "top_significant": top,
                "predicted_mae_c": d.diagnosis.significant().next().map(|h| h.predicted_mae),
                "plain": LIKELIHOODS.iter().zip(&plain)
                    .map(|((n, _), c)| (n.to_string(), summary(c))).collect::<BTreeMap<_, _>>(),
                "with_effect": LIKELIHOODS.iter().zip(&with_effect)
                    .map(|((n, _), c)| (n.to_string(), summary(c))).collect::<BTreeMap<_, _>>(),
            }));
        }
    }
    println!("| dataset | likelihood | cases | mean MAE C | mean alpha error | alpha within 10% |");
    println!("|---|---|---|---|---|---|");
    for ((di, _, li), r) in rows.iter().filter(|(k, _)| k.1 == 0) {
        println!(
            "| {} | {} | {} | {:.3} | {:.1}% | {} of {} |",
            DATASETS[*di].0,
            LIKELIHOODS[*li].0,
            r.cases,
            r.mean_mae(),
            100.0 * r.mean_alpha_abs_rel_err(),
            r.alpha_within_10,
            r.alpha_types
        );
    }
    println!("\nwith the suggested effect added (cases where the diagnosis named it):\n");
    println!("| dataset | likelihood | cases | mean MAE C | fitted: mean (min to max) | truth |");
    println!("|---|---|---|---|---|---|");
    for ((di, _, li), r) in rows.iter().filter(|(k, _)| k.1 == 1) {
        let truth = effect_truth(DATASETS[*di].0)
            .and_then(|(_, v)| v)
            .map_or("about 0.16".to_string(), |v| format!("{v}"));
        let (mean, min, max) = r.fitted_range().unwrap_or((f64::NAN, f64::NAN, f64::NAN));
        println!(
            "| {} | {} | {} | {:.3} | {mean:.3} ({min:.3} to {max:.3}) | {truth} |",
            DATASETS[*di].0,
            LIKELIHOODS[*li].0,
            r.cases,
            r.mean_mae(),
        );
    }
    let summary: Vec<Value> = rows
        .iter()
        .map(|((di, stage, li), r)| {
            let mut v = r.json();
            v["dataset"] = json!(DATASETS[*di].0);
            v["stage"] = json!(if *stage == 0 {
                "as given"
            } else {
                "with the suggested effect"
            });
            v["likelihood"] = json!(LIKELIHOODS[*li].0);
            v
        })
        .collect();
    let doc = json!({
        "experiment": "recalibration_variants", "variants": o.variants,
        "named_by_diagnosis": named.iter().map(|(d, n)| (DATASETS[*d].0, *n)).collect::<BTreeMap<_, _>>(),
        "summary": summary, "cases": records,
    });
    write_json(&o.out, &doc)?;
    println!(
        "\nwrote {} ({} cases, {:.0} s)",
        o.out.display(),
        records.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn main() {
    let o = parse_args();
    if let Err(e) = run(&o) {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
