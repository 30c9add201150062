//! `kalibre simulate --model command`: the hall's own simulator, driven through files as
//! `kalibre calibrate --model command` drives it (`--config model.toml`), on every
//! snapshot at a calibration's parameters or any others, what-ifs included: the
//! predicted sensor readings.

use std::path::Path;
use std::time::Instant;

use kalibre_core::{Model, ModelError};
use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{self, HallSnapshot};

use super::calibrated_model::CalibratedModel;
use super::hall_command::{self, HallCommand};
use super::simulate::{load_params, SimulateArgs};
use super::{io_err, say, CliError, CliResult};

/// The built-in simulator's options that a command's runs do not have, by flag: a
/// command returns its sensors only, not the air of every server nor the fields.
fn refuse_builtin_only(args: &SimulateArgs) -> CliResult {
    let given = super::simulate::field_and_grid_flags(args);
    super::simulate::refuse_given(&given, |flag| {
        format!(
            "{flag} is not available with --model command: the command returns the sensors' \
             readings only (the built-in simulator and OpenFOAM give the servers' air and \
             fields)"
        )
    })
}

/// Runs the command of `--config` on every snapshot of `snaps` (what-ifs applied) at the
/// parameters of `file` (a JSON object or a calibration's report, as read by `--params`)
/// and writes the predicted readings. A failed run ends the command with its reason, its
/// log's gist and where its directory was kept.
pub(super) fn run(
    args: &SimulateArgs,
    hall: &Hall,
    snaps: &[HallSnapshot],
    file: Option<&(serde_json::Value, Option<CalibratedModel>)>,
) -> CliResult {
    refuse_builtin_only(args)?;
    let path = args
        .config
        .as_deref()
        .ok_or_else(|| CliError::Input("--model command needs --config model.toml".into()))?;
    let recorded = file.and_then(|(_, m)| m.as_ref());
    // A report's alpha mode decides the parameters' names, as it did for its calibration.
    let hall = match recorded {
        Some(m) => m.calibrated_hall(hall),
        None => hall.clone(),
    };
    let model = HallCommand::new(&hall, hall_command::load_config(path)?, path)?;
    super::out_dir::note_interrupted_runs(model.command.remove_interrupted_runs());
    match recorded {
        Some(m) if m.kind != "command" => eprintln!(
            "note: the calibration ran the {} model; simulate runs the command of {} at its \
             parameters",
            m.kind,
            path.display()
        ),
        Some(CalibratedModel {
            fingerprint: Some(f),
            ..
        }) if *f != model.fingerprint() => eprintln!(
            "note: {} describes another command than the one the calibration ran (its \
             program, arguments, templates or parser differ): the predictions are this \
             command's",
            path.display()
        ),
        _ => {}
    }
    model.check_snapshots(snaps, path)?;
    let space = model.layout.space();
    let params = match (&args.params, file) {
        (Some(p), Some((json, _))) => load_params(p, json, space)?,
        _ => space.initial(),
    };
    let mut labels = Vec::with_capacity(snaps.len());
    let mut predicted = Vec::with_capacity(snaps.len());
    for snap in snaps {
        let label = &snap.state.label;
        let started = Instant::now();
        let report = model.command.run(&model.scenario(&snap.state), &params);
        // The attempt's own record: a run with no log tail (a non-finite output) is
        // kept too.
        let kept = report
            .attempts
            .last()
            .filter(|a| a.kept)
            .and_then(|a| a.run_dir.as_deref());
        let outputs = report
            .outcome
            .and_then(|o| model.check_plausible(&o).map(|()| o))
            .map_err(|e| CliError::Run(format!("snapshot `{label}`: {}", failed_run(&e, kept))))?;
        say!(
            "{label}: the command ran in {:.1} s",
            started.elapsed().as_secs_f64()
        );
        labels.push(label.clone());
        predicted.push(outputs.values);
    }
    let csv = snapshots::write_predictions(&hall, &labels, &predicted);
    kalibre_core::write_atomic(&args.out, csv).map_err(|e| io_err(&args.out, e))?;
    super::simulate::say_if_uncalibrated(args);
    say!(
        "wrote {} ({} x {} sensors, from the command of {})",
        args.out.display(),
        super::counted(labels.len(), "snapshot"),
        hall.sensors.len(),
        path.display()
    );
    Ok(())
}

/// A failed run for a one-line message: the error, the gist of its log and where its
/// directory was kept, if it was.
pub(super) fn failed_run(e: &ModelError, kept: Option<&Path>) -> String {
    let gist = e.log_gist().map(|g| format!("; its log: {g}"));
    let kept = kept.map(|d| format!(" (its directory is kept: {})", d.display()));
    format!(
        "{e}{}{}",
        gist.unwrap_or_default(),
        kept.unwrap_or_default()
    )
}
