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

use super::super::own_model;
use super::super::simulate::refuse_given;
use super::super::{io_err, significant, with_threads, CliError, CliResult};
use super::progress::{Plan, Progress};
use super::summary::{held_at_bounds, print_summary, Style};
use super::{CalibrateArgs, ModelArg};

/// What a calibration of a model of your own writes in `--out`.
const OUT_FILES: [&str; 3] = ["runs.jsonl", "report.json", MODEL_PARTS];

/// Beside the journal: the digest of each part of the model's fingerprint, so that a
/// later command of another fingerprint is told which parts changed.
pub(in crate::cli) const MODEL_PARTS: &str = "model-parts.json";

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
        let add = if args.config.is_some() {
            "--model command"
        } else {
            "--model command --config model.toml"
        };
        return Err(CliError::Input(format!(
            "--measurements calibrates a model of your own: add {add} (docs/models.md); a \
             hall takes --hall and --snapshots"
        )));
    }
    let Some(config) = args.config.as_deref() else {
        return Err(CliError::Input(
            "--model command needs --config model.toml (see docs/models.md)".into(),
        ));
    };
    own_model::refuse_openfoam_flags(&args.openfoam)?;
    refuse_hall_flags(args)?;
    let settings = super::settings::settings(args)?;
    let cfg = own_model::load_config(
        config,
        ": a model of your own is calibrated against measurements of its scenarios, each a \
         `label` and its `variables` (docs/models.md)",
    )?;
    own_model::warn_unwritten_params(config, &cfg);
    if !cfg.candidates.is_empty() && cfg.space.params().iter().all(|p| p.is_fixed()) {
        return Err(CliError::Input(format!(
            "{}: every [[params]] is a candidate effect (`absent`) or fixed (equal bounds): \
             calibrate at least one; delete a candidate's `absent` (and `effect`) to \
             calibrate it",
            config.display()
        )));
    }
    let observations = observations(&cfg, measurements)?;
    let scaled = observations.scales().is_some();
    let style = Style::Generic { scaled };
    let _lock = super::super::out_dir::lock(&args.out, "--out", "calibrate")?;
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
    // The Gaussian process's own loop (`Settings::recommended_for_gaussian_process`
    // says why): no focus weights, no noisy copies of the design runs.
    let gp = kalibre_core::Settings::recommended_for_gaussian_process();
    core.focus = gp.focus;
    core.augment_copies = gp.augment_copies;
    if space.dim() > settings.polish_max_params {
        core.polish_iterations = 0;
    }
    let progress = Progress::new(
        Plan {
            snapshots: observations.snapshots().len(),
            iterations: args.iterations,
            polish_iterations: core.polish_iterations,
            polish_max_params: settings.polish_max_params,
            style,
        },
        args.quiet,
    );
    let started = Instant::now();
    let (report, per_output) = with_threads(args.threads, || {
        let mut calibrator = Calibrator::new(
            &cfg.command,
            GaussianProcess::new(space.clone()),
            &observations,
            space,
        )
        .with_settings(core)
        .with_searcher(settings.searcher.clone())
        .with_store(store)
        .with_observer(move |e: &kalibre_core::Event<'_>| progress.observe(e));
        let report = calibrator.run()?;
        let per_output = calibrator
            .store()
            .map(|store| per_output_errors(&cfg, &observations, store, &report));
        Ok((report, per_output.flatten()))
    })?
    .map_err(|e| match e {
        kalibre_core::Error::InvalidSetting { name, reason } => super::settings::flag_error(
            kalibre_dc::Error::Core(kalibre_core::Error::InvalidSetting { name, reason }),
        ),
        e => CliError::Run(e.to_string()),
    })?;
    let wall_s = started.elapsed().as_secs_f64();
    super::warn_skipped_journal_lines(&journal, &report);
    super::summary::warn_unreached(&journal, &report, style);
    let failed_at_bounds = (report.runs.failed > 0)
        .then(|| {
            super::failed_at_bounds::clause(
                &journal,
                &[cfg.command.fingerprint()],
                space,
                &format!("{}'s [[params]]", config.display()),
                args.replay_failed,
            )
        })
        .flatten();
    let mut report = report;
    report.model = Some(serde_json::json!({
        "kind": "command",
        "config": config.display().to_string(),
        "fingerprint": cfg.command.fingerprint(),
        "errors_in": errors_in(scaled),
        "per_output": per_output.as_deref().map(per_output_json),
        // Held absent: what a diagnosis of this calibration may test.
        "candidates": (cfg.candidates.iter())
            .flat_map(|c| c.params.iter().map(|p| (p.name.clone(), serde_json::json!(p.absent))))
            .collect::<serde_json::Map<String, serde_json::Value>>(),
    }));
    let report_path = args.out.join("report.json");
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| CliError::Run(format!("report.json: {e}")))?;
    kalibre_core::write_atomic(&report_path, json).map_err(|e| io_err(&report_path, e))?;
    print_summary(
        &report,
        wall_s,
        style,
        None,
        None,
        failed_at_bounds.as_deref(),
    );
    if let Some(line) = held_at_bounds(&report, &cfg.space) {
        println!("{line}");
    }
    if let Some(rows) = &per_output {
        print_per_output(rows);
    }
    if !cfg.candidates.is_empty() {
        let names: Vec<&str> = cfg.candidates.iter().map(|c| c.name.as_str()).collect();
        let (effects, are, them) = if names.len() == 1 {
            ("candidate effect", "is", "it")
        } else {
            ("candidate effects", "are", "them")
        };
        println!(
            "  {effects} {} {are} held absent; whether the data want {them}: kalibre \
             diagnose --model command --config {} --measurements {} --calibration {}",
            names.join(", "),
            super::super::shell_word(config),
            super::super::shell_word(measurements),
            super::super::shell_word(&args.out)
        );
    }
    println!("wrote {}, {}", report_path.display(), journal.display());
    Ok(())
}

/// What `report.json`'s `model.errors_in` says the errors are in: sd units with an `sd`
/// column (`scaled`), else the outputs' own.
pub(in crate::cli) fn errors_in(scaled: bool) -> &'static str {
    if scaled {
        "sd"
    } else {
        "outputs' units"
    }
}

/// One output's error at the best parameters, in its own units.
struct OutputError {
    name: String,
    mae: f64,
    max_abs: f64,
    measured: usize,
}

/// Each measured output's error at the report's best parameters, in the output's own
/// units, from the journal's runs there; `None` if a run there is missing or failed.
fn per_output_errors(
    cfg: &CommandModelConfig,
    observations: &Observations<NamedScenario>,
    store: &RunStore,
    report: &kalibre_core::calibrate::Report,
) -> Option<Vec<OutputError>> {
    let names = cfg.space.names();
    let params = report.best.params.values();
    let mut sums: Vec<(f64, f64, usize)> = vec![(0.0, 0.0, 0); observations.outputs().len()];
    for snap in observations.snapshots() {
        let key = cfg.command.scenario_key(&snap.scenario);
        let (_, rec) = store.get_keyed(&snap.label, &key, &names, &params)?;
        let outputs = rec.result().ok()?;
        for ((m, v), acc) in snap.measured.iter().zip(&outputs.values).zip(&mut sums) {
            if let Some(m) = m {
                let e = (v - m).abs();
                *acc = (acc.0 + e, acc.1.max(e), acc.2 + 1);
            }
        }
    }
    Some(
        (observations.outputs().iter())
            .zip(sums)
            .filter(|(_, (_, _, n))| *n > 0)
            .map(|(o, (sum, max_abs, n))| OutputError {
                name: o.name.clone(),
                mae: sum / n as f64,
                max_abs,
                measured: n,
            })
            .collect(),
    )
}

/// The outputs the summary's table shows; `report.json` has them all.
const PER_OUTPUT_SHOWN: usize = 20;

/// The per-output table of the summary: outputs in different units each in their own.
fn print_per_output(rows: &[OutputError]) {
    println!("  at the best parameters, each output in its own units:");
    println!(
        "    {:<24} {:>12} {:>12} {:>9}",
        "output", "MAE", "max abs", "measured"
    );
    for r in rows.iter().take(PER_OUTPUT_SHOWN) {
        println!(
            "    {:<24} {:>12} {:>12} {:>9}",
            r.name,
            significant(r.mae, 4),
            significant(r.max_abs, 4),
            r.measured
        );
    }
    if rows.len() > PER_OUTPUT_SHOWN {
        println!(
            "    ... and {} more (report.json, model.per_output)",
            rows.len() - PER_OUTPUT_SHOWN
        );
    }
}

/// The per-output errors as `report.json` keeps them.
fn per_output_json(rows: &[OutputError]) -> serde_json::Value {
    rows.iter()
        .map(|r| {
            serde_json::json!({
                "output": r.name,
                "mae": r.mae,
                "max_abs": r.max_abs,
                "measured": r.measured,
            })
        })
        .collect()
}

/// The measurements of `cfg`'s scenarios: those with no row are left out (and said so),
/// as are outputs measured nowhere (noted).
pub(in crate::cli) fn observations(
    cfg: &CommandModelConfig,
    measurements: &Path,
) -> CliResult<Observations<NamedScenario>> {
    let labels: Vec<String> = cfg.scenarios.iter().map(|s| s.label.clone()).collect();
    let outputs = cfg.command.output_names().to_vec();
    let read = kalibre_dc::snapshots::load_measurements(measurements, &labels, &outputs)?;
    let measured = read.values;
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
    let in_file =
        |e: kalibre_core::Error| CliError::Input(format!("{}: {e}", measurements.display()));
    let observations = Observations::new_called("scenario", infos, snapshots).map_err(in_file)?;
    match read.sd {
        None => {
            if let Some(note) = mixed_sizes_note(&observations) {
                eprintln!("kalibre: note: {}: {note}", measurements.display());
            }
            Ok(observations)
        }
        Some(sd) => observations
            .with_scales(scales(&sd, outputs.len()))
            .map_err(in_file),
    }
}

/// How far apart the outputs' typical sizes must be for the summary to say that the
/// largest will decide the fit.
const MIXED_SIZES_RATIO: f64 = 100.0;

/// Said when the measured outputs differ in size by [`MIXED_SIZES_RATIO`] or more and
/// no `sd` column weighs them: unweighted, the largest outputs' errors decide the fit.
fn mixed_sizes_note(observations: &Observations<NamedScenario>) -> Option<String> {
    let sizes: Vec<(&str, f64)> = (observations.outputs().iter().enumerate())
        .filter_map(|(k, o)| {
            let values: Vec<f64> = (observations.snapshots().iter())
                .filter_map(|s| s.measured[k])
                .map(f64::abs)
                .collect();
            let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
            (mean > 0.0).then_some((o.name.as_str(), mean))
        })
        .collect();
    let cmp = |a: &&(&str, f64), b: &&(&str, f64)| a.1.total_cmp(&b.1);
    let small = sizes.iter().min_by(cmp)?;
    let large = sizes.iter().max_by(cmp)?;
    (large.1 >= MIXED_SIZES_RATIO * small.1).then(|| {
        format!(
            "the outputs differ in size by {:.0}x (`{}` about {}, `{}` about {}): the loop \
             minimises the error over every output alike, so the largest outputs decide the \
             fit. Give each measurement's standard uncertainty in an `sd` column \
             (`scenario,output,value,sd`, docs/models.md) to weigh them by it",
            large.1 / small.1,
            large.0,
            significant(large.1, 4),
            small.0,
            significant(small.1, 4)
        )
    })
}

/// The loop's scales from the file's `sd` column, for the scenarios measured: each
/// measurement's own, and where an output is not measured in a scenario (its residual
/// never counts there), the mean of that output's sds elsewhere, so that the surrogate
/// sees its runs on the same scale.
fn scales(sd: &kalibre_dc::snapshots::ScenarioMeasurements, n_outputs: usize) -> Vec<Vec<f64>> {
    let rows: Vec<&Vec<Option<f64>>> = sd.iter().flatten().collect();
    let typical: Vec<f64> = (0..n_outputs)
        .map(|k| {
            let given: Vec<f64> = rows.iter().filter_map(|r| r[k]).collect();
            if given.is_empty() {
                1.0
            } else {
                given.iter().sum::<f64>() / given.len() as f64
            }
        })
        .collect();
    rows.iter()
        .map(|r| {
            r.iter()
                .zip(&typical)
                .map(|(v, t)| v.unwrap_or(*t))
                .collect()
        })
        .collect()
}

/// The run journal, refused when it holds runs of another model: the command's program,
/// arguments, templates, outputs, parameters or fingerprint files changed since.
pub(in crate::cli) fn open_journal(
    journal: &Path,
    cfg: &CommandModelConfig,
    config: &Path,
    replay_failed: bool,
) -> CliResult<RunStore> {
    let fingerprint = cfg.command.fingerprint();
    let store = RunStore::open_with(journal, fingerprint.clone(), replay_failed)
        .map_err(|e| CliError::Input(e.to_string()))?;
    let parts_path = journal.with_file_name(MODEL_PARTS);
    let other = store.load_report().other_fingerprint;
    if other > 0 {
        let what = changed_since(&parts_path, cfg).unwrap_or_else(|| {
            "its program, arguments, templates, outputs, parameters, or a file of \
             fingerprint_files changed since they ran"
                .to_string()
        });
        return Err(CliError::Input(format!(
            "{}: holds {other} runs of another model than {}: {what}. Calibrate into another \
             --out, or move the journal away to run them anew",
            journal.display(),
            config.display()
        )));
    }
    let record = serde_json::json!({
        "fingerprint": fingerprint,
        "parts": cfg.command.fingerprint_parts().iter()
            .map(|(n, d)| serde_json::json!({ "part": n, "digest": d }))
            .collect::<Vec<_>>(),
    });
    let text = serde_json::to_string_pretty(&record)
        .map_err(|e| CliError::Run(format!("{}: {e}", parts_path.display())))?;
    kalibre_core::write_atomic(&parts_path, text + "\n").map_err(|e| io_err(&parts_path, e))?;
    Ok(store)
}

/// What changed in `cfg`'s model since the runs of `model-parts.json` (`parts_path`)
/// ran, in words (`since they ran, these changed: the program, hx.py`); `None` when it
/// is not recorded or nothing differs.
pub(in crate::cli) fn changed_since(parts_path: &Path, cfg: &CommandModelConfig) -> Option<String> {
    let (then, parts) = recorded_parts(parts_path)?;
    if then == cfg.command.fingerprint() {
        return None;
    }
    let changed = kalibre_core::external::changed_parts(&parts, cfg.command.fingerprint_parts());
    (!changed.is_empty()).then(|| {
        let named: Vec<String> = changed.iter().map(|c| part_in_words(c)).collect();
        format!("since they ran, these changed: {}", named.join(", "))
    })
}

/// The fingerprint and parts `model-parts.json` recorded, if it is there and readable
/// (a journal from before it was written has none: the message is then the general one).
fn recorded_parts(path: &Path) -> Option<(String, Vec<(String, String)>)> {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    let fingerprint = json["fingerprint"].as_str()?.to_string();
    let parts = (json["parts"].as_array()?.iter())
        .map(|p| {
            Some((
                p["part"].as_str()?.to_string(),
                p["digest"].as_str()?.to_string(),
            ))
        })
        .collect::<Option<Vec<_>>>()?;
    Some((fingerprint, parts))
}

/// A fingerprint part as the refusal names it.
fn part_in_words(part: &str) -> String {
    match part {
        "program" => "the program".into(),
        "args" => "the arguments".into(),
        "env" => "the environment".into(),
        "output" => "the output (file, parser or names)".into(),
        "params" => "the parameters' names or their order".into(),
        // `template SOURCE`, or a fingerprint file by its path: as named.
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn observations(rows: &[[Option<f64>; 2]]) -> Observations<NamedScenario> {
        let outputs = ["t_end_c", "q_loss_wh"]
            .iter()
            .map(|n| OutputInfo {
                name: n.to_string(),
                group: String::new(),
            })
            .collect();
        let snapshots = (rows.iter().enumerate())
            .map(|(i, r)| Snapshot {
                label: format!("s{i}"),
                scenario: NamedScenario::new(format!("s{i}")),
                measured: r.to_vec(),
            })
            .collect();
        Observations::new(outputs, snapshots).unwrap()
    }

    #[test]
    fn outputs_of_very_different_sizes_are_noted_by_name() {
        let mixed = observations(&[[Some(18.0), Some(5000.0)], [Some(-19.0), Some(22000.0)]]);
        let note = mixed_sizes_note(&mixed).expect("a note");
        assert!(
            note.contains("differ in size by 730x")
                && note.contains("`q_loss_wh` about 13500")
                && note.contains("`t_end_c` about 18.50")
                && note.contains("an `sd` column"),
            "{note}"
        );
        let alike = observations(&[[Some(18.0), Some(1000.0)], [Some(20.0), None]]);
        assert_eq!(mixed_sizes_note(&alike), None);
        let one_measured = observations(&[[Some(18.0), None]]);
        assert_eq!(mixed_sizes_note(&one_measured), None);
    }

    #[test]
    fn unmeasured_outputs_take_their_typical_sd() {
        let sd = vec![
            Some(vec![Some(0.5), None]),
            None,
            Some(vec![Some(1.5), Some(200.0)]),
        ];
        assert_eq!(scales(&sd, 2), vec![vec![0.5, 200.0], vec![1.5, 200.0]]);
        let none_given = vec![Some(vec![Some(0.5), None])];
        assert_eq!(scales(&none_given, 2), vec![vec![0.5, 1.0]]);
    }
}
