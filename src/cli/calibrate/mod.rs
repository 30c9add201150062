//! `kalibre calibrate`: the four-step loop on a hall, with the built-in simulator,
//! OpenFOAM or any external command as the model.

mod args;
mod failed_at_bounds;
mod findings;
pub(super) mod generic;
mod journal_mismatch;
mod progress;
mod settings;
mod summary;

use std::path::Path;
use std::time::Instant;

use kalibre_core::calibrate::Report;
use kalibre_core::{Model, Observe, ParamSpace};
use kalibre_dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre_dc::calibration_model::calibrate_hall_model;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{remove_interrupted_runs, OpenFoamModel, OpenFoamSettings};
use kalibre_dc::snapshots::{self, HallSnapshot};
use kalibre_dc::surrogate::PenaltyReport;

use super::calibrated_model::{scenario_keys, CalibratedModel};
use super::hall_command::{self, HallCommand};
use super::openfoam_args::of_err;
use super::{io_err, with_threads, CliError, CliResult};
pub use args::{AlphaArg, CalibrateArgs, ModelArg};
pub(crate) use findings::busiest;
use findings::{builtin_findings, openfoam_findings};
use progress::Progress;
pub(super) use settings::{check_finer_grids, check_grid_factors};
use settings::{flag_error, settings};
use summary::{print_summary, warn_unreached, Intakes};

/// Refuses model options that do not belong to the chosen model.
fn check_model_flags(args: &CalibrateArgs) -> CliResult {
    args.openfoam
        .refuse_unless(args.model == ModelArg::Openfoam)?;
    match (args.model, &args.config) {
        (ModelArg::Command, None) => Err(CliError::Input(
            "--model command needs --config model.toml (see docs/models.md)".into(),
        )),
        (ModelArg::Builtin | ModelArg::Openfoam, Some(_)) => {
            Err(CliError::Input("--config is for --model command".into()))
        }
        (ModelArg::Command, _) if args.grid_m.is_some() => Err(CliError::Input(
            "--grid-m sets the grid of the built-in simulator or OpenFOAM; a command model \
             meshes for itself"
                .into(),
        )),
        (ModelArg::Openfoam | ModelArg::Command, _) if args.grid_check.is_some() => {
            Err(CliError::Input(
                "--grid-check runs the built-in simulator on finer grids: it needs --model \
                 builtin"
                    .into(),
            ))
        }
        (ModelArg::Openfoam | ModelArg::Command, _) if args.influence_edges => {
            Err(CliError::Input(
                "--influence-edges takes the air flow of the built-in simulator: it needs \
                 --model builtin"
                    .into(),
            ))
        }
        _ => Ok(()),
    }
}

/// What a calibration with one of the models gives: its report, the prior's report, the
/// model's fingerprints (its own first, then those earlier versions gave it:
/// [`Model::legacy_fingerprints`]) and the parameter space it searched.
type Calibrated = (Report, PenaltyReport, Vec<String>, ParamSpace);

/// Runs the calibration with the chosen model.
fn calibrate_with_model<'o>(
    args: &CalibrateArgs,
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &HallCalibrationSettings,
    journal: &Path,
    observers: Vec<Box<dyn Observe + 'o>>,
) -> CliResult<Calibrated> {
    let hall = calibrated_hall(hall, settings);
    let refused = |e: kalibre_dc::Error| match e {
        kalibre_dc::Error::OtherModelJournal {
            path,
            runs,
            first_line,
        } => match model_record(args, &hall, settings, String::new()) {
            Ok(current) => journal_mismatch::explain(
                Path::new(&path),
                (runs, first_line),
                &current,
                &hall,
                args.hall_path(),
            ),
            Err(e) => e,
        },
        e => flag_error(e.in_hall_file(&args.hall_path().display().to_string())),
    };
    match args.model {
        ModelArg::Builtin => {
            let c = calibrate_hall(&hall, snaps, settings, Some(journal), observers)
                .map_err(refused)?;
            let space = c.model.layout().space().clone();
            Ok((
                c.report,
                c.penalty_report,
                c.model.run_fingerprints(),
                space,
            ))
        }
        ModelArg::Openfoam => {
            let model = OpenFoamModel::new(
                &hall,
                args.openfoam
                    .settings(&args.out.join("openfoam"), args.grid_m)?,
            )
            .map_err(|e| of_err(e.in_hall_file(&args.hall_path().display().to_string())))?;
            super::out_dir::note_interrupted_runs(remove_interrupted_runs(
                &model.settings().cache_root,
            ));
            let c = calibrate_hall_model(
                &hall,
                snaps,
                &model,
                model.layout(),
                settings,
                Some(journal),
                observers,
            )
            .map_err(refused)?;
            let space = model.layout().space().clone();
            Ok((c.report, c.penalty_report, model.run_fingerprints(), space))
        }
        ModelArg::Command => {
            let path = args
                .config
                .as_deref()
                .expect("checked by check_model_flags");
            let model = HallCommand::new(&hall, hall_command::load_config(path)?, path)?;
            super::out_dir::note_interrupted_runs(model.command.remove_interrupted_runs());
            let c = calibrate_hall_model(
                &hall,
                snaps,
                &model,
                &model.layout,
                settings,
                Some(journal),
                observers,
            )
            .map_err(refused)?;
            let space = model.layout.space().clone();
            Ok((c.report, c.penalty_report, model.run_fingerprints(), space))
        }
    }
}

/// The hall as calibrated: its alpha mode set to `--alpha`'s when given.
fn calibrated_hall(hall: &Hall, settings: &HallCalibrationSettings) -> Hall {
    let mut hall = hall.clone();
    if let Some(mode) = settings.alpha_mode {
        hall.calibrate.alpha = mode;
    }
    hall
}

/// Refuses a hall with no parameter to calibrate (alpha `fixed` and no effect with
/// parameters) before anything runs, naming the file and the field to change.
fn refuse_nothing_to_calibrate(hall_path: &Path, calibrated: &Hall) -> CliResult {
    let effects = kalibre_dc::effects::EffectRegistry::builtin().build_all(calibrated)?;
    if kalibre_dc::ParamLayout::new(calibrated, &effects)?
        .space()
        .is_empty()
    {
        return Err(CliError::Input(format!(
            "{}: /calibrate/alpha: alpha is `fixed` and no effect has parameters, so there is \
             nothing to calibrate; expected `per_type` or `per_server` (or `kalibre calibrate \
             --alpha per-type`), or an effect with parameters (`kalibre simulate` runs the \
             hall as it is)",
            hall_path.display()
        )));
    }
    Ok(())
}

/// Says when `--out` holds the report of a calibration against other measurements:
/// this one replaces it when it ends, while the journal's runs (which do not depend on
/// the measurements) are reused. A report of these measurements (a resumed or repeated
/// calibration) is replaced without a word.
fn note_replaced_report(out: &Path, hall: &Hall, snaps: &[snapshots::HallSnapshot]) {
    let path = out.join("report.json");
    let Some(report) = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str::<kalibre_core::calibrate::Report>(&t).ok())
    else {
        return;
    };
    use super::calibrated_model::{measurement_difference, MeasurementDifference};
    let what = match measurement_difference(&report.residuals, hall, snaps) {
        MeasurementDifference::Same => return,
        MeasurementDifference::Readings(what) => what,
        MeasurementDifference::Sensor(s) => format!("sensor `{s}` is not in this hall"),
    };
    eprintln!(
        "kalibre: note: {} is a calibration against other measurements ({what}); this \
         calibration replaces it when it ends (move it away to keep it)",
        path.display()
    );
}

/// What `report.json` records of the model, for `diagnose` and `simulate` to repeat.
fn model_record(
    args: &CalibrateArgs,
    hall: &Hall,
    settings: &HallCalibrationSettings,
    fingerprint: String,
) -> CliResult<CalibratedModel> {
    let alpha = settings.alpha_mode.unwrap_or(hall.calibrate.alpha);
    let fingerprint = Some(fingerprint);
    Ok(match args.model {
        ModelArg::Builtin => CalibratedModel {
            kind: "builtin".into(),
            grid_m: Some(settings.sim.cell_m),
            alpha,
            of_iterations: None,
            np: None,
            fingerprint,
            scenario_keys: None,
        },
        ModelArg::Openfoam => {
            let of = args
                .openfoam
                .settings(&args.out.join("openfoam"), args.grid_m)?;
            CalibratedModel {
                kind: "openfoam".into(),
                grid_m: Some(of.grid_m),
                alpha,
                of_iterations: Some(of.iterations),
                np: Some(of.np),
                fingerprint,
                scenario_keys: None,
            }
        }
        ModelArg::Command => CalibratedModel {
            kind: "command".into(),
            grid_m: None,
            alpha,
            of_iterations: None,
            np: None,
            fingerprint,
            scenario_keys: None,
        },
    })
}

/// What `kalibre calibrate` writes in `--out`.
const OUT_FILES: [&str; 3] = ["runs.jsonl", "report.json", "report.html"];

/// A hall and its snapshots, both given; without them, what to give instead (a
/// `model.toml` of one's own takes `--measurements`).
fn check_hall_given(args: &CalibrateArgs) -> CliResult {
    match (&args.hall, &args.snapshots) {
        (Some(_), Some(_)) => Ok(()),
        (Some(_), None) => Err(CliError::Input(
            "--hall needs --snapshots: the operating conditions and measurements \
             (snapshots.csv) to calibrate it against"
                .into(),
        )),
        (None, Some(_)) => Err(CliError::Input(
            "--snapshots needs --hall: the hall (hall.json) they were measured in".into(),
        )),
        (None, None) if args.model == ModelArg::Command && args.config.is_some() => {
            Err(CliError::Input(
                "--model command --config without --hall calibrates a model of your own: \
                 give --measurements FILE, what was measured at its [[scenarios]] \
                 (scenario,output,value rows, docs/models.md)"
                    .into(),
            ))
        }
        (None, None) => Err(CliError::Input(
            "kalibre calibrate needs --hall and --snapshots (a hall), or --model command \
             --config model.toml --measurements FILE (a model of your own, docs/models.md)"
                .into(),
        )),
    }
}

/// Runs `kalibre calibrate`.
pub fn run(args: CalibrateArgs) -> CliResult {
    if let Some(measurements) = &args.measurements {
        return generic::run(&args, measurements);
    }
    check_hall_given(&args)?;
    let settings = settings(&args)?;
    check_model_flags(&args)?;
    let hall = Hall::load(args.hall_path())?;
    kalibre_dc::effects::EffectRegistry::builtin()
        .check_hall(&hall, &args.hall_path().display().to_string())?;
    refuse_nothing_to_calibrate(args.hall_path(), &calibrated_hall(&hall, &settings))?;
    let snaps = snapshots::load_snapshots(&hall, args.snapshots_path())?;
    super::plausible::warn_readings(args.snapshots_path(), &hall, &snaps);
    super::plausible::note_missing_readings(args.snapshots_path(), &hall, &snaps);
    super::plausible::warn_setpoints(args.snapshots_path(), &hall, snaps.iter().map(|s| &s.state));
    let states = snaps.iter().map(|s| &s.state);
    super::plausible::warn_alpha_units(args.hall_path(), &hall);
    super::plausible::warn_implausible_rises(
        args.hall_path(),
        args.snapshots_path(),
        &hall,
        states,
    )?;
    if args.model == ModelArg::Builtin {
        super::simulate::check_model_cells(
            &hall,
            args.hall_path(),
            settings.sim.cell_m,
            args.grid_m.is_some(),
        )?;
        super::plausible::warn_builtin_hall(args.hall_path(), &hall, settings.sim.cell_m);
    }
    if args.model == ModelArg::Openfoam {
        let grid_m = args.grid_m.unwrap_or(OpenFoamSettings::default().grid_m);
        super::openfoam_args::check_mesh(&hall, args.hall_path(), grid_m, args.grid_m.is_some())?;
    }
    check_finer_grids(&hall, settings.sim.cell_m, &settings.grid_check)?;
    // Held until the report is written: a second calibration here would repeat the runs.
    let _lock = super::out_dir::lock(&args.out, "--out", "calibrate")?;
    super::out_dir::check_files(
        &args.out,
        &[&OUT_FILES[..], &[super::hall_changes::RUNS_HALL]].concat(),
    )?;
    super::same_file::refuse_inputs_in_out(
        &args.out,
        &OUT_FILES,
        &[
            ("the --hall file", Some(args.hall_path())),
            ("the --snapshots file", Some(args.snapshots_path())),
            ("the --config file", args.config.as_deref()),
        ],
    )?;
    if args.model == ModelArg::Command {
        // Checked before the loop so a bad template fails at once, not per run.
        let path = args
            .config
            .as_deref()
            .expect("checked by check_model_flags");
        // The hall as the loop will run it: `--alpha` decides the parameters' names.
        let calibrated = calibrated_hall(&hall, &settings);
        let model = HallCommand::new(&calibrated, hall_command::load_config(path)?, path)?;
        model.check_snapshots(&snaps, path)?;
        if !model.unused_param_settings.is_empty() {
            eprintln!(
                "kalibre: warning: {}: the search uses the hall's bounds, initial values and \
                 scales; these [[params]] give others, which are not used: {}",
                path.display(),
                model.unused_param_settings.join("; ")
            );
        }
    }
    note_replaced_report(&args.out, &hall, &snaps);
    let journal = args.out.join("runs.jsonl");
    super::hall_changes::keep_runs_hall(&args.out, args.hall_path(), &journal)?;
    set_stop_message(&journal, args.model == ModelArg::Openfoam);
    let progress = Progress::new(
        progress::Plan {
            snapshots: snaps.len(),
            iterations: args.iterations,
            polish_iterations: settings.core.polish_iterations,
            polish_max_params: settings.polish_max_params,
            style: summary::Style::Hall,
        },
        args.quiet,
    );
    let started = Instant::now();
    let (report, penalty_report, fingerprints, space) = with_threads(args.threads, || {
        calibrate_with_model(
            &args,
            &hall,
            &snaps,
            &settings,
            &journal,
            vec![Box::new(progress)],
        )
    })??;
    let wall_s = started.elapsed().as_secs_f64();
    warn_skipped_journal_lines(&journal, &report);
    warn_unreached(&journal, &report, summary::Style::Hall);
    let failed_at_bounds = (report.runs.failed > 0)
        .then(|| {
            let bounds_in = args
                .hall
                .as_deref()
                .map_or_else(|| "hall.json".to_string(), |h| h.display().to_string());
            failed_at_bounds::clause(
                &journal,
                &fingerprints,
                &space,
                &bounds_in,
                args.replay_failed,
            )
        })
        .flatten();
    let mut report = report;
    let fingerprint = fingerprints.into_iter().next().unwrap_or_default();
    let mut record = model_record(&args, &hall, &settings, fingerprint)?;
    if args.model != ModelArg::Command {
        record.scenario_keys = Some(scenario_keys(&snaps));
    }
    report.model = Some(record.to_json());
    let report_path = args.out.join("report.json");
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| CliError::Run(format!("report.json: {e}")))?;
    kalibre_core::write_atomic(&report_path, json).map_err(|e| io_err(&report_path, e))?;
    let html_path = args.out.join("report.html");
    let mut fluctuation = None;
    let (intakes, warming) = match args.model {
        ModelArg::Builtin => {
            let found = builtin_findings(&hall, &snaps, &settings, &report)?;
            (Some(found.intakes), Some(found.warming))
        }
        // OpenFOAM's flow is not the built-in model's: its own intakes, and no attribution.
        ModelArg::Openfoam => {
            let found = openfoam_findings(&args, &hall, &snaps, &settings, &report, &journal)?;
            fluctuation = found.fluctuation;
            (found.intakes, None)
        }
        // A command model gives its sensors' readings only.
        ModelArg::Command => (None, None),
    };
    let html = kalibre_dc::report::calibration_html(
        &hall,
        &snaps,
        &report,
        &penalty_report,
        intakes.as_deref(),
        warming.as_deref(),
    );
    let intakes = intakes.map(|checks| Intakes {
        checks,
        under_read: kalibre_dc::sim::coldest_under_read(&hall, &report.residuals),
    });
    kalibre_core::write_atomic(&html_path, html).map_err(|e| io_err(&html_path, e))?;
    let locations = kalibre_dc::report::effect_locations(&hall);
    print_summary(
        &report,
        wall_s,
        summary::Style::Hall,
        Some(summary::HallFacts {
            penalty: &penalty_report,
            intakes: intakes.as_ref(),
            locations: &locations,
        }),
        fluctuation.as_ref().map(|f| f.describe()).as_deref(),
        failed_at_bounds.as_deref(),
    );
    if let Some(f) = &fluctuation {
        f.warn_if_unsteady(report.best.mae_c);
    }
    println!(
        "wrote {}, {}, {}",
        report_path.display(),
        journal.display(),
        html_path.display()
    );
    Ok(())
}

/// Journal lines the calibration could not read or did not replay (and whose runs, if
/// any, it did again): said on stderr, not only in `report.json`'s `journal`.
fn warn_skipped_journal_lines(journal: &Path, report: &kalibre_core::calibrate::Report) {
    let Some(load) = &report.journal else {
        return;
    };
    let count = load.bad_lines.len() + usize::from(load.torn_tail.is_some());
    if let Some(first) = load.bad_lines.first().or(load.torn_tail.as_ref()) {
        eprintln!(
            "kalibre: warning: {}: {count} unreadable line(s) skipped (line {}: {}{}); see \
             `journal` in report.json",
            journal.display(),
            first.line,
            first.reason,
            if count > 1 { ", ..." } else { "" }
        );
    }
    if load.failed_to_retry > 0 {
        eprintln!(
            "note: {}: {} run(s) journaled only as failed were not replayed (a failure's \
             cause may have passed); each ran again where the calibration asked for it \
             (--replay-failed replays them as failures)",
            journal.display(),
            load.failed_to_retry
        );
    }
    if load.failed_replayed > 0 {
        eprintln!(
            "note: {}: {} run(s) journaled only as failed are replayed as failures where the \
             calibration asks for them (--replay-failed), not run again",
            journal.display(),
            load.failed_replayed
        );
    }
    if let Some(first) = load.conflicts.first() {
        eprintln!(
            "kalibre: warning: {}: line {} {}{}; one of the two is wrong (an edited or merged \
             journal?)",
            journal.display(),
            first.line,
            first.reason,
            match load.conflicts.len() {
                1 => String::new(),
                n => format!(" ({} more such lines)", n - 1),
            }
        );
    }
}

/// What Ctrl-C (or a kill) says: where the finished runs are, and that the same command
/// resumes from them (once per process: the texts live as long as it). With OpenFOAM what
/// it ends may be a mesh being built rather than a solve; the next command sweeps that.
pub(in crate::cli) fn set_stop_message(journal: &Path, openfoam: bool) {
    let kept = format!(
        "kept in {}: the same command resumes from there, repeating no successful run",
        journal.display()
    );
    let in_progress = match openfoam {
        true => "the OpenFOAM solves or meshing in progress were",
        false => "the model runs in progress were",
    };
    let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
    kalibre_core::external::set_stop_message(kalibre_core::external::StopMessage {
        runs_ended: leak(format!(
            "kalibre: stopped; {in_progress} ended with it; finished runs are {kept}\n"
        )),
        no_runs: leak(format!(
            "kalibre: stopped; finished model runs are {kept}\n"
        )),
    });
}
