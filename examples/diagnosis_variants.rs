//! How well the hall diagnosis (`kalibre diagnose`) names the hidden effect of the
//! OpenFOAM development data (`of-dev-{clean,crac-offset,blanking,bypass}`), and of
//! variants of it, under several diagnosis settings.
//!
//! ```sh
//! cargo run --release --example diagnosis_variants [-- --variants 6]
//! ```
//!
//! Options: `--out FILE` (JSON, default `out/diagnosis_variants.json`), `--work DIR`
//! (calibration outputs, default `out/diagnosis_variants/`), `--variants N` (default 6),
//! `--data DIR` (default the workspace's `data/openfoam`), `--layout2` (the second
//! layout's datasets, `data/openfoam-layout2/ol2-*`, instead), `--quick` (N = 1, settings
//! `gaussian` and `default` only, for a smoke run; it overrides `--variants`).
//!
//! Cases per dataset: `original` (as stored); `noise k` (k = 1..N: every `sensor_c`
//! reading replaced by the noise-free OpenFOAM value of `truth.json` plus N(0, 0.15 C),
//! a fresh seeded draw); `noise k, 4 removed` (the same draw, and 4 seeded random
//! sensors removed from the hall with their readings). Each case is calibrated once as
//! `kalibre calibrate` does by default (built-in simulator, seed 1) and diagnosed at the
//! best parameters once per setting, as `kalibre diagnose` does. Settings: `gaussian`
//! (least squares, no single-output check: the diagnosis before Student-t), `student-t 4,
//! no single-output check`, `default` (`HallDiagnosisSettings::default()`: Student-t
//! nu 4, the single-output check, the ambiguity check and the model form), `student-t
//! 2` and `student-t 8` (with both checks), `refit 3` and `refit 8` (the default with
//! the 3 or 8 leading hypotheses refit with the model,
//! `HallDiagnosisSettings::refit_top`), `no ambiguity check` (the default without
//! `DiagnoseSettings::ambiguity_check`), `no model form` (the default of session 30:
//! without the model-form uncertainty, `HallDiagnosisSettings::model_form`), `no model
//! form, no ambiguity check` (the default before session 30), and `sensor-bias rival 6`
//! and `sensor-bias rival 10` (the default with `DiagnoseSettings::sensor_bias_rival_bic`
//! at 6 or 10). Every setting but those named `no model form` has the model form, and
//! every setting but those named `no ambiguity check` the ambiguity check.
//! `--settings 'NAME;NAME'` runs only the named settings.
//!
//! Verdicts per case and setting: `pass` when the top significant hypothesis is the
//! expected one (for `clean`: nothing significant), `miss` when nothing is significant
//! but an effect was expected, `wrong` when another hypothesis is the top significant one
//! (for `clean`: anything significant). Prints a markdown table (setting x dataset),
//! writes JSON (every case's verdicts, top hypothesis, fitted values, delta BIC and
//! single-output delta BIC, and the summary); per-case progress goes to stderr. The JSON
//! holds no wall times: the same options give the same file at any thread count.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::snapshots::HallSnapshot;
use serde_json::{json, Value};

#[path = "openfoam_cases/mod.rs"]
mod openfoam_cases;
use openfoam_cases::{
    calibrate_as_cli, cases, write_json, CaseData, Dataset, DATASETS, LAYOUT2_DATASETS, NOISE_C,
    REMOVED_SENSORS,
};

/// A diagnosis setting: `(robust_nu, single_output_check)` over the library's
/// `DiagnoseSettings::default()`, or none to keep the defaults as they are, and how many
/// leading hypotheses are refit with the model (`HallDiagnosisSettings::refit_top`).
struct Setting {
    name: &'static str,
    overrides: Option<(Option<f64>, bool)>,
    refit_top: usize,
    quick: bool,
}

const fn setting(
    name: &'static str,
    overrides: Option<(Option<f64>, bool)>,
    refit_top: usize,
    quick: bool,
) -> Setting {
    Setting {
        name,
        overrides,
        refit_top,
        quick,
    }
}

const SETTINGS: [Setting; 12] = [
    setting("gaussian", Some((None, false)), 0, true),
    setting(
        "student-t 4, no single-output check",
        Some((Some(4.0), false)),
        0,
        false,
    ),
    setting("default", None, 0, true),
    setting("student-t 2", Some((Some(2.0), true)), 0, false),
    setting("student-t 8", Some((Some(8.0), true)), 0, false),
    setting("refit 3", None, 3, false),
    setting("refit 8", None, 8, false),
    setting("no ambiguity check", None, 0, false),
    setting("no model form", None, 0, false),
    setting("no model form, no ambiguity check", None, 0, false),
    setting("sensor-bias rival 6", None, 0, false),
    setting("sensor-bias rival 10", None, 0, false),
];

/// Calibrates one case as `kalibre calibrate` does by default, journal and report in
/// `dir`, and diagnoses it under each setting; returns the case's JSON record.
fn run_case(
    hall: &Hall,
    snaps: &[HallSnapshot],
    expected: Option<&str>,
    dir: &Path,
    settings: &[&Setting],
) -> Result<Value, String> {
    let (cal, cal_settings) = calibrate_as_cli(hall, snaps, dir)?;
    let params = cal.report.best.params.values();
    let registry = EffectRegistry::builtin();
    let mut verdicts = Vec::new();
    for s in settings {
        let mut ds = HallDiagnosisSettings {
            sim: cal_settings.sim.clone(),
            ..HallDiagnosisSettings::default()
        };
        if let Some((nu, check)) = s.overrides {
            ds.diagnose.robust_nu = nu;
            ds.diagnose.single_output_check = check;
        }
        ds.refit_top = s.refit_top;
        // Session 29's options: the ambiguity check (on by default since session 30)
        // and the model form (on by default since session 31).
        if s.name.ends_with("no ambiguity check") {
            ds.diagnose.ambiguity_check = false;
        }
        ds.model_form = !s.name.starts_with("no model form");
        // Session 34's option: a one-output hypothesis against a bias of that sensor.
        if let Some(t) = s.name.strip_prefix("sensor-bias rival ") {
            ds.diagnose.sensor_bias_rival_bic = t.parse().ok();
        }
        let d = diagnose_hall(hall, snaps, &params, &registry, &ds)
            .map_err(|e| format!("diagnosis ({}): {e}", s.name))?;
        let top = d.diagnosis.significant().next();
        let verdict = match (top, expected) {
            (None, None) => "pass",
            (None, Some(_)) => "miss",
            (Some(h), Some(e)) if h.name == e => "pass",
            (Some(_), _) => "wrong",
        };
        // `NamedValues` serialises as an object of name -> value.
        let top = top.map(|h| {
            json!({
                "name": h.name, "fitted": h.fitted, "delta_bic": h.delta_bic,
                "single_output_delta_bic": h.single_output_delta_bic,
                "carried_by": h.carried_by,
                "sensor_bias_delta_bic": h.sensor_bias_delta_bic,
            })
        });
        verdicts.push(json!({
            "setting": s.name, "robust_nu": ds.diagnose.robust_nu,
            "ambiguity_check": ds.diagnose.ambiguity_check, "model_form": ds.model_form,
            "single_output_check": ds.diagnose.single_output_check,
            "sensor_bias_rival_bic": ds.diagnose.sensor_bias_rival_bic,
            "refit_top": ds.refit_top,
            "verdict": verdict, "top_significant": top,
            "significant": d.diagnosis.significant().count(),
            // The close set the ambiguity check left undecided: its best, then the others.
            "undecided": d.diagnosis.undecided(),
            "mae_c": d.diagnosis.mae, "noise_sigma_c": d.diagnosis.noise_sigma,
            "model_form_share": d.diagnosis.model_form_share,
        }));
    }
    Ok(json!({
        "calibration": {
            "best_mae_c": cal.report.best.mae_c, "best_iteration": cal.report.best.iteration,
            "model_runs": cal.report.runs.total,
            "params": cal.report.best.params,
        },
        "verdicts": verdicts,
    }))
}

/// Verdict counts of one (setting, dataset), with each wrong name's count.
#[derive(Default)]
struct Tally {
    pass: usize,
    miss: usize,
    wrong: usize,
    wrong_names: BTreeMap<String, usize>,
}

struct Options {
    out: PathBuf,
    work: PathBuf,
    data: PathBuf,
    variants: usize,
    quick: bool,
    settings: Option<Vec<String>>,
    datasets: &'static [(&'static str, Option<&'static str>)],
}

fn parse_args() -> Options {
    let mut o = Options {
        out: PathBuf::from("out/diagnosis_variants.json"),
        work: PathBuf::from("out/diagnosis_variants"),
        data: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/openfoam")),
        variants: 6,
        quick: false,
        settings: None,
        datasets: &DATASETS,
    };
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    o.quick = args.iter().any(|a| a == "--quick");
    let layout2 = args.iter().any(|a| a == "--layout2");
    args.retain(|a| a != "--quick" && a != "--layout2");
    if layout2 {
        o.datasets = &LAYOUT2_DATASETS;
        o.data = PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/openfoam-layout2"
        ));
    }
    let mut i = 0;
    while i < args.len() {
        let flag = args[i].as_str();
        let known = ["--out", "--work", "--data", "--variants", "--settings"].contains(&flag);
        if !known {
            eprintln!("unknown argument `{flag}` (use --out FILE, --work DIR, --data DIR, --layout2, --variants N, --settings 'NAME;NAME', --quick)");
            std::process::exit(2);
        }
        let Some(value) = args.get(i + 1).cloned() else {
            eprintln!("{flag} needs a value");
            std::process::exit(2)
        };
        match flag {
            "--out" => o.out = PathBuf::from(&value),
            "--work" => o.work = PathBuf::from(&value),
            "--data" => o.data = PathBuf::from(&value),
            "--settings" => {
                let names: Vec<String> = value.split(';').map(|n| n.trim().to_string()).collect();
                if let Some(bad) = names.iter().find(|n| SETTINGS.iter().all(|s| s.name != *n)) {
                    let known: Vec<&str> = SETTINGS.iter().map(|s| s.name).collect();
                    eprintln!(
                        "--settings: no setting `{bad}` (settings: {})",
                        known.join("; ")
                    );
                    std::process::exit(2)
                }
                o.settings = Some(names);
            }
            _ => {
                o.variants = value.parse().unwrap_or_else(|_| {
                    eprintln!("--variants needs a whole number >= 0, got `{value}`");
                    std::process::exit(2)
                })
            }
        }
        i += 2;
    }
    if o.quick {
        o.variants = 1;
    }
    o
}

fn run(o: &Options) -> Result<(), String> {
    let started = Instant::now();
    let settings: Vec<&Setting> = SETTINGS
        .iter()
        .filter(|s| match &o.settings {
            Some(names) => names.iter().any(|n| n == s.name),
            None => s.quick || !o.quick,
        })
        .collect();
    let cases = cases(o.variants);
    let total = o.datasets.len() * cases.len();
    let mut records = Vec::new();
    // By (setting, dataset): the table's rows in order.
    let mut summary: BTreeMap<(usize, usize), Tally> = BTreeMap::new();
    for (di, (dataset, expected)) in o.datasets.iter().enumerate() {
        let data = Dataset::load(&o.data.join(dataset))?;
        for &case in &cases {
            let t = Instant::now();
            let CaseData {
                hall: case_hall,
                snaps: case_snaps,
                noise_seed,
                removal_seed,
                removed,
            } = data.case(di, case)?;
            let work = o.work.join(dataset).join(case.slug());
            let mut record = run_case(&case_hall, &case_snaps, *expected, &work, &settings)
                .map_err(|e| format!("{dataset}, {}: {e}", case.label()))?;
            let mut line = format!(
                "[{}/{total}] {dataset}, {}:",
                records.len() + 1,
                case.label()
            );
            for (si, v) in record["verdicts"]
                .as_array()
                .into_iter()
                .flatten()
                .enumerate()
            {
                let verdict = v["verdict"].as_str().unwrap_or("");
                let name = v["top_significant"]["name"].as_str().unwrap_or("-");
                let e = summary.entry((si, di)).or_default();
                match verdict {
                    "pass" => e.pass += 1,
                    "miss" => e.miss += 1,
                    _ => {
                        e.wrong += 1;
                        *e.wrong_names.entry(name.to_string()).or_default() += 1;
                    }
                }
                line += &format!(" {} {verdict} ({name});", settings[si].name);
            }
            eprintln!("{line} {:.1} s", t.elapsed().as_secs_f64());
            record["dataset"] = json!(dataset);
            record["expected"] = json!(expected);
            record["case"] = json!(case.label());
            record["noise_seed"] = json!(noise_seed);
            record["removal_seed"] = json!(removal_seed);
            record["removed_sensors"] = json!(removed);
            records.push(record);
        }
    }
    println!("| setting | dataset | cases | pass | miss | wrong | wrong names |");
    println!("|---|---|---|---|---|---|---|");
    let mut rows = Vec::new();
    for ((si, di), t) in &summary {
        let (pass, miss, wrong) = (t.pass, t.miss, t.wrong);
        let names: Vec<String> = t
            .wrong_names
            .iter()
            .map(|(n, c)| format!("{n} x{c}"))
            .collect();
        println!(
            "| {} | {} | {} | {pass} | {miss} | {wrong} | {} |",
            settings[*si].name,
            o.datasets[*di].0,
            pass + miss + wrong,
            names.join(", ")
        );
        rows.push(json!({
            "setting": settings[*si].name, "dataset": o.datasets[*di].0, "cases": pass + miss + wrong,
            "pass": pass, "miss": miss, "wrong": wrong, "wrong_names": names,
        }));
    }
    // No wall times in the JSON: the same options give the same file.
    let doc = json!({
        "experiment": "diagnosis_variants", "variants": o.variants, "quick": o.quick,
        "noise_c": NOISE_C, "removed_sensors": REMOVED_SENSORS,
        "settings": settings.iter().map(|s| s.name).collect::<Vec<_>>(),
        "summary": rows, "cases": records,
    });
    write_json(&o.out, &doc)?;
    println!(
        "\nwrote {} ({total} cases, {:.0} s)",
        o.out.display(),
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
