//! `kalibre diagnose`: where a calibrated hall model fails, and which physical effect is
//! missing; for a model of your own (`--model command`), which of its candidate effects
//! the data want (`own.rs`).

use std::path::PathBuf;

use clap::Args;
use kalibre_core::calibrate::{NamedValues, Report, REPORT_SCHEMA};
use kalibre_core::diagnose::CLOSE_ALTERNATIVE_BIC;
use kalibre_core::Model;
use kalibre_dc::diagnosis::{
    candidates_tried, diagnose_hall_with, EffectSolver, HallDiagnosisSettings,
};
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{remove_interrupted_runs, OpenFoamEffectSolver, OpenFoamModel};
use kalibre_dc::sim::Simulator;
use kalibre_dc::snapshots;
use kalibre_dc::HallModel;

mod journal;
mod next_hall;
mod own;
mod print;

use next_hall::{check_writable_file, write_next_hall};
use print::{
    print_close_alternatives, print_odd_snapshots, print_unexplained, print_where_it_fails,
};
pub(super) use print::{sensor_line, warming_racks};

use super::calibrated_model::{
    check_same_conditions, check_same_measurements, grid_or_recorded, CalibratedModel,
};
use super::likelihood::Likelihood;
use super::openfoam_args::{of_err, OpenFoamArgs};
use super::simulate::{check_model_cells, load_params, sim_config};
use super::{with_threads, CliError, CliResult};

/// Options of `kalibre diagnose`.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The hall (`hall.json`) that was calibrated.
    #[arg(long)]
    hall: Option<PathBuf>,
    /// The measurements it was calibrated against (`snapshots.csv`).
    #[arg(long)]
    snapshots: Option<PathBuf>,
    /// With `--model command`: the `model.toml` of a model of your own, whose `[[params]]`
    /// with `absent` are the candidate effects to test.
    #[arg(long)]
    config: Option<PathBuf>,
    /// With `--model command`: the measurements it was calibrated against
    /// (`measurements.csv`).
    #[arg(long)]
    measurements: Option<PathBuf>,
    /// The calibration directory (`report.json`, `runs.jsonl`) of `kalibre calibrate`.
    #[arg(long)]
    calibration: PathBuf,
    /// Print the diagnosis as JSON (`kalibre.diagnosis/1`; with `--model command`, the
    /// document of docs/formats.md) instead of text.
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
    /// `rack_recirculation`; finished solves are kept in CALIBRATION/openfoam and reused),
    /// or `command` (a model of your own, `--config` and `--measurements`: its candidate
    /// effects, each run journaled in CALIBRATION/runs.jsonl). The alpha mode is always
    /// the one the calibration recorded (there is no --alpha here); the grid and OpenFOAM
    /// options are the recorded ones unless --grid-m or those options are given.
    #[arg(long, value_enum, default_value_t = DiagnoseModel::Builtin)]
    model: DiagnoseModel,
    #[command(flatten)]
    openfoam: OpenFoamArgs,
    /// How residuals are weighed: `student-t` (robust: a few sensors the model misses
    /// for reasons no candidate names, e.g. its own physics or a faulty sensor, count
    /// less) or `gaussian` (least squares: every residual counts by its square).
    #[arg(long, value_enum, default_value_t = Likelihood::StudentT)]
    likelihood: Likelihood,
    /// Degrees of freedom of the Student-t likelihood (smaller: more robust; at least 1;
    /// default 4).
    #[arg(long)]
    nu: Option<f64>,
    /// The measurements' noise (standard deviation, in their units: C for a hall's
    /// sensors), when it is known: the ranking then takes it instead of estimating it
    /// from the residuals. Needed when there are no more measured values than
    /// calibrated parameters, which leave nothing to estimate it from.
    #[arg(long, value_name = "SIGMA")]
    noise: Option<f64>,
    /// Skip the single-output check (by default a hypothesis must stay significant with
    /// any one sensor left out, so that one sensor the model misses cannot carry it).
    #[arg(long)]
    no_single_output_check: bool,
    /// Let a hypothesis the single-output check would stop pass when its BIC is at least
    /// this much below that of a constant bias of the one sensor it rests on (a faulty
    /// sensor reads as such a bias; an effect follows its cause from snapshot to
    /// snapshot). By default the check stops it.
    #[arg(long, value_name = "BIC", conflicts_with = "no_single_output_check")]
    sensor_bias_rival: Option<f64>,
    /// Name the best explanation even when another of a different footprint fits about
    /// as well (BIC within 6). By default both are listed as undecided: the data then
    /// say that something is missing, not which.
    #[arg(long)]
    no_ambiguity_check: bool,
    /// Leave the built-in model's tile-jet variant out of each sensor's model
    /// uncertainty. By default what that variant (each tile's supply carried up the cold
    /// aisle, physics the model lacks) reads beyond the model counts beside the grid
    /// error, by the share of it the residuals bear out: none where the model
    /// reproduces the data. No effect with `--model openfoam`.
    #[arg(long)]
    no_model_form: bool,
    /// Write FILE: the hall with the top significant suggestion added to its effects, and
    /// the calibrated values refitted beside it (the linearised joint fit that sized the
    /// suggestion) as every parameter's initial value (a warm start), ready for
    /// the next `kalibre calibrate --hall FILE`. Not written when nothing is significant.
    #[arg(long = "write-hall", value_name = "FILE")]
    write_hall: Option<PathBuf>,
    /// With `--model command`: write FILE, model.toml with the top significant candidate
    /// added (its `absent` and `effect` deleted, `initial` its fitted value) and every
    /// calibrated parameter's `initial` where the model ran at that fit: the next
    /// `kalibre calibrate --config FILE` with the same --out starts from that run, read
    /// from the journal. FILE goes beside model.toml (its paths are relative to it);
    /// comments and layout are kept. Not written when nothing is significant.
    #[arg(long = "write-config", value_name = "FILE")]
    write_config: Option<PathBuf>,
    /// Refit the K leading hypotheses with the model itself before the final ranking:
    /// each is run at its fitted point (the calibrated parameters moved with it), and its
    /// linearisation replaced by the secant through that run. For large effects that the
    /// calibration has half absorbed into its parameters, or (`--model command`) whose
    /// footprint is not linear in their size. Costs K x --refit-iterations runs per
    /// snapshot.
    #[arg(long, value_name = "K", default_value_t = 0)]
    refit: usize,
    /// Runs of each refit hypothesis (one solve per snapshot each).
    #[arg(long, value_name = "N", default_value_t = 4, requires = "refit")]
    refit_iterations: usize,
    /// With `--model command`: replay the journal's failed runs as the failures they were
    /// instead of running them again (by default a failed run is retried, since its
    /// cause may have passed).
    #[arg(long = "replay-failed")]
    replay_failed: bool,
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
    /// A model of your own (`model.toml`), as `kalibre calibrate --model command
    /// --measurements` runs it.
    Command,
}

/// `--model openfoam`: finite-difference step of the calibrated parameters (unit box).
const OPENFOAM_UNIT_STEP: f64 = 0.03;
/// `--model openfoam`: step of a candidate's parameter (share of its range).
const OPENFOAM_EFFECT_STEP: f64 = 0.2;

/// Runs `kalibre diagnose`.
pub fn run(args: DiagnoseArgs) -> CliResult {
    if let Some(t) = args.sensor_bias_rival {
        if !(t.is_finite() && t >= 0.0) {
            return Err(CliError::Input(format!(
                "--sensor-bias-rival: must be finite and >= 0, got {t}"
            )));
        }
    }
    if args.calibration.is_file() {
        let dir = match args.calibration.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.display().to_string(),
            _ => ".".to_string(),
        };
        return Err(CliError::Input(format!(
            "--calibration {}: is a file; give the directory `kalibre calibrate --out` wrote \
             (the one holding report.json and runs.jsonl, here perhaps {dir})",
            args.calibration.display()
        )));
    }
    // Both kinds of model refit with the model itself.
    if args.refit > 0 && args.refit_iterations == 0 {
        return Err(CliError::Input(
            "--refit-iterations: must be at least 1 with --refit (each refit runs the model)"
                .into(),
        ));
    }
    // A flag's value is checked before any file is read.
    noise_arg(args.noise)?;
    if args.model == DiagnoseModel::Command {
        return own::run(&args);
    }
    args.openfoam
        .refuse_unless(args.model == DiagnoseModel::Openfoam)?;
    for (flag, given) in [
        ("--config", args.config.is_some()),
        ("--measurements", args.measurements.is_some()),
        ("--replay-failed", args.replay_failed),
        ("--write-config", args.write_config.is_some()),
    ] {
        if given {
            return Err(CliError::Input(format!(
                "{flag} belongs to a model of your own: add --model command (a hall takes \
                 --hall and --snapshots)"
            )));
        }
    }
    let (Some(hall_path), Some(snaps_path)) = (args.hall.clone(), args.snapshots.clone()) else {
        return Err(CliError::Input(
            "kalibre diagnose needs --hall and --snapshots (the calibrated hall and its \
             measurements), or --model command --config model.toml --measurements FILE for a \
             model of your own"
                .into(),
        ));
    };
    if let Some(path) = &args.write_hall {
        // The refusal first: the writability check writes a probe file in the target's
        // directory, which is no business of an input's directory.
        let (report, journal) = (
            args.calibration.join("report.json"),
            args.calibration.join("runs.jsonl"),
        );
        super::same_file::refuse_same_files(
            &[("--write-hall", Some(path.as_path()))],
            &[
                ("the --hall file", Some(hall_path.as_path())),
                ("the --snapshots file", Some(snaps_path.as_path())),
                ("the calibration's report", Some(report.as_path())),
                ("the calibration's run journal", Some(journal.as_path())),
            ],
        )?;
        check_writable_file(path)?;
    }
    let hall = Hall::load(&hall_path)?;
    let registry = EffectRegistry::builtin();
    registry.check_hall(&hall, &hall_path.display().to_string())?;
    let snaps = snapshots::load_snapshots(&hall, &snaps_path)?;
    super::plausible::warn_readings(&snaps_path, &hall, &snaps);
    super::plausible::warn_setpoints(&snaps_path, &hall, snaps.iter().map(|s| &s.state));
    let states = snaps.iter().map(|s| &s.state);
    super::plausible::warn_alpha_units(&hall_path, &hall);
    super::plausible::warn_implausible_rises(&hall_path, &snaps_path, &hall, states)?;
    let report_path = args.calibration.join("report.json");
    journal::check_regular_files(&args.calibration)?;
    let text = std::fs::read_to_string(&report_path)
        .map_err(|e| CliError::Input(format!("{}: {e}", report_path.display())))?;
    // A byte-order mark from an editor that touched the file is no reason to refuse it.
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let mut report: Report = serde_json::from_str(text).map_err(|e| {
        CliError::Input(format!(
            "{}: not a kalibre report: {e}",
            report_path.display()
        ))
    })?;
    if report.schema != REPORT_SCHEMA {
        return Err(CliError::Input(format!(
            "{}: /schema: expected \"{REPORT_SCHEMA}\", found \"{}\"",
            report_path.display(),
            report.schema
        )));
    }
    // The model the calibration ran, as it recorded it: its grid, alpha mode and
    // OpenFOAM options stand unless given again here. Read before the readings are
    // compared, so that a model of your own's calibration is named as such, not blamed
    // on `--snapshots`.
    let recorded = CalibratedModel::of_report(&report_path, report.model.as_ref())?;
    check_same_measurements(&report_path, &report.residuals, &snaps_path, &hall, &snaps)?;
    let openfoam = args.model == DiagnoseModel::Openfoam;
    let chosen = if openfoam { "openfoam" } else { "builtin" };
    if let Some(m) = recorded.as_ref().filter(|m| m.kind != chosen) {
        return Err(CliError::Input(format!(
            "{}: runs of another model than --model {chosen}: the calibration ran the {} model{}",
            report_path.display(),
            m.kind,
            match m.kind.as_str() {
                "openfoam" => "; diagnose it with --model openfoam",
                "builtin" => "; diagnose it with --model builtin",
                "command" => "; a model of your own is diagnosed with --model command --config model.toml --measurements FILE, and a hall's external command the diagnosis cannot solve: calibrate the hall with --model builtin or openfoam to diagnose it",
                _ => ", which the diagnosis cannot solve; calibrate the hall with --model builtin or openfoam to diagnose it",
            }
        )));
    }
    let hall = match &recorded {
        Some(m) => m.calibrated_hall(&hall),
        None => hall,
    };
    if let (None, Some(m)) = (args.grid_m, &recorded) {
        m.check_cells(&report_path, &hall)?;
    }
    let grid_m = grid_or_recorded(args.grid_m, recorded.as_ref());
    let mut of_args = args.openfoam.clone();
    if let Some(m) = &recorded {
        of_args.of_iterations = of_args.of_iterations.or(m.of_iterations);
        of_args.np = of_args.np.or(m.np);
    }
    let sim = sim_config(grid_m)?;
    if args.model == DiagnoseModel::Builtin {
        check_model_cells(&hall, &hall_path, sim.cell_m, args.grid_m.is_some())?;
        super::plausible::warn_builtin_hall(&hall_path, &hall, sim.cell_m);
    }
    let model = HallModel::new(&hall, sim.clone())
        .map_err(|e| e.in_hall_file(&hall_path.display().to_string()))?;
    // The solver, and the fingerprints of the model the calibration must have run: its
    // own, then those earlier versions gave it (their reports and runs are its too).
    let (solver, fps): (Box<dyn EffectSolver>, Vec<String>) = match openfoam {
        false => (
            Box::new(Simulator::new(&hall, sim.clone())?),
            model.run_fingerprints(),
        ),
        true => {
            let of = of_args.settings(&args.calibration.join("openfoam"), grid_m)?;
            super::openfoam_args::check_mesh(&hall, &hall_path, of.grid_m, args.grid_m.is_some())?;
            super::out_dir::note_interrupted_runs(remove_interrupted_runs(&of.cache_root));
            let fps = OpenFoamModel::new(&hall, of.clone())
                .map_err(|e| of_err(e.in_hall_file(&hall_path.display().to_string())))?
                .run_fingerprints();
            (Box::new(OpenFoamEffectSolver::new(&hall, of)?), fps)
        }
    };
    if let Some(recorded_fp) = recorded.as_ref().and_then(|m| m.fingerprint.as_ref()) {
        if !fps.contains(recorded_fp) {
            return Err(CliError::Input(format!(
                "{}: /model/fingerprint: runs of another model (a different hall.json, \
                 effects, --grid-m, --model or OpenFOAM option) than `{}` with --model \
                 {chosen}{}",
                report_path.display(),
                hall_path.display(),
                super::hall_changes::clause(&args.calibration, &hall_path),
            )));
        }
    }
    let space = model.layout().space();
    // By name, as JSON objects are unordered (a report rewritten by another tool keeps
    // its values); every calibrated parameter must be there, within its bounds.
    let report_json: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| CliError::Input(format!("{}: {e}", report_path.display())))?;
    let params = load_params(&report_path, &report_json, space)?;
    report.best.params = NamedValues::new(&space.names(), &params);
    let journal_keys = journal::scenario_keys(
        &args.calibration.join("runs.jsonl"),
        &fps,
        &hall_path,
        chosen,
    )?;
    check_same_conditions(
        &report_path,
        recorded.as_ref(),
        &journal_keys,
        &snaps_path,
        &snaps,
    )?;
    let robust_nu = args.likelihood.robust_nu(args.nu)?;
    let noise = noise_arg(args.noise)?;
    let mut settings = HallDiagnosisSettings {
        sim,
        ..HallDiagnosisSettings::default()
    };
    settings.diagnose.single_output_check = !args.no_single_output_check;
    settings.diagnose.ambiguity_check = !args.no_ambiguity_check;
    settings.diagnose.sensor_bias_rival_bic = args.sensor_bias_rival;
    settings.model_form = !args.no_model_form;
    settings.diagnose.robust_nu = robust_nu;
    settings.diagnose.noise_sigma = noise;
    settings.refit_top = args.refit;
    settings.refit_iterations = args.refit_iterations;
    if args.model == DiagnoseModel::Openfoam {
        // Larger steps than the built-in simulator's: a solve's sensor values are window
        // means of oscillating probes, so a step must move them well beyond that scatter;
        // and the effect's step is then a typical size of the effect (a tenth of the
        // supply for a bypass), so the linearisation is a secant where it matters.
        settings.unit_step = OPENFOAM_UNIT_STEP;
        settings.effect_step = OPENFOAM_EFFECT_STEP;
        let candidates = candidates_tried(&hall, &registry, solver.as_ref());
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
            &registry,
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
    // busiest snapshot): whose alphas they inform, and where a missing effect would act.
    // An OpenFOAM calibration's flow is OpenFOAM's, which the built-in model does not have.
    let heat = match (args.model, super::calibrate::busiest(&snaps)) {
        (DiagnoseModel::Builtin, Some(first)) => {
            let (_, rows) = model
                .rack_heat(&first.state, &params)
                .map_err(|e| CliError::Run(format!("snapshot `{}`: {e}", first.state.label)))?;
            Some(rows)
        }
        _ => None,
    };
    if args.json {
        let doc = d.document(&hall, &report.residuals, heat.as_deref());
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
    print_odd_snapshots(&kalibre_dc::diagnosis::odd_snapshots(&report.residuals));
    println!(
        "\nmissing effects, best first: the significant ones, then the others, each in order \
         of `BIC` (the change of the Bayesian information criterion the effect brings: lower \
         is better supported, {} or less is needed to be significant); MAE now {:.3} C; \
         `explains`: the share of the residual, as the ranking weighs the sensors, that the \
         effect removes; `predicted MAE`: over every sensor, linearised, with the calibrated \
         parameters refitted beside the effect, as a recalibration with it refits them:",
        -settings.diagnose.bic_threshold, d.diagnosis.mae
    );
    // Said only when it weighs: on data the model reproduces the share is about 0.
    if let Some(share) = d.diagnosis.model_form_share.filter(|c| *c >= 0.01) {
        println!(
            "  (model uncertainty: tile jets, which the built-in model's air flow lacks, would \
             move some sensors; the residuals are large enough to allow {:.0} % of that \
             movement's variance, so those sensors, often the row-end inlets, weigh less in \
             this ranking)",
            100.0 * share
        );
    }
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
    } else if significant.len() > 1 {
        // Several places or kinds can each take up the same residual: the first is the
        // best-supported reading, the rest are often it read another way.
        println!(
            "  {} are significant, often one residual read several ways (those marked an \
             alternative below read the same part of it as the first): add the first, \
             recalibrate and diagnose again; the others fall away if they were the same",
            significant.len()
        );
    }
    let best = significant.first().copied();
    for (i, (h, s)) in d
        .diagnosis
        .hypotheses
        .iter()
        .zip(&d.suggestions)
        .enumerate()
        .take(8)
    {
        let flags = print::flags(h);
        println!(
            "  {:<48} explains {:>4.0}%  predicted MAE {:.3} C  BIC {:+.1}  {}",
            h.name,
            100.0 * h.explained_fraction,
            h.predicted_mae,
            h.delta_bic,
            flags
        );
        // A fit outside its range has no entry: clamped, it would do nothing.
        let Some(entry) = d.entry(i) else {
            println!("    {}; no entry to add", print::outside_range(h));
            continue;
        };
        let entry = || serde_json::to_string(entry).unwrap_or_default();
        if let Some(best) = best.filter(|b| h.significant && b.name != h.name) {
            if let Some(note) = kalibre_dc::diagnosis::alternative_note(
                &best.name,
                best.explained_fraction,
                h.explained_fraction,
                h.delta_bic - best.delta_bic,
            ) {
                println!("    {note}");
            }
        }
        if h.significant && !h.identifiable {
            println!("    {}", print::not_identifiable(h));
        }
        if h.significant {
            // What the kind is on the floor: its name is the model's.
            match registry.get(&s.kind).map(|f| f.meaning()) {
                Some(meaning) if !meaning.is_empty() => println!("    that is {meaning}"),
                _ => {}
            }
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
            if let Some(b) = h.sensor_bias_delta_bic {
                // A fault reads the same in every snapshot; an effect follows its cause.
                // Within 6 either way the evidence between the two is short of strong.
                let verdict = if b <= -CLOSE_ALTERNATIVE_BIC {
                    "the snapshots prefer it to a constant bias of that sensor"
                } else if b < CLOSE_ALTERNATIVE_BIC {
                    "the snapshots cannot tell it from a constant bias of that sensor"
                } else {
                    "a constant bias of that sensor fits better"
                };
                println!("    {verdict} (BIC {b:+.1} against the bias)");
            }
            println!(
                "    if {sensor} reads right, add to hall.json \"effects\": {}",
                entry()
            );
        }
        if significant.first().is_some_and(|best| best.name == h.name) {
            print_close_alternatives(&d.diagnosis, h);
        }
    }
    print_unexplained(&d.diagnosis, report.settings.robust_nu);
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

/// `--noise`, checked: a finite standard deviation above 0.
pub(super) fn noise_arg(noise: Option<f64>) -> CliResult<Option<f64>> {
    match noise {
        Some(s) if !(s.is_finite() && s > 0.0) => Err(CliError::Input(format!(
            "--noise: expected the measurements' noise, a finite standard deviation above 0, \
             got {}",
            kalibre_dc::snapshots::number(s)
        ))),
        _ => Ok(noise),
    }
}
