//! `kalibre diagnose`: where a calibrated hall model fails, and which physical effect is
//! missing.

use std::collections::BTreeMap;
use std::path::PathBuf;

use clap::Args;
use kalibre_core::calibrate::Report;
use kalibre_core::diagnose::{Diagnosis, HypothesisResult, CLOSE_ALTERNATIVE_BIC};
use kalibre_core::Model;
use kalibre_dc::diagnosis::{
    candidates_tried, diagnose_hall_with, EffectSolver, HallDiagnosisSettings,
};
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{OpenFoamEffectSolver, OpenFoamModel};
use kalibre_dc::report::WARMING_RACK_MIN_SHARE;
use kalibre_dc::sim::{sensor_warming, RackHeat, Simulator};
use kalibre_dc::snapshots;
use kalibre_dc::story::with_effect_from_report;
use kalibre_dc::HallModel;

use super::calibrated_model::{grid_or_recorded, CalibratedModel};
use super::openfoam_args::{of_err, OpenFoamArgs};
use super::simulate::sim_config;
use super::{with_threads, CliError, CliResult};

/// Options of `kalibre diagnose`.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The hall (`hall.json`) that was calibrated.
    #[arg(long)]
    hall: PathBuf,
    /// The measurements it was calibrated against (`snapshots.csv`).
    #[arg(long)]
    snapshots: PathBuf,
    /// The calibration directory (`report.json`, `runs.jsonl`) of `kalibre calibrate`.
    #[arg(long)]
    calibration: PathBuf,
    /// Print the diagnosis as JSON (`kalibre.diagnosis/1`) instead of text.
    #[arg(long)]
    json: bool,
    /// Grid cell size (m) of the model that supplies the Jacobians (default: the one the
    /// calibration recorded in `report.json`, else the built-in default).
    #[arg(long = "grid-m")]
    grid_m: Option<f64>,
    /// What solves the calibrated model and each candidate effect; it must be the model
    /// the calibration ran: `builtin` (the built-in simulator, seconds) or `openfoam` (the
    /// calibration's OpenFOAM model: one solve per snapshot for the base, each calibrated
    /// parameter and each candidate it can represent: `crac_supply_offset`, `bypass` and
    /// `rack_recirculation`; finished solves are kept in CALIBRATION/openfoam and reused).
    /// The grid, alpha mode and OpenFOAM options default to the ones the calibration
    /// recorded.
    #[arg(long, value_enum, default_value_t = DiagnoseModel::Builtin)]
    model: DiagnoseModel,
    #[command(flatten)]
    openfoam: OpenFoamArgs,
    /// How residuals are weighed: `student-t` (robust: a few sensors the model misses
    /// for reasons no candidate names, e.g. its own physics or a faulty sensor, count
    /// less) or `gaussian` (least squares: every residual counts by its square).
    #[arg(long, value_enum, default_value_t = Likelihood::StudentT)]
    likelihood: Likelihood,
    /// Degrees of freedom of the Student-t likelihood (smaller: more robust).
    #[arg(long, default_value_t = 4.0)]
    nu: f64,
    /// Skip the single-output check (by default a hypothesis must stay significant with
    /// any one sensor left out, so that one sensor the model misses cannot carry it).
    #[arg(long)]
    no_single_output_check: bool,
    /// Name the best explanation even when another of a different footprint fits about
    /// as well (BIC within 6). By default both are listed as undecided: the data then
    /// say that something is missing, not which.
    #[arg(long)]
    no_ambiguity_check: bool,
    /// Count the built-in model's tile-jet variant (each tile's supply carried up the
    /// cold aisle, physics the model lacks) in each sensor's model uncertainty, beside its
    /// grid error. No effect with `--model openfoam`.
    #[arg(long)]
    model_form: bool,
    /// Write FILE: the hall with the top significant suggestion added to its effects, and
    /// the calibrated values as every parameter's initial value (a warm start), ready for
    /// the next `kalibre calibrate --hall FILE`. Not written when nothing is significant.
    #[arg(long = "write-hall", value_name = "FILE")]
    write_hall: Option<PathBuf>,
    /// Refit the K leading hypotheses with the model itself before the final ranking:
    /// each is run at its fitted point (the calibrated parameters moved with it), and its
    /// linearisation replaced by the secant through that run. For large effects that the
    /// calibration has half absorbed into its parameters. Costs K x --refit-iterations
    /// solves per snapshot.
    #[arg(long, value_name = "K", default_value_t = 0)]
    refit: usize,
    /// Runs of each refit hypothesis (one solve per snapshot each).
    #[arg(long, value_name = "N", default_value_t = 4)]
    refit_iterations: usize,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
}

/// The model of `kalibre diagnose`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DiagnoseModel {
    /// The built-in simulator.
    Builtin,
    /// OpenFOAM, as `kalibre calibrate --model openfoam` runs it.
    Openfoam,
}

/// The likelihood of `kalibre diagnose`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Likelihood {
    /// Student-t with `--nu` degrees of freedom.
    StudentT,
    /// Gaussian.
    Gaussian,
}

impl Likelihood {
    /// The settings' `robust_nu` for this likelihood and `--nu`, which is checked whatever
    /// the likelihood (a bad value is refused, not ignored).
    pub fn robust_nu(self, nu: f64) -> CliResult<Option<f64>> {
        if !(nu.is_finite() && nu > 0.0) {
            return Err(CliError::Input(format!(
                "--nu: must be finite and > 0, got {nu}"
            )));
        }
        Ok(match self {
            Likelihood::StudentT => Some(nu),
            Likelihood::Gaussian => None,
        })
    }
}

/// `--model openfoam`: finite-difference step of the calibrated parameters (unit box).
const OPENFOAM_UNIT_STEP: f64 = 0.03;
/// `--model openfoam`: step of a candidate's parameter (share of its range).
const OPENFOAM_EFFECT_STEP: f64 = 0.2;

/// Runs `kalibre diagnose`.
pub fn run(args: DiagnoseArgs) -> CliResult {
    args.openfoam
        .refuse_unless(args.model == DiagnoseModel::Openfoam)?;
    let hall = Hall::load(&args.hall)?;
    kalibre_dc::effects::EffectRegistry::builtin()
        .check_hall(&hall, &args.hall.display().to_string())?;
    let snaps = snapshots::load_snapshots(&hall, &args.snapshots)?;
    let report_path = args.calibration.join("report.json");
    let text = std::fs::read_to_string(&report_path)
        .map_err(|e| CliError::Input(format!("{}: {e}", report_path.display())))?;
    let report: Report = serde_json::from_str(&text).map_err(|e| {
        CliError::Input(format!(
            "{}: not a kalibre report: {e}",
            report_path.display()
        ))
    })?;
    // The model the calibration ran, as it recorded it: its grid, alpha mode and
    // OpenFOAM options stand unless given again here.
    let recorded = CalibratedModel::of_report(&report_path, report.model.as_ref())?;
    let chosen = match args.model {
        DiagnoseModel::Builtin => "builtin",
        DiagnoseModel::Openfoam => "openfoam",
    };
    if let Some(m) = recorded.as_ref().filter(|m| m.kind != chosen) {
        return Err(CliError::Input(format!(
            "{}: runs of another model than --model {chosen}: the calibration ran the {} model{}",
            report_path.display(),
            m.kind,
            match m.kind.as_str() {
                "openfoam" => "; diagnose it with --model openfoam",
                "builtin" => "; diagnose it with --model builtin",
                _ => ", which the diagnosis cannot solve; calibrate the hall with --model builtin or openfoam to diagnose it",
            }
        )));
    }
    let hall = match &recorded {
        Some(m) => m.calibrated_hall(&hall),
        None => hall,
    };
    let grid_m = grid_or_recorded(args.grid_m, recorded.as_ref());
    let mut of_args = args.openfoam.clone();
    if let Some(m) = &recorded {
        of_args.of_iterations = of_args.of_iterations.or(m.of_iterations);
        of_args.np = of_args.np.or(m.np);
    }
    let sim = sim_config(grid_m)?;
    let model = HallModel::new(&hall, sim.clone())?;
    // The solver, and the fingerprint of the model the calibration must have run.
    let (solver, fp): (Box<dyn EffectSolver>, String) = match args.model {
        DiagnoseModel::Builtin => (
            Box::new(Simulator::new(&hall, sim.clone())?),
            model.fingerprint(),
        ),
        DiagnoseModel::Openfoam => {
            let of = of_args.settings(&args.calibration.join("openfoam"), grid_m)?;
            let fp = OpenFoamModel::new(&hall, of.clone())
                .map_err(of_err)?
                .fingerprint();
            (Box::new(OpenFoamEffectSolver::new(&hall, of)?), fp)
        }
    };
    let space = model.layout().space();
    let names: Vec<&str> = report
        .best
        .params
        .0
        .iter()
        .map(|(n, _)| n.as_str())
        .collect();
    if names != space.names().iter().map(String::as_str).collect::<Vec<_>>() {
        return Err(CliError::Input(format!(
            "{}: calibrated parameters ({}) do not match hall `{}` ({}): this calibration is of another hall",
            report_path.display(),
            names.join(", "),
            hall.name,
            space.names().join(", ")
        )));
    }
    // The journal names the model it ran: refuse a calibration of another hall or grid.
    let journal = args.calibration.join("runs.jsonl");
    if let Ok(lines) = std::fs::read_to_string(&journal) {
        let other = lines
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .find(|v| v["fingerprint"].as_str().is_some_and(|f| f != fp));
        if other.is_some() {
            return Err(CliError::Input(format!(
                "{}: runs of another model (a different hall.json, effects, --grid-m, --model or OpenFOAM option) than `{}` with --model {}",
                journal.display(),
                args.hall.display(),
                match args.model {
                    DiagnoseModel::Builtin => "builtin",
                    DiagnoseModel::Openfoam => "openfoam",
                }
            )));
        }
    }
    let params = report.best.params.values();
    let robust_nu = args.likelihood.robust_nu(args.nu)?;
    let mut settings = HallDiagnosisSettings {
        sim,
        ..HallDiagnosisSettings::default()
    };
    settings.diagnose.single_output_check = !args.no_single_output_check;
    settings.diagnose.ambiguity_check = !args.no_ambiguity_check;
    settings.model_form = args.model_form;
    settings.diagnose.robust_nu = robust_nu;
    if args.refit > 0 && args.refit_iterations == 0 {
        return Err(CliError::Input(
            "--refit-iterations: must be at least 1 with --refit (each refit runs the model)"
                .into(),
        ));
    }
    settings.refit_top = args.refit;
    settings.refit_iterations = args.refit_iterations;
    if args.model == DiagnoseModel::Openfoam {
        // Larger steps than the built-in simulator's: a solve's sensor values are window
        // means of oscillating probes, so a step must move them well beyond that scatter;
        // and the effect's step is then a typical size of the effect (a tenth of the
        // supply for a bypass), so the linearisation is a secant where it matters.
        settings.unit_step = OPENFOAM_UNIT_STEP;
        settings.effect_step = OPENFOAM_EFFECT_STEP;
        let candidates = candidates_tried(&hall, &EffectRegistry::builtin(), solver.as_ref());
        eprintln!(
            "diagnosing with OpenFOAM: {} solves ({} snapshots x (1 base + {} calibrated parameters + {} candidates)); finished solves are kept in {} and reused",
            snaps.len() * (1 + space.dim() + candidates),
            snaps.len(),
            space.dim(),
            candidates,
            args.calibration.join("openfoam").display()
        );
    }
    let d = with_threads(args.threads, || {
        diagnose_hall_with(
            &hall,
            &snaps,
            &params,
            &EffectRegistry::builtin(),
            &settings,
            solver.as_ref(),
        )
    })??;
    // The next hall first, so that a file that cannot be written fails before any output.
    let written = match &args.write_hall {
        Some(path) => write_next_hall(&hall, &report, &model, &d, path)?,
        None => None,
    };
    // Which racks warm the worst sensors in the calibrated built-in model's air flow (the
    // first snapshot): whose alphas they inform, and where a missing effect would act.
    // An OpenFOAM calibration's flow is OpenFOAM's, which the built-in model does not have.
    let heat = match (args.model, snaps.first()) {
        (DiagnoseModel::Builtin, Some(first)) => {
            let (_, rows) = model
                .rack_heat(&first.state, &params)
                .map_err(|e| CliError::Run(format!("snapshot `{}`: {e}", first.state.label)))?;
            Some(rows)
        }
        _ => None,
    };
    if args.json {
        let mut doc = d.to_json();
        doc["worst_sensors"] = worst_sensors_json(&hall, &report, heat.as_deref());
        println!(
            "{}",
            serde_json::to_string_pretty(&doc).map_err(|e| CliError::Run(format!("JSON: {e}")))?
        );
        // stdout is the JSON document; say what was written on stderr.
        if let Some(line) = &written {
            eprintln!("{line}");
        }
        return Ok(());
    }
    print_where_it_fails(&hall, &report, heat.as_deref());
    println!(
        "\nmissing effects, best first (MAE now {:.3} C):",
        d.diagnosis.mae
    );
    let significant: Vec<_> = d.diagnosis.significant().collect();
    let undecided = d.diagnosis.undecided();
    if !undecided.is_empty() {
        println!(
            "  no effect decided: {} fit about as well (BIC within {CLOSE_ALTERNATIVE_BIC:.0}), \
             each with another footprint; the data say something is missing, not which. \
             Recalibrate with each entry added and keep the one that lowers the error.",
            undecided.join(", ")
        );
    } else if significant.is_empty() {
        println!("  no significant missing effect");
    }
    for (h, s) in d.diagnosis.hypotheses.iter().zip(&d.suggestions).take(8) {
        let flags = hypothesis_flags(h.significant, h.refuted, h.inert, h.identifiable);
        println!(
            "  {:<48} explains {:>4.0}%  predicted MAE {:.3} C  {}",
            h.name,
            100.0 * h.explained_fraction,
            h.predicted_mae,
            flags
        );
        let entry = || serde_json::to_string(s).unwrap_or_default();
        if h.significant {
            println!("    add to hall.json \"effects\": {}", entry());
        } else if undecided.contains(&h.name.as_str()) {
            println!(
                "    undecided (about as good: {}); if it is this one, add to hall.json \"effects\": {}",
                h.ambiguous_with.join(", "),
                entry()
            );
        } else if !h.ambiguous_with.is_empty() {
            println!(
                "    not named: better explanations are undecided ({}); its entry: {}",
                h.ambiguous_with.join(", "),
                entry()
            );
        } else if let Some(sensor) = &h.carried_by {
            println!(
                "    rests on one sensor, {sensor}: without it the others do not prefer it \
                 (a faulty sensor, or the model's own error there, looks the same)"
            );
            println!(
                "    if {sensor} reads right, add to hall.json \"effects\": {}",
                entry()
            );
        }
        if significant.first().is_some_and(|best| best.name == h.name) {
            print_close_alternatives(&d.diagnosis, h);
        }
    }
    print_unexplained(&d.diagnosis);
    if !d.refits.is_empty() {
        println!(
            "\nrefit with the model (each run: the effect's value, the model's MAE there; \
             `worse`: not better than the best point before it, so the next step was halved):"
        );
        for r in &d.refits {
            let steps: Vec<String> = r
                .steps
                .iter()
                .map(|s| {
                    let worse = if s.accepted { "" } else { " worse" };
                    format!("{:.4}: {:.3} C{worse}", s.effect_value, s.model_mae_c)
                })
                .collect();
            let stopped = r
                .stopped
                .as_ref()
                .map(|w| format!(" (stopped: {w})"))
                .unwrap_or_default();
            println!("  {:<48} {}{stopped}", r.name, steps.join(", "));
        }
    }
    if !d.not_tried.is_empty() {
        println!("\nnot tried:");
        for n in &d.not_tried {
            let count = if n.count > 1 {
                format!(" ({} candidates)", n.count)
            } else {
                String::new()
            };
            println!("  {}{count}: {}", n.candidate, n.reason);
        }
    }
    if let Some(line) = &written {
        println!("\n{line}");
    }
    Ok(())
}

/// `--write-hall`: the hall with the top significant suggestion added, warm-started at
/// the calibrated values; returns what to tell the user.
fn write_next_hall(
    hall: &Hall,
    report: &Report,
    model: &HallModel,
    d: &kalibre_dc::diagnosis::HallDiagnosis,
    path: &std::path::Path,
) -> CliResult<Option<String>> {
    let top = d
        .diagnosis
        .hypotheses
        .iter()
        .zip(&d.suggestions)
        .find(|(h, _)| h.significant);
    let Some((h, entry)) = top else {
        return Ok(Some(format!(
            "nothing significant: {} not written",
            path.display()
        )));
    };
    let next = with_effect_from_report(hall, report, model, &EffectRegistry::builtin(), entry)?;
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| CliError::Input(format!("--write-hall: {}: {e}", dir.display())))?;
    }
    next.save(path)?;
    Ok(Some(format!(
        "wrote {}: the hall with {} added, warm-started at the calibrated values",
        path.display(),
        h.name
    )))
}

/// The hypotheses the data hardly tell from the best one, under it: a neighbouring
/// placement is often among them, and the place to look is then either.
fn print_close_alternatives(d: &Diagnosis, best: &HypothesisResult) {
    let close = d.close_alternatives();
    if close.is_empty() {
        return;
    }
    let describe = |h: &&HypothesisResult| {
        let why = match &h.carried_by {
            Some(sensor) => format!(", rests on {sensor} alone"),
            None => String::new(),
        };
        format!("{} (BIC {:+.1}{why})", h.name, h.delta_bic - best.delta_bic)
    };
    // Those with a lower BIC than the best are not significant for another reason (one
    // sensor carries them, say): they fit better, which is not "hardly told apart".
    let (better, near): (Vec<_>, Vec<_>) = close.iter().partition(|h| h.delta_bic < best.delta_bic);
    if !near.is_empty() {
        let names: Vec<String> = near.iter().map(describe).collect();
        println!(
            "    the data hardly tell it from (BIC within {CLOSE_ALTERNATIVE_BIC:.0}): {}",
            names.join(", ")
        );
    }
    if !better.is_empty() {
        let names: Vec<String> = better.iter().map(describe).collect();
        println!(
            "    fit better, but are not significant: {}",
            names.join(", ")
        );
    }
}

/// The sensors no candidate explains: the model's own error there, or a faulty sensor.
pub(super) fn print_unexplained(d: &kalibre_core::diagnose::Diagnosis) {
    if d.unexplained.is_empty() {
        return;
    }
    println!(
        "\nsensors no candidate explains (the model's own physics there, or a faulty or misplaced sensor; \
         the ranking above counts them little):"
    );
    for u in &d.unexplained {
        // A candidate may explain it and still not count: one that rests on it alone.
        let resting: Vec<&str> = d
            .hypotheses
            .iter()
            .filter(|h| h.carried_by.as_deref() == Some(u.output.as_str()))
            .map(|h| h.name.as_str())
            .collect();
        let mut notes = Vec::new();
        if !resting.is_empty() {
            notes.push(format!("{} rests on it alone", resting.join(", ")));
        }
        // How far other plausible physics (the model-form variants) moves it: when that
        // is of the residual's size, the model's own physics there is the likely cause.
        if let Some(form) = u.model_form_c {
            notes.push(format!(
                "the model's tile-jet variant moves it by {form:.2} C"
            ));
        }
        let note = if notes.is_empty() {
            String::new()
        } else {
            format!(" ({})", notes.join("; "))
        };
        println!(
            "  {:<12} model minus measurement {:+.2} C on average, {:.1} noise scales{note}",
            u.output, u.mean_residual, u.rms_scales
        );
    }
    println!(
        "  to calibrate again (with a suggested effect) weighing them down as this ranking does, \
         add `--likelihood student-t` to `kalibre calibrate`"
    );
}

/// Mean residual (model minus measurement, C) per sensor over the snapshots, largest
/// magnitude first.
pub(super) fn worst_sensors(report: &Report) -> Vec<(&str, f64)> {
    let mut by_sensor: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
    for r in &report.residuals {
        let s = by_sensor.entry(r.sensor.as_str()).or_default();
        s.0 += r.predicted_c - r.measured_c;
        s.1 += 1;
    }
    let mut worst: Vec<(&str, f64)> = by_sensor
        .iter()
        .map(|(k, (s, n))| (*k, s / *n as f64))
        .collect();
    worst.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    worst
}

/// One worst sensor in words: where it is and how far off the model reads.
pub(super) fn sensor_line(hall: &Hall, sensor: &str, mean_c: f64) -> String {
    let s = hall.sensors.iter().find(|s| s.id == sensor);
    let (aisle, pos) = s.map_or(("?", [0.0; 3]), |s| (s.aisle.as_str(), s.position_m));
    format!(
        "{sensor:<12} {aisle:>4} aisle at ({:.1}, {:.1}, {:.1}) m: the model reads {:.2} C {}",
        pos[0],
        pos[1],
        pos[2],
        mean_c.abs(),
        if mean_c > 0.0 { "too warm" } else { "too cold" }
    )
}

/// The racks that warm `sensor` in the model's flow, in words (`rows`: every rack's
/// share, no cut).
pub(super) fn warming_racks(rows: &[RackHeat], sensor: &str, mean_c: f64) -> String {
    let Some(warming) = sensor_warming(rows, sensor, WARMING_RACK_MIN_SHARE) else {
        let none = "no exhaust reaches it in the model (under 0.01 K)";
        return if mean_c < 0.0 {
            format!(
                "{none}: the measured warmth takes a path the model lacks, or the sensor is off"
            )
        } else {
            none.into()
        };
    };
    let racks: Vec<String> = warming
        .racks
        .iter()
        .map(|r| format!("{} {:.0} %", r.rack, 100.0 * r.share))
        .collect();
    format!(
        "in the model, exhausts warm it by {:.2} K in {}: {}",
        warming.warming_k,
        warming.snapshot,
        if racks.is_empty() {
            format!(
                "no rack gives {:.0} % of that",
                100.0 * WARMING_RACK_MIN_SHARE
            )
        } else {
            format!("racks {}", racks.join(", "))
        }
    )
}

/// How many of the worst sensors the diagnosis describes.
const WORST_SENSORS_SHOWN: usize = 5;

/// `worst_sensors` of `diagnose --json`: the sensors the calibrated model misses most,
/// each with where it is, the mean residual, and (built-in model) which racks warm it in
/// the model's flow (`warming`, `null` when no exhaust reaches it; absent with a model
/// whose flow kalibre does not have).
fn worst_sensors_json(
    hall: &Hall,
    report: &Report,
    heat: Option<&[RackHeat]>,
) -> serde_json::Value {
    worst_sensors(report)
        .iter()
        .take(WORST_SENSORS_SHOWN)
        .map(|(sensor, mean_c)| {
            let s = hall.sensors.iter().find(|s| s.id == *sensor);
            let mut entry = serde_json::json!({
                "sensor": sensor,
                "aisle": s.map(|s| s.aisle.as_str()),
                "position_m": s.map(|s| s.position_m),
                "mean_residual_c": mean_c,
            });
            if let Some(rows) = heat {
                entry["warming"] = sensor_warming(rows, sensor, WARMING_RACK_MIN_SHARE).map_or(
                    serde_json::Value::Null,
                    |w| {
                        let racks: Vec<_> = w
                            .racks
                            .iter()
                            .map(|r| {
                                serde_json::json!({
                                    "rack": r.rack, "warming_k": r.warming_k, "share": r.share
                                })
                            })
                            .collect();
                        serde_json::json!({"snapshot": w.snapshot, "warming_k": w.warming_k, "racks": racks})
                    },
                );
            }
            entry
        })
        .collect()
}

/// A hypothesis's flags in words, e.g. `significant, not identifiable`.
pub(super) fn hypothesis_flags(
    significant: bool,
    refuted: bool,
    inert: bool,
    identifiable: bool,
) -> String {
    [
        (significant, "significant"),
        (refuted, "refuted by its model runs"),
        (inert, "inert"),
        (!identifiable, "not identifiable"),
    ]
    .iter()
    .filter(|f| f.0)
    .map(|f| f.1)
    .collect::<Vec<_>>()
    .join(", ")
}

/// The worst sensors and the residual by aisle and snapshot, in words.
fn print_where_it_fails(hall: &Hall, report: &Report, heat: Option<&[RackHeat]>) {
    println!("where the calibrated model fails (model minus measurement):");
    let mut by_group: BTreeMap<(String, String), (f64, usize)> = BTreeMap::new();
    for r in &report.residuals {
        let aisle = hall
            .sensors
            .iter()
            .find(|s| s.id == r.sensor)
            .map_or("?", |s| s.aisle.as_str());
        let g = by_group
            .entry((aisle.to_string(), r.snapshot.clone()))
            .or_default();
        g.0 += r.predicted_c - r.measured_c;
        g.1 += 1;
    }
    for (sensor, mean) in worst_sensors(report).iter().take(WORST_SENSORS_SHOWN) {
        println!("  {}", sensor_line(hall, sensor, *mean));
        if let Some(rows) = heat {
            println!("  {:<12} {}", "", warming_racks(rows, sensor, *mean));
        }
    }
    for ((aisle, snap), (s, n)) in &by_group {
        println!(
            "  {aisle:>4} aisle, snapshot {snap:<6} mean residual {:+.2} C",
            s / *n as f64
        );
    }
}
