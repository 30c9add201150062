//! `kalibre calibrate --model command --config model.toml --measurements FILE`: the loop on
//! a model of your own, not a hall. The model is the external command of `model.toml`
//! with its `[[scenarios]]` and `[[params]]`; the measurements are `measurements.csv`
//! (`scenario,output,value`); the surrogate is a Gaussian process
//! ([`kalibre_core::GaussianProcess`]), since nothing is known of the model's form.
//! Runs are journaled in `OUT/runs.jsonl` and resumed as a hall's are.

use std::path::Path;
use std::time::Instant;

use kalibre_core::external::{CommandModelConfig, NamedScenario};
use kalibre_core::{
    Calibrator, GaussianProcess, Model, Observations, Observe, OutputInfo, RunStore, Snapshot,
};

use super::super::simulate::refuse_given;
use super::super::{io_err, with_threads, CliError, CliResult};
use super::progress::{Plan, Progress};
use super::summary::{print_summary, Style};
use super::{CalibrateArgs, ModelArg};

/// What a calibration of a model of your own writes in `--out`.
const OUT_FILES: [&str; 2] = ["runs.jsonl", "report.json"];

/// Flags that describe a hall, its built-in simulator or its surrogate: refused here
/// rather than ignored.
fn refuse_hall_flags(args: &CalibrateArgs) -> CliResult {
    let given = [
        ("--grid-m", args.grid_m.is_some()),
        ("--grid-check", args.grid_check.is_some()),
        ("--no-grid-check", args.no_grid_check),
        ("--no-grid-weighting", args.no_grid_weighting),
        ("--alpha", args.alpha.is_some()),
        ("--trainable-adjacency", args.trainable_adjacency),
        ("--paper-surrogate", args.paper_surrogate),
        ("--local-recirculation", args.local_recirculation),
        ("--influence-edges", args.influence_edges),
        ("--epochs", args.epochs.is_some()),
        ("--rise-weight", args.rise_weight.is_some()),
        ("--rise-range", args.rise_range.is_some()),
    ];
    refuse_given(&given, |flag| {
        format!(
            "{flag} is about a hall (its simulator, surrogate or servers); --measurements \
             calibrates a model of your own"
        )
    })?;
    if args.focus.is_some() {
        return Err(CliError::Input(
            "--focus weighs a hall surrogate's runs; the Gaussian process of --measurements \
             weighs every run alike"
                .into(),
        ));
    }
    Ok(())
}

/// Runs the generic calibration.
pub(super) fn run(args: &CalibrateArgs, measurements: &Path) -> CliResult {
    if args.model != ModelArg::Command {
        return Err(CliError::Input(
            "--measurements calibrates a model of your own: add --model command --config \
             model.toml (docs/models.md); a hall takes --hall and --snapshots"
                .into(),
        ));
    }
    let Some(config) = args.config.as_deref() else {
        return Err(CliError::Input(
            "--model command needs --config model.toml (see docs/models.md)".into(),
        ));
    };
    args.openfoam.refuse_unless(false)?;
    refuse_hall_flags(args)?;
    let settings = super::settings::settings(args)?;
    let cfg = CommandModelConfig::load(config).map_err(|e| CliError::Input(e.to_string()))?;
    cfg.command
        .check_program()
        .map_err(|e| CliError::Input(format!("{}: {e}", config.display())))?;
    if cfg.scenarios.is_empty() {
        return Err(CliError::Input(format!(
            "{}: no [[scenarios]]: a model of your own is calibrated against measurements \
             of its scenarios, each a `label` and its `variables` (docs/models.md)",
            config.display()
        )));
    }
    let observations = observations(&cfg, measurements)?;
    let _lock = super::super::out_dir::lock(&args.out, "calibrate")?;
    super::super::out_dir::check_files(&args.out, &OUT_FILES)?;
    super::super::same_file::refuse_inputs_in_out(
        &args.out,
        &OUT_FILES,
        &[
            ("the --config file", Some(config)),
            ("the --measurements file", Some(measurements)),
        ],
    )?;
    super::super::out_dir::note_interrupted_runs(cfg.command.remove_interrupted_runs());
    let journal = args.out.join("runs.jsonl");
    super::set_stop_message(&journal, false);
    let store = open_journal(&journal, &cfg, config, settings.replay_failed)?;
    let space = &cfg.space;
    let mut core = settings.core.clone();
    core.regularizer_weight = 0.0;
    // The Gaussian process weighs every run alike (its docs say why): no focus weights.
    core.focus = None;
    // The noisy copies of the design runs help a graph learn its form; to a Gaussian
    // process they are flat plateaus around each run that cost its fit (cubic in the
    // samples) and teach it nothing.
    core.augment_copies = 1;
    if space.dim() > settings.polish_max_params {
        core.polish_iterations = 0;
    }
    let progress = Progress::new(
        Plan {
            snapshots: observations.snapshots().len(),
            iterations: args.iterations,
            polish_iterations: core.polish_iterations,
            polish_max_params: settings.polish_max_params,
            style: Style::Generic,
        },
        args.quiet,
    );
    let started = Instant::now();
    let report = with_threads(args.threads, || {
        Calibrator::new(
            &cfg.command,
            GaussianProcess::new(space.clone()),
            &observations,
            space,
        )
        .with_settings(core)
        .with_searcher(settings.searcher.clone())
        .with_store(store)
        .with_observer(move |e: &kalibre_core::Event<'_>| progress.observe(e))
        .run()
    })?
    .map_err(|e| match e {
        kalibre_core::Error::InvalidSetting { name, reason } => super::settings::flag_error(
            kalibre_dc::Error::Core(kalibre_core::Error::InvalidSetting { name, reason }),
        ),
        e => CliError::Run(e.to_string()),
    })?;
    let wall_s = started.elapsed().as_secs_f64();
    super::warn_skipped_journal_lines(&journal, &report);
    super::summary::warn_unreached(&journal, &report, Style::Generic);
    let failed_at_bounds = (report.runs.failed > 0)
        .then(|| {
            super::failed_at_bounds::clause(
                &journal,
                &cfg.command.fingerprint(),
                space,
                args.replay_failed,
            )
        })
        .flatten();
    let mut report = report;
    report.model = Some(serde_json::json!({
        "kind": "command",
        "config": config.display().to_string(),
        "fingerprint": cfg.command.fingerprint(),
    }));
    let report_path = args.out.join("report.json");
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| CliError::Run(format!("report.json: {e}")))?;
    kalibre_core::write_atomic(&report_path, json).map_err(|e| io_err(&report_path, e))?;
    print_summary(
        &report,
        wall_s,
        Style::Generic,
        None,
        None,
        None,
        failed_at_bounds.as_deref(),
    );
    println!("wrote {}, {}", report_path.display(), journal.display());
    Ok(())
}

/// The measurements of `cfg`'s scenarios: those with no row are left out (and said so),
/// as are outputs measured nowhere (noted).
fn observations(
    cfg: &CommandModelConfig,
    measurements: &Path,
) -> CliResult<Observations<NamedScenario>> {
    let labels: Vec<String> = cfg.scenarios.iter().map(|s| s.label.clone()).collect();
    let outputs = cfg.command.output_names().to_vec();
    let measured = kalibre_dc::snapshots::load_measurements(measurements, &labels, &outputs)?;
    let unmeasured: Vec<String> = labels
        .iter()
        .zip(&measured)
        .filter(|(_, m)| m.is_none())
        .map(|(l, _)| l.clone())
        .collect();
    if !unmeasured.is_empty() {
        eprintln!(
            "kalibre: note: {}: no measurement of scenario(s) {}: the model is not run there",
            measurements.display(),
            kalibre_core::some_names(&unmeasured)
        );
    }
    let snapshots: Vec<Snapshot<NamedScenario>> = cfg
        .scenarios
        .iter()
        .zip(measured)
        .filter_map(|(scenario, m)| {
            m.map(|measured| Snapshot {
                label: scenario.label.clone(),
                scenario: scenario.clone(),
                measured,
            })
        })
        .collect();
    let nowhere: Vec<String> = outputs
        .iter()
        .enumerate()
        .filter(|(k, _)| snapshots.iter().all(|s| s.measured[*k].is_none()))
        .map(|(_, n)| n.clone())
        .collect();
    if !nowhere.is_empty() {
        eprintln!(
            "kalibre: note: {}: output(s) {} measured in no scenario: they do not count",
            measurements.display(),
            kalibre_core::some_names(&nowhere)
        );
    }
    let infos = outputs
        .iter()
        .map(|name| OutputInfo {
            name: name.clone(),
            group: String::new(),
        })
        .collect();
    Observations::new(infos, snapshots)
        .map_err(|e| CliError::Input(format!("{}: {e}", measurements.display())))
}

/// The run journal, refused when it holds runs of another model: the command's program,
/// arguments, templates, outputs, parameters or fingerprint files changed since.
fn open_journal(
    journal: &Path,
    cfg: &CommandModelConfig,
    config: &Path,
    replay_failed: bool,
) -> CliResult<RunStore> {
    let fingerprint = cfg.command.fingerprint();
    let store = RunStore::open_with(journal, fingerprint, replay_failed)
        .map_err(|e| CliError::Input(e.to_string()))?;
    let other = store.load_report().other_fingerprint;
    if other > 0 {
        return Err(CliError::Input(format!(
            "{}: holds {other} runs of another model: {} (its program, arguments, \
             templates, outputs, parameters, or a file of fingerprint_files) changed since \
             they ran. Calibrate into another --out, or move the journal away to run them \
             anew",
            journal.display(),
            config.display()
        )));
    }
    Ok(store)
}
