//! `kalibre diagnose --model command --config model.toml --measurements FILE
//! --calibration DIR`: which of a model of your own's candidate effects (its `[[params]]`
//! with `absent`) the data want, at the calibration's parameters. The model is linearised
//! by its own runs, through the calibration's journal: a run already there is read, and
//! each new one is kept, so a recalibration with the effect added starts from them.

mod inputs;
mod print;
mod write_config;

use kalibre_core::diagnose::{
    diagnose, linearise, refit_leading, run_fitted, Calibrated, DiagnoseSettings, Diagnosis,
    Hypothesis, LineariseSettings, Refit, RefitSettings,
};

use super::super::calibrate::generic::{observations, open_journal};
use super::super::{own_model, with_threads, CliError, CliResult};
use super::DiagnoseArgs;
use inputs::{check_calibrated_runs, check_same_measurements, read_report};

/// Flags about a hall, its simulator or OpenFOAM: refused rather than ignored.
fn refuse_hall_flags(args: &DiagnoseArgs) -> CliResult {
    let given = [
        ("--hall", args.hall.is_some()),
        ("--snapshots", args.snapshots.is_some()),
        ("--grid-m", args.grid_m.is_some()),
        ("--no-model-form", args.no_model_form),
        ("--write-hall", args.write_hall.is_some()),
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
    own_model::warn_unwritten_params(config, &cfg);
    if let Some(path) = &args.write_config {
        let (report, journal) = (
            args.calibration.join("report.json"),
            args.calibration.join("runs.jsonl"),
        );
        write_config::check_target(
            path,
            config,
            &[
                ("the --measurements file", measurements),
                ("the calibration's report", &report),
                ("the calibration's run journal", &journal),
            ],
        )?;
    }
    let obs = observations(&cfg, measurements)?;
    super::journal::check_regular_files(&args.calibration)?;
    let report_path = args.calibration.join("report.json");
    let (report, params) = read_report(&report_path, &cfg, config, obs.scales().is_some())?;
    check_same_measurements(&report_path, &report, &obs, measurements)?;
    let noise = super::noise_arg(args.noise)?;
    if noise.is_some() && obs.scales().is_some() {
        // The residuals the ranking reads are then in scale units, not the readings'.
        return Err(CliError::Input(format!(
            "--noise: {} gives the outputs scales, so the diagnosis weighs residuals in \
             scale units: leave --noise out (a scale is the noise a residual is measured in)",
            config.display()
        )));
    }
    let settings = DiagnoseSettings::new()
        .with_single_output_check(!args.no_single_output_check)
        .with_robust_nu(args.likelihood.robust_nu(args.nu)?);
    let settings = DiagnoseSettings {
        ambiguity_check: !args.no_ambiguity_check,
        sensor_bias_rival_bic: args.sensor_bias_rival,
        noise_sigma: noise,
        ..settings
    };
    let _lock = super::super::out_dir::lock(&args.calibration, "--calibration", "diagnose")?;
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
    let n_snap = obs.snapshots().len();
    let refit_runs = if args.refit > 0 {
        format!(
            ", up to {} for --refit",
            n_snap * args.refit.min(cfg.candidates.len()) * args.refit_iterations
        )
    } else {
        String::new()
    };
    eprintln!(
        "diagnosing {} candidate effect(s) of {}: about {planned} model runs ({n_snap} \
         scenario(s) x (the calibrated point, a step of each calibrated parameter and of each \
         candidate's)), {n_snap} at the leading candidate's fit, {n_snap} at the calibrated \
         parameters' own refit if the calibration had not converged{refit_runs}, through {}",
        cfg.candidates.len(),
        config.display(),
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
    let at = Calibrated {
        model: &cfg.command,
        obs: &obs,
        space: &cfg.space,
        params: &params,
        store: &store,
    };
    let rank = |hypotheses: &[Hypothesis]| {
        diagnose(&lin.residuals, hypotheses, &settings).map_err(|e| {
            let msg = format!("diagnosis of {}: {e}", config.display());
            // A mismatch is the data's (too few measured values for the parameters).
            match e {
                kalibre_core::Error::Mismatch(_) => CliError::Input(msg),
                _ => CliError::Run(msg),
            }
        })
    };
    let run_err = |e: kalibre_core::Error| CliError::Run(e.to_string());
    let mut hypotheses = lin.hypotheses.clone();
    let mut d = rank(&hypotheses)?;
    let (mut new_runs, mut read_runs) = (lin.runs, lin.cached);
    // A calibration that stopped short of its own floor: the model run where the
    // calibrated parameters alone refit, so that no candidate is credited with the way
    // there.
    let mut baseline = d.mae;
    let floor = if d.refit_mae < UNCONVERGED * d.mae {
        let run = with_threads(args.threads, || at.run_refit_alone(&d))?.map_err(run_err)?;
        new_runs += run.runs;
        read_runs += run.cached;
        let mae = run.mae();
        if let Ok(m) = mae {
            baseline = baseline.min(m);
        }
        // Where the refit would take a parameter beyond its bounds, the box (not the
        // iterations) stopped the calibration.
        let beyond = (cfg.space.params().iter().zip(&params))
            .filter_map(|(p, x)| {
                let wanted = x + d.refit_change.get(&p.name)?;
                let tol = 1e-9 * (p.upper - p.lower).abs().max(1e-12);
                // At the bound it would cross: an interior value short of it is the
                // iterations', not the box's.
                let up = wanted > p.upper + tol && *x >= p.upper - tol;
                let down = wanted < p.lower - tol && *x <= p.lower + tol;
                (up || down).then(|| {
                    let bound = if up { p.upper } else { p.lower };
                    (p.name.clone(), wanted, bound)
                })
            })
            .collect();
        Some(Floor {
            params: cfg.space.names().into_iter().zip(run.params).collect(),
            mae,
            beyond,
        })
    } else {
        None
    };
    let mut refits: Vec<Refit> = Vec::new();
    if args.refit > 0 {
        let how = RefitSettings {
            top: args.refit,
            iterations: args.refit_iterations,
            ..RefitSettings::default()
        };
        let r = with_threads(args.threads, || {
            refit_leading(
                &at,
                &lin.residuals,
                &cfg.candidates,
                hypotheses.clone(),
                baseline,
                &settings,
                &how,
            )
        })?
        .map_err(run_err)?;
        (d, hypotheses, refits) = (r.diagnosis, r.hypotheses, r.refits);
        new_runs += r.runs;
        read_runs += r.cached;
    }
    // The leading candidate run where it was fitted: the model's own MAE there. One that
    // reads no better than the baseline is refuted, and the ranking made again.
    let mut checked: Vec<Checked> = Vec::new();
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
        // Refit with a run below the baseline: that run is the check, and its point the
        // value (the ranking's fit, from columns exact there, may lie beyond it).
        if let Some(step) = refits
            .iter()
            .find(|r| r.name == best.name)
            .and_then(Refit::best)
        {
            checked.push(Checked {
                name: best.name.clone(),
                params: step.params.0.clone(),
                mae: step.mae.ok_or_else(|| "no MAE".to_string()),
                refuted: false,
                from_refit: true,
                clamped: Vec::new(),
            });
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
        .map_err(run_err)?;
        new_runs += run.runs;
        read_runs += run.cached;
        let refuted = run.mae.as_ref().is_ok_and(|m| *m >= baseline);
        // The joint fit's calibrated parameters beyond their bounds: the run is not at
        // the fit, and a refutation may be the box's.
        let clamped = (cfg.space.params().iter().zip(&params).zip(&run.params))
            .filter(|((p, x), ran)| {
                // The calibrated ones: the candidate's own are in `fitted`.
                best.current_change.get(&p.name).is_some_and(|change| {
                    (*x + change - **ran).abs() > 1e-9 * (p.upper - p.lower).abs().max(1e-300)
                })
            })
            .map(|((p, _), _)| p.name.clone())
            .collect();
        checked.push(Checked {
            name: best.name.clone(),
            params: cfg.space.names().into_iter().zip(run.params).collect(),
            mae: run.mae,
            refuted,
            from_refit: false,
            clamped,
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
    // The next model.toml: the effect named, everything where the model ran at its fit.
    // A write that fails is said after the diagnosis, which is printed anyway.
    let mut write_error = None;
    let written = match (&args.write_config, d.significant().next()) {
        (None, _) => None,
        (Some(path), None) => Some(format!(
            "--write-config {}: not written, since no candidate is significant",
            path.display()
        )),
        (Some(path), Some(best)) => {
            let effect = (cfg.candidates.iter().find(|c| c.name == best.name))
                .expect("a significant hypothesis is a candidate's");
            match checked.iter().find(|c| c.name == best.name) {
                Some(Checked { mae: Err(why), .. }) => Some(format!(
                    "--write-config {}: not written, since the model failed where {} was \
                     fitted ({why}): a calibration would start from a point that does not run",
                    path.display(),
                    effect.name
                )),
                check => {
                    let point = match check {
                        Some(c) => c.params.clone(),
                        None => (cfg.space.names().into_iter())
                            .zip(at.fitted_point(effect, best))
                            .collect(),
                    };
                    match write_config::write(path, config, &cfg, effect, &point) {
                        Ok(line) => Some(line),
                        Err(e) => {
                            write_error = Some(e);
                            None
                        }
                    }
                }
            }
        }
    };
    let outcome = Outcome {
        d,
        not_tried: &lin.not_tried,
        floor,
        refits,
        refit_asked: args.refit,
        checked,
        baseline,
        runs: (new_runs, read_runs),
        written,
    };
    let scaled = obs.scales().is_some();
    if args.json {
        let doc = print::json(&outcome, &cfg, config, scaled);
        println!(
            "{}",
            serde_json::to_string_pretty(&doc).map_err(|e| CliError::Run(format!("JSON: {e}")))?
        );
        // stdout is the JSON document; say what was written on stderr.
        if let Some(line) = &outcome.written {
            eprintln!("{line}");
        }
        return write_error.map_or(Ok(()), Err);
    }
    print::text(
        &outcome,
        &cfg,
        config,
        scaled,
        (settings.robust_nu, report.settings.robust_nu),
    );
    println!(
        "\n{new_runs} new model runs, {read_runs} read from {}",
        journal.display()
    );
    if let Some(line) = &outcome.written {
        println!("{line}");
    }
    write_error.map_or(Ok(()), Err)
}

/// Refitting the calibrated parameters alone lowers the linearised MAE below this share
/// of the calibrated one: the calibration had not converged.
const UNCONVERGED: f64 = 0.9;

/// What the diagnosis found and ran, for the text and the JSON.
struct Outcome<'a> {
    d: Diagnosis,
    not_tried: &'a [(String, String)],
    /// The calibrated parameters' own refit, run by the model, when the calibration had
    /// not converged.
    floor: Option<Floor>,
    /// The `--refit` of the leading candidates, and how many were asked for.
    refits: Vec<Refit>,
    refit_asked: usize,
    /// The leading candidates run at their fit.
    checked: Vec<Checked>,
    /// What a candidate's run must read below: the calibrated MAE, or the floor's.
    baseline: f64,
    /// Model runs made, and read from the journal.
    runs: (usize, usize),
    /// What `--write-config` wrote, in words.
    written: Option<String>,
}

/// The model run where the calibrated parameters alone refit.
struct Floor {
    params: Vec<(String, f64)>,
    mae: Result<f64, String>,
    /// Parameters the refit would move beyond a bound: name, where it would go, the bound.
    beyond: Vec<(String, f64, f64)>,
}

/// The model run where the diagnosis fitted a leading candidate, or its refit's best.
struct Checked {
    name: String,
    /// Every parameter there, by name.
    params: Vec<(String, f64)>,
    /// The model's MAE there, or why it failed.
    mae: Result<f64, String>,
    /// It read no better than the baseline.
    refuted: bool,
    /// The best run of its `--refit`, not a run at the ranking's fit.
    from_refit: bool,
    /// Calibrated parameters the fit moved beyond their bounds, clamped there for the run.
    clamped: Vec<String>,
}
