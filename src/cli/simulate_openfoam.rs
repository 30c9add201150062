//! `kalibre simulate --model openfoam`: OpenFOAM on a hall's snapshots, at a calibration's
//! parameters or any others, what-ifs included; the predicted sensor readings, and every
//! server's air with the intakes counted against the limit.

use std::path::Path;
use std::time::Instant;

use kalibre_core::Model;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{
    remove_interrupted_runs, server_air_from_intakes, OpenFoamModel, SERVER_INTAKE_KEY,
};
use kalibre_dc::sim::{inlet_check, setpoint_headroom_c, write_server_air};
use kalibre_dc::snapshots::{self, HallSnapshot};

use super::calibrated_model::{grid_or_recorded, CalibratedModel};
use super::inlets::inlet_line;
use super::openfoam_args::of_err;
use super::simulate::{
    inlet_limit_c, load_params, print_servers_written, print_under_read_note, SimulateArgs,
};
use super::{io_err, say, CliError, CliResult};

/// The built-in simulator's options that OpenFOAM runs do not have, by flag.
fn refuse_builtin_only(args: &SimulateArgs) -> CliResult {
    let given = [
        ("--vtk", args.vtk.is_some()),
        ("--heat-sources", args.heat_sources.is_some()),
        ("--grid-check", !args.grid_check.is_empty()),
    ];
    super::simulate::refuse_given(&given, |flag| {
        format!(
            "{flag} needs the built-in simulator's fields; with --model openfoam, simulate \
             writes the sensor readings and the servers' air"
        )
    })
}

/// Runs OpenFOAM on every snapshot of `snaps` (what-ifs applied) at the parameters of
/// `file` (a JSON object or a calibration's report, as read by `--params`), writes the
/// predicted readings (and with `--servers` every server's air), and prints each
/// snapshot's intakes against the limit with the setpoint headroom.
pub(super) fn run(
    args: &SimulateArgs,
    hall_path: &Path,
    hall: &Hall,
    snaps: &[HallSnapshot],
    file: Option<&(serde_json::Value, Option<CalibratedModel>)>,
) -> CliResult {
    refuse_builtin_only(args)?;
    let limit_c = inlet_limit_c(args)?;
    // An OpenFOAM calibration's report brings its mesh, iterations and processes; any
    // report its alpha mode.
    let recorded = file.and_then(|(_, m)| m.as_ref());
    let of_recorded = recorded.filter(|m| m.kind == "openfoam");
    if let Some(m) = recorded.filter(|m| m.kind != "openfoam") {
        eprintln!(
            "note: the calibration ran the {} model; simulate runs OpenFOAM at its parameters",
            m.kind
        );
    }
    let hall = match recorded {
        Some(m) => m.calibrated_hall(hall),
        None => hall.clone(),
    };
    let mut of_args = args.openfoam.clone();
    if let Some(m) = of_recorded {
        of_args.of_iterations = of_args.of_iterations.or(m.of_iterations);
        of_args.np = of_args.np.or(m.np);
    }
    // Beside the calibration, an OpenFOAM calibration's meshed case is found again.
    let root = match (&args.of_dir, &args.params, file) {
        (Some(dir), _, _) => dir.clone(),
        (None, Some(p), Some((json, _))) if json.get("best").is_some() => p
            .parent()
            .map_or_else(|| "openfoam".into(), |d| d.join("openfoam")),
        _ => args
            .out
            .parent()
            .map_or_else(|| "openfoam".into(), |d| d.join("openfoam")),
    };
    let settings = of_args.settings(&root, grid_or_recorded(args.grid_m, of_recorded))?;
    super::openfoam_args::check_mesh(&hall, hall_path, settings.grid_m, args.grid_m.is_some())?;
    let model = OpenFoamModel::new(&hall, settings)
        .map_err(|e| of_err(e.in_hall_file(&hall_path.display().to_string())))?;
    super::out_dir::note_interrupted_runs(remove_interrupted_runs(&model.settings().cache_root));
    let space = model.layout().space();
    let params = match (&args.params, file) {
        (Some(p), Some((json, _))) => load_params(p, json, space)?,
        _ => space.initial(),
    };
    // The case prescribes each server's flow from its alpha.
    let alpha = model.layout().alpha_per_server(&params);
    let mut labels = Vec::with_capacity(snaps.len());
    let mut predicted = Vec::with_capacity(snaps.len());
    let mut air = Vec::new();
    let mut checks = Vec::with_capacity(snaps.len());
    for snap in snaps {
        let label = &snap.state.label;
        let started = Instant::now();
        let failed =
            |e: &dyn std::fmt::Display| CliError::Run(format!("snapshot `{label}`: OpenFOAM: {e}"));
        let out = model.evaluate(&snap.state, &params).map_err(|e| {
            let kept = e.run_dir().map(std::path::Path::new);
            failed(&super::simulate_command::failed_run(&e, kept))
        })?;
        let intake_c = out
            .extras
            .get(SERVER_INTAKE_KEY)
            .ok_or_else(|| failed(&"the run sampled no server intakes"))?;
        say!(
            "{label}: OpenFOAM solved in {:.0} s",
            started.elapsed().as_secs_f64()
        );
        let servers =
            server_air_from_intakes(&hall, &snap.state, &alpha, intake_c, model.settings())?;
        checks.push(inlet_check(&servers, limit_c, 3)?);
        if args.servers.is_some() {
            air.extend(servers);
        }
        labels.push(label.clone());
        predicted.push(out.values);
    }
    // Each file whole or not at all, the side table first (as the built-in model's).
    if let Some(path) = &args.servers {
        kalibre_core::write_atomic(path, write_server_air(&air)).map_err(|e| io_err(path, e))?;
    }
    let csv = snapshots::write_predictions(&hall, &labels, &predicted);
    kalibre_core::write_atomic(&args.out, csv).map_err(|e| io_err(&args.out, e))?;
    super::simulate::say_if_uncalibrated(args);
    for (label, check) in labels.iter().zip(&checks) {
        say!("{}", inlet_line(label, check));
    }
    let headroom: Vec<Option<f64>> = checks.iter().map(setpoint_headroom_c).collect();
    print_under_read_note(args, file, &hall, &labels, &headroom)?;
    say!(
        "wrote {} ({} x {} sensors; OpenFOAM case in {})",
        args.out.display(),
        super::counted(labels.len(), "snapshot"),
        hall.sensors.len(),
        root.display()
    );
    print_servers_written(args, &labels, &hall);
    Ok(())
}
