//! `kalibre diagnose --model command --config model.toml --measurements FILE
//! --calibration DIR`: which of a model of your own's candidate effects (its `[[params]]`
//! with `absent`) the data want, at the calibration's parameters. The model is linearised
//! by its own runs, through the calibration's journal: a run already there is read, and
//! each new one is kept, so a recalibration with the effect added starts from them.

use std::path::Path;

use kalibre_core::calibrate::{Report, REPORT_SCHEMA};
use kalibre_core::diagnose::{
    diagnose, linearise, run_fitted, DiagnoseSettings, Diagnosis, HypothesisResult,
    LineariseSettings, CLOSE_ALTERNATIVE_BIC,
};
use kalibre_core::external::{CommandModelConfig, NamedScenario};
use kalibre_core::{Model, Observations};

use super::super::calibrate::generic::{errors_in, observations, open_journal};
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
    super::journal::check_regular_files(&args.calibration)?;
    let report_path = args.calibration.join("report.json");
    let (report, params) = read_report(&report_path, &cfg, config, obs.scales().is_some())?;
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
    super::super::calibrate::set_stop_message(&journal, false);
    let store = open_journal(&journal, &cfg, config, args.replay_failed)?;
    check_calibrated_runs(&store, &cfg, &obs, &params, &report, config)?;
    let planned = obs.snapshots().len()
        * (1 + (cfg.space.params().iter())
            .filter(|p| !p.is_fixed())
            .count()
            + cfg.candidates.iter().map(|c| c.params.len()).sum::<usize>());
    eprintln!(
        "diagnosing {} candidate effect(s) of {}: about {planned} model runs ({} scenarios x \
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
    let rank = |hypotheses: &[kalibre_core::diagnose::Hypothesis]| {
        diagnose(&lin.residuals, hypotheses, &settings)
            .map_err(|e| CliError::Run(format!("diagnosis of {}: {e}", config.display())))
    };
    let mut hypotheses = lin.hypotheses.clone();
    let mut d = rank(&hypotheses)?;
    // The leading candidate run where it was fitted: the model's own MAE there. One that
    // reads no better than the calibrated point is refuted, and the ranking made again.
    let mut checked: Vec<Checked> = Vec::new();
    let (mut new_runs, mut read_runs) = (lin.runs, lin.cached);
    loop {
        let Some(best) = d.significant().next().cloned() else {
            break;
        };
        let best = &best;
        let Some(effect) = cfg.candidates.iter().find(|c| c.name == best.name) else {
            break;
        };
        if checked.iter().any(|c| c.name == best.name) {
            break;
        }
        let run = with_threads(args.threads, || {
            run_fitted(
                &cfg.command,
                &obs,
                &cfg.space,
                &params,
                effect,
                best,
                &store,
            )
        })?
        .map_err(|e| CliError::Run(e.to_string()))?;
        new_runs += run.runs;
        read_runs += run.cached;
        let refuted = run.mae.as_ref().is_ok_and(|m| *m >= d.mae);
        checked.push(Checked {
            name: best.name.clone(),
            params: cfg.space.names().into_iter().zip(run.params).collect(),
            mae: run.mae,
            refuted,
        });
        if !refuted {
            break;
        }
        let name = best.name.clone();
        for h in hypotheses.iter_mut().filter(|h| h.name == name) {
            h.refuted = true;
        }
        d = rank(&hypotheses)?;
    }
    let scaled = obs.scales().is_some();
    if args.json {
        let doc = serde_json::json!({
            "model": { "kind": "command", "config": config.display().to_string(),
                       "fingerprint": cfg.command.fingerprint(),
                       "errors_in": errors_in(scaled) },
            "diagnosis": d,
            // The diagnosis fits each candidate's change from absent; the model takes
            // the value.
            "fitted_values": fitted_values_json(&d, &cfg),
            "not_tried": lin.not_tried.iter()
                .map(|(name, why)| serde_json::json!({ "candidate": name, "reason": why }))
                .collect::<Vec<_>>(),
            "checked": checked.iter().map(Checked::to_json).collect::<Vec<_>>(),
            "runs": { "new": new_runs, "from_journal": read_runs },
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&doc).map_err(|e| CliError::Run(format!("JSON: {e}")))?
        );
        return Ok(());
    }
    print_text(
        &d,
        &cfg,
        config,
        (&lin.not_tried, &checked),
        scaled,
        (settings.robust_nu, report.settings.robust_nu),
    );
    println!(
        "\n{} model runs, {} read from {}",
        new_runs,
        read_runs,
        journal.display()
    );
    Ok(())
}

/// The model run where the diagnosis fitted a leading candidate.
struct Checked {
    name: String,
    /// Every parameter there, by name.
    params: Vec<(String, f64)>,
    /// The model's MAE there, or why it failed.
    mae: Result<f64, String>,
    /// It read no better than the calibrated point.
    refuted: bool,
}

impl Checked {
    fn to_json(&self) -> serde_json::Value {
        let params: serde_json::Map<String, serde_json::Value> = (self.params.iter())
            .map(|(n, v)| (n.clone(), serde_json::json!(v)))
            .collect();
        serde_json::json!({
            "candidate": self.name,
            "params": params,
            "mae": self.mae.as_ref().ok(),
            "failed": self.mae.as_ref().err(),
            "refuted": self.refuted,
        })
    }

    /// In words, beside `mae_now`, the calibrated point's.
    fn line(&self, mae_now: f64, unit: &str) -> String {
        match &self.mae {
            Ok(m) if self.refuted => format!(
                "the model run there reads MAE {}{unit}, no better than now ({}{unit}): \
                 the linearisation misleads, so it is not named",
                significant(*m, 4),
                significant(mae_now, 4)
            ),
            Ok(m) => format!(
                "the model run there (the calibrated parameters moved with it) reads MAE \
                 {}{unit}, against {}{unit} now",
                significant(*m, 4),
                significant(mae_now, 4)
            ),
            Err(why) => format!("the model could not run there ({why}): not checked"),
        }
    }
}

/// The calibration's report and its best parameters, refused when it is of another model
/// than `cfg` (its fingerprint recorded otherwise) or not a calibration of one's own.
fn read_report(
    report_path: &Path,
    cfg: &CommandModelConfig,
    config: &Path,
    measurements_scaled: bool,
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
        let parts = report_path.with_file_name(super::super::calibrate::generic::MODEL_PARTS);
        let what =
            super::super::calibrate::generic::changed_since(&parts, cfg).unwrap_or_else(|| {
                "its program, arguments, templates, outputs, parameters or a file of \
                 fingerprint_files changed since"
                    .to_string()
            });
        return Err(CliError::Input(format!(
            "{file}: /model/fingerprint: the calibration ran another model than {} ({what}): \
             calibrate it into another --out (this one's journal holds the other model's \
             runs), then diagnose that",
            config.display()
        )));
    }
    let recorded_in = json.pointer("/model/errors_in").and_then(|e| e.as_str());
    if let Some(recorded_in) = recorded_in {
        if recorded_in != errors_in(measurements_scaled) {
            return Err(CliError::Input(format!(
                "{file}: /model/errors_in: the calibration weighed the errors in {recorded_in}, \
                 these measurements {} (an `sd` column {}): diagnose with the calibration's \
                 measurements, or calibrate again",
                if measurements_scaled {
                    "in sd"
                } else {
                    "in the outputs' units"
                },
                if measurements_scaled {
                    "added"
                } else {
                    "removed"
                }
            )));
        }
    }
    // A candidate held at another value than the calibration's, or one added or turned
    // into a calibrated parameter since, is a model.toml edit: named there.
    for c in cfg.candidates.iter().flat_map(|c| &c.params) {
        let was = (json.pointer(&format!("/best/params/{}", c.name))).and_then(|v| v.as_f64());
        if let Some(was) = was.filter(|was| *was != c.absent) {
            return Err(CliError::Input(format!(
                "{}: `params[{}].absent` is {}, but the calibration ran `{}` at {}: \
                 calibrate again with the candidates as they are now, then diagnose",
                config.display(),
                c.index,
                kalibre_core::number(c.absent),
                c.name,
                kalibre_core::number(was)
            )));
        }
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

/// The journal must hold the calibration's runs at its parameters, answering what the
/// report recorded, before any step runs: a scenario's variables edited since (not in the
/// model's fingerprint) have no run there, and the diagnosis would explain the edit.
fn check_calibrated_runs(
    store: &kalibre_core::RunStore,
    cfg: &CommandModelConfig,
    obs: &Observations<NamedScenario>,
    params: &[f64],
    report: &Report,
    config: &Path,
) -> CliResult {
    let names = cfg.space.names();
    let journal = store
        .path()
        .map_or_else(String::new, |p| p.display().to_string());
    for s in obs.snapshots() {
        let key = cfg.command.scenario_key(&s.scenario);
        let outputs = store
            .get_keyed(&s.label, &key, &names, params)
            .and_then(|(_, rec)| rec.result().ok());
        let Some(outputs) = outputs else {
            return Err(CliError::Input(format!(
                "{}: scenario `{}`: {journal} has no run of the calibrated parameters under \
                 its variables as they are now: they changed since the calibration (or the \
                 journal lost the run); calibrate again, then diagnose",
                config.display(),
                s.label
            )));
        };
        for ((o, m), v) in (obs.outputs().iter()).zip(&s.measured).zip(&outputs.values) {
            if m.is_none() {
                continue;
            }
            let recorded = (report.residuals.iter())
                .find(|r| r.snapshot == s.label && r.sensor == o.name)
                .map(|r| r.predicted_c);
            // The report keeps (v / scale) * scale with an sd column: equal to v but for
            // its last bit or so.
            if recorded.is_some_and(|r| (r - v).abs() > 1e-12 * r.abs().max(v.abs())) {
                return Err(CliError::Input(format!(
                    "{journal}: scenario `{}`: the run at the calibrated parameters gives {} for \
                     `{}`, where the report recorded {}: the report is not this journal's; \
                     calibrate again, then diagnose",
                    s.label,
                    significant(*v, 6),
                    o.name,
                    significant(recorded.unwrap_or_default(), 6)
                )));
            }
        }
    }
    Ok(())
}

/// Each hypothesis's fitted values as the model takes them: the absent value plus the
/// fitted change, by hypothesis and parameter name.
fn fitted_values_json(d: &Diagnosis, cfg: &CommandModelConfig) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    for h in &d.hypotheses {
        let Some(effect) = cfg.candidates.iter().find(|c| c.name == h.name) else {
            continue;
        };
        let values: serde_json::Map<String, serde_json::Value> = (effect.params.iter())
            .map(|p| {
                let change = h.fitted.get(&p.name).unwrap_or(0.0);
                (p.name.clone(), serde_json::json!(p.absent + change))
            })
            .collect();
        out.insert(h.name.clone(), serde_json::Value::Object(values));
    }
    serde_json::Value::Object(out)
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
    (not_tried, checked): (&[(String, String)], &[Checked]),
    scaled: bool,
    (robust_nu, calibration_nu): (Option<f64>, Option<f64>),
) {
    let unit = if scaled { " sd" } else { "" };
    println!(
        "candidate effects, best first (MAE now {}{unit}; `explains`: the share of the \
         residual, as the ranking weighs the outputs, that the effect removes; `predicted \
         MAE`: linearised, with the calibrated parameters refitted beside it):",
        significant(d.mae, 4)
    );
    println!(
        "  ranked under {}",
        match robust_nu {
            Some(nu) => format!(
                "a Student-t likelihood ({nu} degrees of freedom: a few outputs the model \
                 misses count little; --likelihood gaussian for least squares)"
            ),
            None => "least squares (--likelihood gaussian)".to_string(),
        }
    );
    // The calibrated parameters alone, refitted: a calibration that had not converged
    // shows here, and no candidate earns the difference.
    if d.refit_mae < 0.9 * d.mae {
        println!(
            "  refitting the calibrated parameters alone would already give MAE {}{unit} \
             (linearised): the calibration has not converged, and every predicted MAE below \
             includes that; more --iterations, or --polish N, settles it",
            significant(d.refit_mae, 4)
        );
    }
    let significant_ones: Vec<&HypothesisResult> = d.significant().collect();
    let undecided = d.undecided();
    if !undecided.is_empty() {
        println!(
            "  no effect decided: {} fit about as well (BIC within {CLOSE_ALTERNATIVE_BIC:.0}), \
             each changing other outputs; the data say something is missing, not which. Add \
             each in turn, calibrate, and keep the one that lowers the error.",
            undecided.join(", ")
        );
    } else if d.hypotheses.is_empty() {
        println!("  no candidate could be tried (below: why)");
    } else if significant_ones.is_empty() {
        println!("  no significant missing effect among the candidates");
    }
    for h in &d.hypotheses {
        let flags = super::print::flags(h);
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
        let check = checked.iter().find(|c| c.name == h.name);
        let check_line = check.map(|c| c.line(d.mae, unit));
        if h.significant {
            println!("    fitted {}", fitted.join(", "));
            if let Some(line) = &check_line {
                println!("    {line}");
            }
            if !h.identifiable {
                println!("    {}", super::print::not_identifiable(h));
            }
            let grouped = effect.params.len() > 1 || effect.name != effect.params[0].name;
            println!(
                "    to add it: in {}, delete `absent`{} from [[params]] {} and give `initial` \
                 (the fitted value is a good start), then calibrate again; the same --out \
                 keeps its journal, whose runs are read back wherever the loop asks for one \
                 again",
                config.display(),
                if grouped { " and `effect`" } else { "" },
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
        } else if let Some(line) = check_line.filter(|_| h.refuted) {
            println!("    fitted {}; {line}", fitted.join(", "));
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
    print_unexplained(d, scaled, calibration_nu);
    if !not_tried.is_empty() {
        println!("\nnot tried:");
        for (name, why) in not_tried {
            println!("  {name}: {why}");
        }
    }
}

/// The outputs no candidate explains, in the units the diagnosis weighed them in;
/// `calibration_nu` is the calibration's likelihood, which the advice is about.
fn print_unexplained(d: &Diagnosis, scaled: bool, calibration_nu: Option<f64>) {
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
    if calibration_nu.is_none() {
        println!(
            "  to calibrate weighing them down as a Student-t ranking does, add `--likelihood \
             student-t` to `kalibre calibrate`"
        );
    }
}
