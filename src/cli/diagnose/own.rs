//! `kalibre diagnose --model command --config model.toml --measurements FILE
//! --calibration DIR`: which of a model of your own's candidate effects (its `[[params]]`
//! with `absent`) the data want, at the calibration's parameters. The model is linearised
//! by its own runs, through the calibration's journal: a run already there is read, and
//! each new one is kept, so a recalibration with the effect added starts from them.

use std::path::Path;

use kalibre_core::calibrate::{Report, REPORT_SCHEMA};
use kalibre_core::diagnose::{
    diagnose, linearise, DiagnoseSettings, Diagnosis, HypothesisResult, LineariseSettings,
    CLOSE_ALTERNATIVE_BIC,
};
use kalibre_core::external::{CommandModelConfig, NamedScenario};
use kalibre_core::{Model, Observations};

use super::super::calibrate::generic::{observations, open_journal};
use super::super::params_file::load_params;
use super::super::{own_model, significant, with_threads, CliError, CliResult};
use super::DiagnoseArgs;

/// Flags about a hall, its simulator or OpenFOAM: refused rather than ignored.
fn refuse_hall_flags(args: &DiagnoseArgs) -> CliResult {
    let given = [
        ("--hall", args.hall.is_some()),
        ("--snapshots", args.snapshots.is_some()),
        ("--grid-m", args.grid_m.is_some()),
        ("--no-model-form", args.no_model_form),
        ("--write-hall", args.write_hall.is_some()),
        ("--refit", args.refit > 0),
    ];
    super::super::simulate::refuse_given(&given, |flag| {
        format!(
            "{flag} is about a hall; --model command diagnoses a model of your own by its \
             candidate effects ([[params]] with `absent` in model.toml)"
        )
    })?;
    own_model::refuse_openfoam_flags(&args.openfoam)
}

/// Runs the diagnosis of a model of your own.
pub(super) fn run(args: &DiagnoseArgs) -> CliResult {
    refuse_hall_flags(args)?;
    let (Some(config), Some(measurements)) = (args.config.as_deref(), args.measurements.as_deref())
    else {
        return Err(CliError::Input(
            "--model command diagnoses a model of your own: give --config model.toml and \
             --measurements FILE, the ones it was calibrated with (docs/models.md)"
                .into(),
        ));
    };
    let cfg = own_model::load_config(
        config,
        ": a model of your own is diagnosed at the scenarios it was calibrated on",
    )?;
    if cfg.candidates.is_empty() {
        return Err(CliError::Input(format!(
            "{}: no candidate effect to test: give a [[params]] entry `absent = VALUE` (the \
             value at which its effect is absent; calibrate holds it there), calibrate \
             again, then diagnose (docs/models.md)",
            config.display()
        )));
    }
    let obs = observations(&cfg, measurements)?;
    let report_path = args.calibration.join("report.json");
    let (report, params) = read_report(&report_path, &cfg, config)?;
    check_same_measurements(&report_path, &report, &obs, measurements)?;
    let settings = DiagnoseSettings::new()
        .with_single_output_check(!args.no_single_output_check)
        .with_robust_nu(args.likelihood.robust_nu(args.nu)?);
    let settings = DiagnoseSettings {
        ambiguity_check: !args.no_ambiguity_check,
        sensor_bias_rival_bic: args.sensor_bias_rival,
        ..settings
    };
    let _lock = super::super::out_dir::lock(&args.calibration, "diagnose")?;
    super::super::out_dir::note_interrupted_runs(cfg.command.remove_interrupted_runs());
    let journal = args.calibration.join("runs.jsonl");
    let store = open_journal(&journal, &cfg, config, false)?;
    let planned = obs.snapshots().len()
        * (1 + (cfg.space.params().iter())
            .filter(|p| !p.is_fixed())
            .count()
            + cfg.candidates.iter().map(|c| c.params.len()).sum::<usize>());
    eprintln!(
        "diagnosing {} candidate effect(s) of {}: up to {planned} model runs ({} scenarios x \
         (the calibrated point, a step of each calibrated parameter and of each candidate's)), \
         through {}",
        cfg.candidates.len(),
        config.display(),
        obs.snapshots().len(),
        journal.display()
    );
    let lin = with_threads(args.threads, || {
        linearise(
            &cfg.command,
            &obs,
            &cfg.space,
            &params,
            &cfg.candidates,
            &store,
            &LineariseSettings::default(),
        )
    })?
    .map_err(|e| CliError::Run(e.to_string()))?;
    let d = diagnose(&lin.residuals, &lin.hypotheses, &settings)
        .map_err(|e| CliError::Run(format!("diagnosis of {}: {e}", config.display())))?;
    let scaled = obs.scales().is_some();
    if args.json {
        let doc = serde_json::json!({
            "model": { "kind": "command", "config": config.display().to_string(),
                       "fingerprint": cfg.command.fingerprint(),
                       "errors_in": if scaled { "sd" } else { "outputs' units" } },
            "diagnosis": d,
            "not_tried": lin.not_tried.iter()
                .map(|(name, why)| serde_json::json!({ "candidate": name, "reason": why }))
                .collect::<Vec<_>>(),
            "runs": { "new": lin.runs, "from_journal": lin.cached },
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&doc).map_err(|e| CliError::Run(format!("JSON: {e}")))?
        );
        return Ok(());
    }
    print_text(&d, &cfg, config, &lin.not_tried, scaled, settings.robust_nu);
    println!(
        "\n{} model runs, {} read from {}",
        lin.runs,
        lin.cached,
        journal.display()
    );
    Ok(())
}

/// The calibration's report and its best parameters, refused when it is of another model
/// than `cfg` (its fingerprint recorded otherwise) or not a calibration of one's own.
fn read_report(
    report_path: &Path,
    cfg: &CommandModelConfig,
    config: &Path,
) -> CliResult<(Report, Vec<f64>)> {
    let file = report_path.display();
    let text = std::fs::read_to_string(report_path)
        .map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    let json: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| CliError::Input(format!("{file}: not valid JSON: {e}")))?;
    let report: Report = serde_json::from_value(json.clone())
        .map_err(|e| CliError::Input(format!("{file}: not a kalibre report: {e}")))?;
    if report.schema != REPORT_SCHEMA {
        return Err(CliError::Input(format!(
            "{file}: /schema: expected \"{REPORT_SCHEMA}\", found \"{}\"",
            report.schema
        )));
    }
    let kind = json.pointer("/model/kind").and_then(|k| k.as_str());
    if kind != Some("command") || json.pointer("/model/config").is_none() {
        return Err(CliError::Input(format!(
            "{file}: /model: not a calibration of a model of your own (kind {}); diagnose a \
             hall's with --hall and --snapshots",
            kind.map_or("not recorded".to_string(), |k| format!("`{k}`"))
        )));
    }
    let recorded = json.pointer("/model/fingerprint").and_then(|f| f.as_str());
    if recorded != Some(cfg.command.fingerprint().as_str()) {
        return Err(CliError::Input(format!(
            "{file}: /model/fingerprint: the calibration ran another model than {} (its \
             program, arguments, templates, outputs, parameters or a file of \
             fingerprint_files changed since): calibrate it again, then diagnose",
            config.display()
        )));
    }
    let params = load_params(report_path, &json, &cfg.space)?;
    Ok((report, params))
}

/// The report's residual rows must be these measurements: a diagnosis against other data
/// than the calibration's would credit effects with the difference.
fn check_same_measurements(
    report_path: &Path,
    report: &Report,
    obs: &Observations<NamedScenario>,
    measurements: &Path,
) -> CliResult {
    let outputs = obs.outputs();
    let mut rows = 0;
    for s in obs.snapshots() {
        for (o, m) in outputs.iter().zip(&s.measured) {
            let Some(m) = m else { continue };
            rows += 1;
            let fitted = (report.residuals.iter())
                .find(|r| r.snapshot == s.label && r.sensor == o.name)
                .map(|r| r.measured_c);
            let same = fitted.is_some_and(|f| (f - m).abs() <= 1e-9 * m.abs().max(1.0));
            if !same {
                let what = match fitted {
                    Some(f) => format!(
                        "`{}` in `{}` reads {} here, {} in the calibration",
                        o.name,
                        s.label,
                        significant(*m, 6),
                        significant(f, 6)
                    ),
                    None => format!("`{}` in `{}` was not in the calibration", o.name, s.label),
                };
                return Err(not_the_measurements(report_path, measurements, &what));
            }
        }
    }
    if rows != report.residuals.len() {
        let what = format!(
            "{rows} measurements here, {} in the calibration",
            report.residuals.len()
        );
        return Err(not_the_measurements(report_path, measurements, &what));
    }
    Ok(())
}

fn not_the_measurements(report_path: &Path, measurements: &Path, what: &str) -> CliError {
    CliError::Input(format!(
        "{}: not the measurements {} was calibrated on: {what}; diagnose with the \
         calibration's measurements, or calibrate again",
        measurements.display(),
        report_path.display()
    ))
}

/// The diagnosis in words: each candidate's verdict, how to add the one named, and the
/// outputs none explains.
fn print_text(
    d: &Diagnosis,
    cfg: &CommandModelConfig,
    config: &Path,
    not_tried: &[(String, String)],
    scaled: bool,
    robust_nu: Option<f64>,
) {
    let unit = if scaled { " sd" } else { "" };
    println!(
        "candidate effects, best first (MAE now {}{unit}; `explains`: the share of the \
         residual, as the ranking weighs the outputs, that the effect removes; `predicted \
         MAE`: linearised, with the calibrated parameters refitted beside it):",
        significant(d.mae, 4)
    );
    let significant_ones: Vec<&HypothesisResult> = d.significant().collect();
    let undecided = d.undecided();
    if !undecided.is_empty() {
        println!(
            "  no effect decided: {} fit about as well (BIC within {CLOSE_ALTERNATIVE_BIC:.0}), \
             each changing other outputs; the data say something is missing, not which. Add \
             each in turn, calibrate, and keep the one that lowers the error.",
            undecided.join(", ")
        );
    } else if significant_ones.is_empty() {
        println!("  no significant missing effect among the candidates");
    }
    for h in &d.hypotheses {
        let flags = kalibre_dc::diagnosis::hypothesis_flags(
            h.significant,
            h.refuted,
            h.inert,
            h.identifiable,
            h.in_range,
        );
        println!(
            "  {:<32} explains {:>4.0}%  predicted MAE {}{unit}  BIC {:+.1}  {}",
            h.name,
            100.0 * h.explained_fraction,
            significant(h.predicted_mae, 4),
            h.delta_bic,
            flags
        );
        let Some(effect) = cfg.candidates.iter().find(|c| c.name == h.name) else {
            continue;
        };
        // The fit is of the change from absent; the model takes the value.
        let values: Vec<(String, f64, [f64; 2])> = (effect.params.iter())
            .map(|p| {
                let change = h.fitted.get(&p.name).unwrap_or(0.0);
                (p.name.clone(), p.absent + change, [p.lower, p.upper])
            })
            .collect();
        let fitted: Vec<String> = (values.iter())
            .map(|(n, v, _)| format!("{n} = {}", significant(*v, 4)))
            .collect();
        if !h.in_range {
            let ranges: Vec<String> = (values.iter())
                .map(|(n, _, [lo, hi])| {
                    format!(
                        "{n} in [{}, {}]",
                        kalibre_core::number(*lo),
                        kalibre_core::number(*hi)
                    )
                })
                .collect();
            println!(
                "    fitted {}: outside model.toml's range ({}), which no value of it gives",
                fitted.join(", "),
                ranges.join(", ")
            );
            continue;
        }
        if h.significant {
            println!("    fitted {}", fitted.join(", "));
            if !h.identifiable {
                println!("    {}", super::print::not_identifiable(h));
            }
            println!(
                "    to add it: in {}, delete `absent` from [[params]] {} and give `initial` \
                 (the fitted value is a good start), then calibrate again into the same --out: \
                 the runs already made count",
                config.display(),
                kalibre_core::some_names(
                    &effect
                        .params
                        .iter()
                        .map(|p| format!("`{}`", p.name))
                        .collect::<Vec<_>>()
                )
            );
            if significant_ones
                .first()
                .is_some_and(|best| best.name == h.name)
            {
                super::print::print_close_alternatives(d, h);
            }
        } else if undecided.contains(&h.name.as_str()) {
            println!(
                "    undecided (about as good: {}); fitted {}",
                h.ambiguous_with.join(", "),
                fitted.join(", ")
            );
        } else if let Some(output) = &h.carried_by {
            println!(
                "    rests on one output, {output}: without it the others do not prefer it \
                 (a faulty measurement, or the model's own error there, looks the same)"
            );
        }
    }
    print_unexplained(d, scaled, robust_nu);
    if !not_tried.is_empty() {
        println!("\nnot tried:");
        for (name, why) in not_tried {
            println!("  {name}: {why}");
        }
    }
}

/// The outputs no candidate explains, in the units the diagnosis weighed them in.
fn print_unexplained(d: &Diagnosis, scaled: bool, robust_nu: Option<f64>) {
    if d.unexplained.is_empty() {
        return;
    }
    let after = match d.significant().next() {
        Some(h) => format!("left with {} added", h.name),
        None => "the calibrated model's".to_string(),
    };
    println!(
        "\noutputs no candidate explains (the model's own form there, or a faulty \
         measurement; the ranking counts them little; residuals {after}):"
    );
    let unit = if scaled { " sd" } else { "" };
    for u in &d.unexplained {
        println!(
            "  {:<24} model minus measurement {}{unit} on average, {:.1} noise scales",
            u.output,
            significant(u.mean_residual, 3),
            u.rms_scales
        );
    }
    if robust_nu.is_none() {
        println!(
            "  to calibrate weighing them down as a Student-t ranking does, add `--likelihood \
             student-t` to `kalibre calibrate`"
        );
    }
}
