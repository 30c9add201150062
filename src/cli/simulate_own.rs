//! `kalibre simulate --model command --config model.toml`, no hall: a model of your own
//! run once at each of its `[[scenarios]]`, at a calibration's parameters (`--params
//! report.json` of `kalibre calibrate --measurements`), at a JSON object's, or at its
//! initial values. The outputs are written as `scenario,output,value` rows, the format
//! of `measurements.csv`: to predict new scenarios, add them to `model.toml`.

use std::time::Instant;

use kalibre_core::Model;

use super::params_file::{load_params, read_params_json};
use super::simulate::{refuse_given, SimulateArgs};
use super::simulate_command::failed_run;
use super::{io_err, say, CliError, CliResult};

/// Flags about a hall (its servers, fields, grid, what-ifs) or OpenFOAM: refused here
/// rather than ignored.
fn refuse_hall_flags(args: &SimulateArgs) -> CliResult {
    let given = super::simulate::field_and_grid_flags(args);
    refuse_given(&given, |flag| {
        format!(
            "{flag} is about a hall; without --hall, simulate runs a model of your own at \
             its [[scenarios]]"
        )
    })?;
    if let Some(what) = args.what_if.describe() {
        return Err(CliError::Input(format!(
            "the what-if ({what}) changes a hall's snapshots; a model of your own takes its \
             scenarios from model.toml: add one with the values to try"
        )));
    }
    super::own_model::refuse_openfoam_flags(&args.openfoam)
}

/// A CSV field, quoted where it must be.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// Runs the model of `--config` at every scenario and writes its outputs to `--out`. A
/// failed run ends the command with its reason, its log's gist and where its directory
/// was kept.
pub(super) fn run(args: &SimulateArgs) -> CliResult {
    refuse_hall_flags(args)?;
    let Some(path) = args.config.as_deref() else {
        return Err(CliError::Input(
            "--model command needs --config model.toml (see docs/models.md)".into(),
        ));
    };
    let cfg = super::own_model::load_config(
        path,
        " to run the model at (each a `label` and its `variables`, docs/models.md)",
    )?;
    super::out_dir::check_out_file("--out", &args.out)?;
    let params = match &args.params {
        Some(file) => {
            let json = read_params_json(file)?;
            // A hall's calibration names its parameters alike only by chance: refused by
            // what it is, before its names are (`alpha/db: unknown parameter`).
            let kind = (json.get("model"))
                .and_then(|m| m.get("kind"))
                .and_then(|k| k.as_str());
            if let Some(kind) = kind.filter(|k| *k != "command") {
                return Err(CliError::Input(format!(
                    "{}: /model/kind: the calibration of a hall (the `{kind}` model), not of a \
                     model of your own: `kalibre simulate --hall HALL --snapshots SNAPSHOTS \
                     --params {}` runs it",
                    file.display(),
                    super::shell_word(file)
                )));
            }
            let recorded = json.get("model").and_then(|m| m.get("fingerprint"));
            if let Some(f) = recorded.and_then(|f| f.as_str()) {
                if f != cfg.command.fingerprint() {
                    eprintln!(
                        "kalibre: note: {} describes another model than the one the \
                         calibration ran (its program, arguments, templates, outputs or a \
                         file of fingerprint_files changed): the outputs are this model's",
                        path.display()
                    );
                }
            }
            load_params(file, &json, &cfg.space)?
        }
        None => cfg.space.initial(),
    };
    super::out_dir::note_interrupted_runs(cfg.command.remove_interrupted_runs());
    let mut csv = String::from("scenario,output,value\n");
    for scenario in &cfg.scenarios {
        let started = Instant::now();
        let report = cfg.command.run(scenario, &params);
        let kept = (report.attempts.last())
            .filter(|a| a.kept)
            .and_then(|a| a.run_dir.as_deref());
        let outputs = report.outcome.map_err(|e| {
            CliError::Run(format!(
                "scenario `{}`: {}",
                scenario.label,
                failed_run(&e, kept)
            ))
        })?;
        say!(
            "{}: the model ran in {:.1} s",
            scenario.label,
            started.elapsed().as_secs_f64()
        );
        for (name, value) in cfg.command.output_names().iter().zip(&outputs.values) {
            csv += &format!(
                "{},{},{value}\n",
                csv_field(&scenario.label),
                csv_field(name)
            );
        }
    }
    kalibre_core::write_atomic(&args.out, csv).map_err(|e| io_err(&args.out, e))?;
    if args.params.is_none() {
        say!(
            "note: no --params: the model ran at the initial values of {}'s [[params]]",
            path.display()
        );
    }
    let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    say!(
        "wrote {} ({} x {}, from the model of {})",
        args.out.display(),
        count(cfg.scenarios.len(), "scenario"),
        count(cfg.command.output_names().len(), "output"),
        path.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::csv_field;

    #[test]
    fn fields_are_quoted_only_where_they_must_be() {
        assert_eq!(csv_field("winter"), "winter");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
    }
}
