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
//! `--data DIR` (default the workspace's `data/openfoam`), `--quick` (N = 1, settings
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
//! nu 4 and the single-output check), `student-t 2` and `student-t 8` (with the check).
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

use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::snapshots::{self, HallSnapshot};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde_json::{json, Value};

/// Datasets and the name of the hypothesis the diagnosis should put on top.
const DATASETS: [(&str, Option<&str>); 4] = [
    ("of-dev-clean", None),
    ("of-dev-crac-offset", Some("crac_supply_offset")),
    ("of-dev-blanking", Some("rack_recirculation(rack=B4)")),
    ("of-dev-bypass", Some("bypass(behind_rack=B3)")),
];
/// The noise of the stored data (README), so that a variant is another draw of the same.
const NOISE_C: f64 = 0.15;
const REMOVED_SENSORS: usize = 4;

/// A diagnosis setting: `(robust_nu, single_output_check)` over the library's
/// `DiagnoseSettings::default()`, or none to keep the defaults as they are.
struct Setting {
    name: &'static str,
    overrides: Option<(Option<f64>, bool)>,
    quick: bool,
}

const fn setting(
    name: &'static str,
    overrides: Option<(Option<f64>, bool)>,
    quick: bool,
) -> Setting {
    Setting {
        name,
        overrides,
        quick,
    }
}

const SETTINGS: [Setting; 5] = [
    setting("gaussian", Some((None, false)), true),
    setting(
        "student-t 4, no single-output check",
        Some((Some(4.0), false)),
        false,
    ),
    setting("default", None, true),
    setting("student-t 2", Some((Some(2.0), true)), false),
    setting("student-t 8", Some((Some(8.0), true)), false),
];

/// Which data a case diagnoses.
#[derive(Clone, Copy)]
enum Case {
    Original,
    Noise(usize),
    NoiseRemoved(usize),
}

impl Case {
    fn label(self) -> String {
        match self {
            Case::Original => "original".into(),
            Case::Noise(k) => format!("noise {k}"),
            Case::NoiseRemoved(k) => format!("noise {k}, {REMOVED_SENSORS} sensors removed"),
        }
    }
    /// The case's directory under `--work`, e.g. `noise-3-4-sensors-removed`.
    fn slug(self) -> String {
        self.label().replace(", ", "-").replace(' ', "-")
    }
}

/// The seed of one random choice, from (dataset index, k, variant: 0 noise, 1 removal):
/// distinct small integers suffice, `seed_from_u64` scrambles them (SplitMix64).
fn seed(dataset: usize, k: usize, variant: u64) -> u64 {
    (1 << 40) | ((dataset as u64) << 24) | ((k as u64) << 8) | variant
}

/// A standard normal draw (Box-Muller; the root package does not depend on `rand_distr`).
fn gauss(rng: &mut Xoshiro256PlusPlus) -> f64 {
    let u1 = 1.0 - rng.random::<f64>(); // (0, 1]: ln stays finite
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The snapshots with every reading replaced by noise-free + N(0, NOISE_C).
fn noisy(
    hall: &Hall,
    snaps: &[HallSnapshot],
    truth: &Value,
    file: &Path,
    seed: u64,
) -> Result<Vec<HallSnapshot>, String> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut out = snaps.to_vec();
    for s in &mut out {
        let free = &truth["snapshots"][&s.state.label]["sensor_c_noise_free"];
        for (reading, sensor) in s.sensor_c.iter_mut().zip(&hall.sensors) {
            let clean = free[&sensor.id].as_f64().ok_or_else(|| {
                format!(
                    "{}: no snapshots.{}.sensor_c_noise_free.{}",
                    file.display(),
                    s.state.label,
                    sensor.id
                )
            })?;
            // Drawn for every sensor so that the draws do not depend on missing readings.
            let z = gauss(&mut rng);
            if reading.is_some() {
                *reading = Some(clean + NOISE_C * z);
            }
        }
    }
    Ok(out)
}

/// The hall without `REMOVED_SENSORS` seeded random sensors, and the snapshots without
/// their readings; returns the removed ids too.
fn remove_sensors(
    hall: &Hall,
    snaps: &[HallSnapshot],
    seed: u64,
) -> Result<(Hall, Vec<HallSnapshot>, Vec<String>), String> {
    let n = hall.sensors.len();
    if n <= REMOVED_SENSORS {
        return Err(format!("hall `{}` has only {n} sensors", hall.name));
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut drop = rand::seq::index::sample(&mut rng, n, REMOVED_SENSORS).into_vec();
    drop.sort_unstable();
    let mut hall = hall.clone();
    let removed = drop.iter().map(|&i| hall.sensors[i].id.clone()).collect();
    hall.sensors = keep(&hall.sensors, &drop);
    let mut snaps = snaps.to_vec();
    for s in &mut snaps {
        s.sensor_c = keep(&s.sensor_c, &drop);
    }
    Ok((hall, snaps, removed))
}

/// The items of `v` whose index is not in `drop`.
fn keep<T: Clone>(v: &[T], drop: &[usize]) -> Vec<T> {
    let kept = v.iter().enumerate().filter(|(i, _)| !drop.contains(i));
    kept.map(|(_, x)| x.clone()).collect()
}

/// Calibrates one case as `kalibre calibrate` does by default, journal and report in
/// `dir`, and diagnoses it under each setting; returns the case's JSON record.
fn run_case(
    hall: &Hall,
    snaps: &[HallSnapshot],
    expected: Option<&str>,
    dir: &Path,
    settings: &[&Setting],
) -> Result<Value, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    // A journal left by an earlier run would be replayed; start afresh so the result does
    // not depend on what the work directory held.
    let journal = dir.join("runs.jsonl");
    if journal.exists() {
        std::fs::remove_file(&journal).map_err(|e| format!("{}: {e}", journal.display()))?;
    }
    // The CLI's defaults (seed 1, 10 iterations, polish 8 with the built-in model) are
    // `HallCalibrationSettings::default()`.
    let cal_settings = HallCalibrationSettings::default();
    let cal = calibrate_hall(hall, snaps, &cal_settings, Some(&journal), Vec::new())
        .map_err(|e| format!("calibration: {e}"))?;
    let report_path = dir.join("report.json");
    let text =
        serde_json::to_string_pretty(&cal.report).map_err(|e| format!("report.json: {e}"))?;
    std::fs::write(&report_path, text).map_err(|e| format!("{}: {e}", report_path.display()))?;
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
            })
        });
        verdicts.push(json!({
            "setting": s.name, "robust_nu": ds.diagnose.robust_nu,
            "single_output_check": ds.diagnose.single_output_check,
            "verdict": verdict, "top_significant": top,
            "significant": d.diagnosis.significant().count(),
            "mae_c": d.diagnosis.mae, "noise_sigma_c": d.diagnosis.noise_sigma,
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
}

fn parse_args() -> Options {
    let mut o = Options {
        out: PathBuf::from("out/diagnosis_variants.json"),
        work: PathBuf::from("out/diagnosis_variants"),
        data: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/openfoam")),
        variants: 6,
        quick: false,
    };
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    o.quick = args.iter().any(|a| a == "--quick");
    args.retain(|a| a != "--quick");
    let mut i = 0;
    while i < args.len() {
        let flag = args[i].as_str();
        let known = ["--out", "--work", "--data", "--variants"].contains(&flag);
        if !known {
            eprintln!("unknown argument `{flag}` (use --out FILE, --work DIR, --data DIR, --variants N, --quick)");
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
    let settings: Vec<&Setting> = SETTINGS.iter().filter(|s| s.quick || !o.quick).collect();
    let mut cases = vec![Case::Original];
    for k in 1..=o.variants {
        cases.push(Case::Noise(k));
        cases.push(Case::NoiseRemoved(k));
    }
    let total = DATASETS.len() * cases.len();
    let mut records = Vec::new();
    // By (setting, dataset): the table's rows in order.
    let mut summary: BTreeMap<(usize, usize), Tally> = BTreeMap::new();
    for (di, (dataset, expected)) in DATASETS.iter().enumerate() {
        let dir = o.data.join(dataset);
        let hall_path = dir.join("hall.json");
        let hall = Hall::load(&hall_path).map_err(|e| e.to_string())?;
        EffectRegistry::builtin()
            .check_hall(&hall, &hall_path.display().to_string())
            .map_err(|e| e.to_string())?;
        let snaps = snapshots::load_snapshots(&hall, &dir.join("snapshots.csv"))
            .map_err(|e| e.to_string())?;
        let truth_path = dir.join("truth.json");
        let truth: Value = std::fs::read_to_string(&truth_path)
            .map_err(|e| e.to_string())
            .and_then(|t| serde_json::from_str(&t).map_err(|e| e.to_string()))
            .map_err(|e| format!("{}: {e}", truth_path.display()))?;
        for &case in &cases {
            let t = Instant::now();
            let (noise_seed, removal_seed) = match case {
                Case::Original => (None, None),
                Case::Noise(k) => (Some(seed(di, k, 0)), None),
                Case::NoiseRemoved(k) => (Some(seed(di, k, 0)), Some(seed(di, k, 1))),
            };
            let case_snaps = match noise_seed {
                Some(s) => noisy(&hall, &snaps, &truth, &truth_path, s)?,
                None => snaps.clone(),
            };
            let (case_hall, case_snaps, removed) = match removal_seed {
                Some(s) => remove_sensors(&hall, &case_snaps, s)?,
                None => (hall.clone(), case_snaps, Vec::new()),
            };
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
            DATASETS[*di].0,
            pass + miss + wrong,
            names.join(", ")
        );
        rows.push(json!({
            "setting": settings[*si].name, "dataset": DATASETS[*di].0, "cases": pass + miss + wrong,
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
    if let Some(parent) = o.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
    }
    let text = serde_json::to_string_pretty(&doc).map_err(|e| format!("JSON: {e}"))?;
    std::fs::write(&o.out, text).map_err(|e| format!("{}: {e}", o.out.display()))?;
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
