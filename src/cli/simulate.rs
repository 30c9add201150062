//! `kalibre simulate`: the built-in simulator on a hall's snapshots (OpenFOAM:
//! `simulate_openfoam`; an external command: `simulate_command`).

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use kalibre_dc::hall::Hall;
use kalibre_dc::sim::{coldest_under_read, setpoint_headroom_c, SimConfig};
use kalibre_dc::snapshots::{self, number, AIR_C_RANGE};
use kalibre_dc::HallModel;

use super::calibrated_model::{grid_or_recorded, CalibratedModel};
use super::inlets::{inlet_line, under_read_note};
use super::openfoam_args::OpenFoamArgs;
pub(super) use super::params_file::{load_params, read_params_file};
use super::what_if::WhatIfArgs;
use super::{io_err, say, CliError, CliResult};

/// `--heat-sources` lists a rack when it gives at least this share of a sensor's warming.
const HEAT_SOURCE_MIN_SHARE: f64 = 0.02;

/// Options of `kalibre simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// The hall (`hall.json`). Without `--hall` and `--snapshots`, `--model command
    /// --config model.toml` runs a model of your own at each of its `[[scenarios]]`.
    #[arg(long)]
    pub(super) hall: Option<PathBuf>,
    /// Operating conditions (`snapshots.csv`); sensor readings in it are optional and ignored.
    #[arg(long)]
    pub(super) snapshots: Option<PathBuf>,
    /// Parameter values: a JSON file holding an object `{ "alpha/<type>": 0.12, ... }`,
    /// or a calibration's `report.json` (its best parameters, and the alpha mode and grid
    /// it ran with).
    /// Parameters not given keep the hall's initial values.
    #[arg(long)]
    pub(super) params: Option<PathBuf>,
    /// Where to write the predicted sensor readings (snapshot CSV format, kind `sensor_c`).
    #[arg(long)]
    pub(super) out: PathBuf,
    /// Also write temperature, pressure and velocity fields as VTK files (one per snapshot)
    /// into this directory, for ParaView.
    #[arg(long)]
    pub(super) vtk: Option<PathBuf>,
    /// Grid cell size (m) of the built-in simulator, or of the OpenFOAM mesh with
    /// `--model openfoam`; default: the grid the `--params` report's calibration recorded
    /// for that model, else 0.2.
    #[arg(long = "grid-m")]
    pub(super) grid_m: Option<f64>,
    /// Also write every server's predicted air per snapshot (CSV:
    /// `snapshot,server,rack,type,power_w,flow_m3_s,intake_c,exhaust_c`): what the
    /// calibrated model says where no sensor measures.
    #[arg(long)]
    pub(super) servers: Option<PathBuf>,
    /// Also write where each sensor's warming comes from, per snapshot (CSV:
    /// `snapshot,sensor,rack,warming_k,share`): the racks whose exhausts give at least 2 %
    /// of the sensor's warming over the supply in the model's air flow, largest first.
    /// One adjoint solve per sensor and snapshot.
    #[arg(long = "heat-sources")]
    pub(super) heat_sources: Option<PathBuf>,
    /// Server intake temperature above which a server is counted as too warm (C); default
    /// 27, ASHRAE TC 9.9's recommended upper bound for classes A1-A4.
    #[arg(long = "inlet-limit-c", allow_hyphen_values = true)]
    pub(super) inlet_limit_c: Option<f64>,
    /// Also solve on grids these factors of the cell size finer (e.g. `0.75,0.5`), and
    /// take each snapshot's least setpoint headroom over the grids: the model's own grid
    /// error at its hottest server is then in the figure.
    #[arg(long = "grid-check", value_delimiter = ',', value_name = "F,F")]
    pub(super) grid_check: Vec<f64>,
    #[command(flatten)]
    pub(super) what_if: WhatIfArgs,
    /// The model: `builtin` (the built-in simulator), `openfoam` (a case generated from
    /// hall.json, meshed once into `--of-dir`, one solve per snapshot) or `command` (the
    /// external simulator of `--config model.toml`, one run per snapshot; predicted sensor
    /// readings only).
    /// Default `builtin`; with `--params` a calibration's report of another model is
    /// refused unless `--model` says which to run.
    #[arg(long = "model", value_enum)]
    pub(super) model_arg: Option<SimulateModel>,
    /// With `--model command`: the `model.toml` describing the external simulator, as for
    /// `kalibre calibrate --model command` (docs/models.md).
    #[arg(long)]
    pub(super) config: Option<PathBuf>,
    /// OpenFOAM: where the case is meshed and solved; default: the calibration's
    /// `openfoam` directory when `--params` is its `report.json` (its mesh is reused), else
    /// `openfoam` beside `--out`.
    #[arg(long = "of-dir")]
    pub(super) of_dir: Option<PathBuf>,
    #[command(flatten)]
    pub(super) openfoam: OpenFoamArgs,
}

/// The model `kalibre simulate` runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SimulateModel {
    /// The built-in simulator.
    Builtin,
    /// OpenFOAM (`buoyantBoussinesqSimpleFoam`).
    Openfoam,
    /// Any simulator driven through files, described by `--config model.toml`.
    Command,
}

/// How far the calibration's own misfit says to trust the headrooms: with a report as
/// `--params`, the note on the cold-aisle sensor the model reads coldest.
pub(super) fn print_under_read_note(
    args: &SimulateArgs,
    file: Option<&(serde_json::Value, Option<CalibratedModel>)>,
    hall: &Hall,
    labels: &[String],
    headroom_c: &[Option<f64>],
) -> CliResult {
    let residuals: Option<Vec<kalibre_core::calibrate::Residual>> = match (
        &args.params,
        file.and_then(|(json, _)| json.get("residuals")),
    ) {
        (Some(path), Some(r)) => Some(
            serde_json::from_value(r.clone())
                .map_err(|e| CliError::Input(format!("{}: /residuals: {e}", path.display())))?,
        ),
        _ => None,
    };
    if let Some(under) = residuals.and_then(|r| coldest_under_read(hall, &r)) {
        say!("{}", under_read_note(&under, labels, headroom_c));
    }
    Ok(())
}

/// The first of `given` (flag, whether given) that was given, refused with `why(flag)`:
/// the options another model than the built-in simulator does not have.
pub(super) fn refuse_given(given: &[(&str, bool)], why: impl Fn(&str) -> String) -> CliResult {
    match given.iter().find(|(_, g)| *g) {
        Some((flag, _)) => Err(CliError::Input(why(flag))),
        None => Ok(()),
    }
}

/// `--inlet-limit-c`, or ASHRAE's recommended bound.
pub(super) fn inlet_limit_c(args: &SimulateArgs) -> CliResult<f64> {
    match args.inlet_limit_c {
        None => Ok(kalibre_dc::sim::RECOMMENDED_MAX_INLET_C),
        Some(t) if AIR_C_RANGE.contains(&t) => Ok(t),
        Some(t) => Err(CliError::Input(format!(
            "--inlet-limit-c: {} C is not an air temperature; expected a limit in [{}, {}] C",
            number(t),
            AIR_C_RANGE.start(),
            AIR_C_RANGE.end()
        ))),
    }
}

/// Refuses snapshots whose `--vtk` files would be one file (labels that differ only in
/// characters a file name cannot hold, or only in case, which some file systems fold),
/// before any solve: one snapshot's fields would silently replace another's.
fn check_vtk_names(snaps: &[snapshots::HallSnapshot]) -> CliResult {
    let mut taken = std::collections::HashMap::new();
    for s in snaps {
        let label = s.state.label.as_str();
        let name = kalibre_dc::sim::vtk_file_name(label);
        if let Some(other) = taken.insert(name.to_lowercase(), label) {
            return Err(CliError::Input(format!(
                "--vtk: snapshots `{other}` and `{label}` would both be written to {name}; give \
                 them labels that differ in letters or digits",
            )));
        }
    }
    Ok(())
}

/// Each `--grid-check` factor's cell size and, per snapshot, the setpoint headroom there.
fn finer_headrooms(
    hall: &Hall,
    snaps: &[kalibre_dc::snapshots::HallSnapshot],
    params: &[f64],
    grid_m: Option<f64>,
    args: &SimulateArgs,
) -> CliResult<Vec<(f64, Vec<f64>)>> {
    let base = sim_config(grid_m)?.cell_m;
    args.grid_check
        .iter()
        .map(|&f| {
            let model = HallModel::new(hall, sim_config(Some(base * f))?)?;
            let rooms = snaps
                .iter()
                .map(|snap| {
                    let air = model.server_air(&snap.state, params).map_err(|e| {
                        CliError::Run(format!(
                            "snapshot `{}` at {:.3} m: {e}",
                            snap.state.label,
                            base * f
                        ))
                    })?;
                    let check = kalibre_dc::sim::inlet_check(&air, inlet_limit_c(args)?, 1)?;
                    Ok(setpoint_headroom_c(&check).unwrap_or(f64::NAN))
                })
                .collect::<CliResult<Vec<f64>>>()?;
            Ok((base * f, rooms))
        })
        .collect()
}

/// The simulator configuration for `--grid-m`.
pub fn sim_config(grid_m: Option<f64>) -> CliResult<SimConfig> {
    let mut config = SimConfig::default();
    if let Some(dx) = grid_m {
        if !(dx.is_finite() && dx > 0.0) {
            return Err(CliError::Input(format!(
                "--grid-m: expected a positive cell size in metres, got {dx}"
            )));
        }
        config = config.with_cell_m(dx);
    }
    config
        .check()
        .map_err(|e| CliError::Input(format!("--grid-m: {e}")))?;
    Ok(config)
}

/// The built-in model's cells for `hall` (read from `hall_path`) at `cell_m` (from
/// `--grid-m` when `grid_given`, else a calibration's record or the default): a room too
/// fine to build is refused before anything runs, rather than failing as the model's
/// (exit 1) when it is built. Without `--grid-m` the room is blamed, not a flag never
/// given: a hall written in millimetres is a thousand times too large.
pub(super) fn check_model_cells(
    hall: &Hall,
    hall_path: &Path,
    cell_m: f64,
    grid_given: bool,
) -> CliResult {
    let Some(cells) = kalibre_dc::sim::cells_beyond_cap(hall.room.size_m, cell_m) else {
        return Ok(());
    };
    let cap = kalibre_dc::sim::MAX_CELLS;
    Err(CliError::Input(if grid_given {
        format!(
            "--grid-m: cells of {} m give {cells:.3e} cells in this room, above the built-in \
             simulator's {cap}: use coarser cells",
            number(cell_m),
        )
    } else {
        let [x, y, z] = hall.room.size_m.map(number);
        format!(
            "{}: /room/size_m: a room of {x} x {y} x {z} m needs {cells:.3e} cells of {} m, \
             above the built-in simulator's {cap}: are its lengths in metres? (a hall this \
             large needs coarser cells: --grid-m)",
            hall_path.display(),
            number(cell_m),
        )
    }))
}

/// An output path that names an input file would replace the measurements (or the hall)
/// with predictions: refused before anything runs.
/// `vtk_files` are `--vtk`'s files (flag-like name, path), once the snapshots are known.
fn refuse_overwriting_inputs(args: &SimulateArgs, vtk_files: &[(String, PathBuf)]) -> CliResult {
    // A calibration's report as --params has its journal beside it.
    let journal = args
        .params
        .as_ref()
        .and_then(|p| p.parent())
        .map(|d| d.join("runs.jsonl"));
    let mut outputs = vec![
        ("--out", Some(args.out.as_path())),
        ("--servers", args.servers.as_deref()),
        ("--heat-sources", args.heat_sources.as_deref()),
        // A directory at an output file's path: the run would end on that file.
        ("--vtk", args.vtk.as_deref()),
    ];
    outputs.extend(
        vtk_files
            .iter()
            .map(|(what, p)| (what.as_str(), Some(p.as_path()))),
    );
    super::same_file::refuse_same_files(
        &outputs,
        &[
            ("the --hall file", args.hall.as_deref()),
            ("the --snapshots file", args.snapshots.as_deref()),
            ("the --params file", args.params.as_deref()),
            ("the --config file", args.config.as_deref()),
            ("the run journal beside --params", journal.as_deref()),
        ],
    )
}

/// The flags about a solve's fields, servers and grid, each with whether it was given:
/// what the built-in simulator and OpenFOAM give and a command's readings do not.
pub(super) fn field_and_grid_flags(args: &SimulateArgs) -> [(&'static str, bool); 7] {
    [
        ("--vtk", args.vtk.is_some()),
        ("--heat-sources", args.heat_sources.is_some()),
        ("--grid-check", !args.grid_check.is_empty()),
        ("--servers", args.servers.is_some()),
        ("--inlet-limit-c", args.inlet_limit_c.is_some()),
        ("--grid-m", args.grid_m.is_some()),
        ("--of-dir", args.of_dir.is_some()),
    ]
}

impl SimulateArgs {
    /// The model to run: `--model`'s, else the built-in simulator.
    pub(super) fn model(&self) -> SimulateModel {
        self.model_arg.unwrap_or(SimulateModel::Builtin)
    }
}

/// Runs `kalibre simulate`.
pub fn run(args: SimulateArgs) -> CliResult {
    // Nothing is journaled here, so a stop cannot promise a resume.
    kalibre_core::external::set_stop_message(kalibre_core::external::StopMessage {
        runs_ended: match args.model() {
            SimulateModel::Openfoam => {
                "kalibre: stopped; the OpenFOAM solves or meshing in progress were ended \
                 with it (simulate keeps no journal: run it again to redo them)\n"
            }
            _ => {
                "kalibre: stopped; the model runs in progress were ended with it \
                 (simulate keeps no journal: run it again to redo them)\n"
            }
        },
        no_runs: "kalibre: stopped (simulate keeps no journal: run it again to redo its runs)\n",
    });
    match (args.model(), &args.config) {
        (SimulateModel::Command, None) => {
            return Err(CliError::Input(
                "--model command needs --config model.toml (see docs/models.md)".into(),
            ))
        }
        (SimulateModel::Builtin | SimulateModel::Openfoam, Some(_)) => {
            return Err(CliError::Input("--config is for --model command".into()))
        }
        _ => {}
    }
    refuse_overwriting_inputs(&args, &[])?;
    super::say_to_stderr_if_stdout(&args.out);
    let (hall_path, snaps_path) = match (&args.hall, &args.snapshots) {
        (Some(h), Some(s)) => (h.clone(), s.clone()),
        (None, None) if args.model() == SimulateModel::Command => {
            return super::simulate_own::run(&args)
        }
        _ => {
            return Err(CliError::Input(
                "a hall's simulation needs --hall hall.json and --snapshots snapshots.csv; a \
                 model of your own runs at its [[scenarios]] with --model command --config \
                 model.toml and neither"
                    .into(),
            ))
        }
    };
    // Before anything is written, so a bad factor never replaces a good `--out`.
    super::calibrate::check_grid_factors(&args.grid_check)?;
    inlet_limit_c(&args)?;
    let hall = Hall::load(&hall_path)?;
    kalibre_dc::effects::EffectRegistry::builtin()
        .check_hall(&hall, &hall_path.display().to_string())?;
    let mut snaps = snapshots::load_states(&hall, &snaps_path)?;
    // After the inputs (their errors first), before the solves.
    for (flag, path) in [
        ("--out", Some(&args.out)),
        ("--servers", args.servers.as_ref()),
        ("--heat-sources", args.heat_sources.as_ref()),
    ] {
        if let Some(path) = path {
            super::out_dir::check_out_file(flag, path)?;
        }
    }
    // Before any what-if: the warning is about the files.
    super::plausible::warn_setpoints(&snaps_path, &hall, snaps.iter().map(|s| &s.state));
    let states = snaps.iter().map(|s| &s.state);
    super::plausible::warn_alpha_units(&hall_path, &hall);
    super::plausible::warn_implausible_rises(&hall_path, &snaps_path, &hall, states)?;
    if let Some(dir) = &args.vtk {
        check_vtk_names(&snaps)?;
        let files: Vec<(String, PathBuf)> = snaps
            .iter()
            .map(|s| {
                let name = kalibre_dc::sim::vtk_file_name(&s.state.label);
                (format!("--vtk's {name}"), dir.join(name))
            })
            .collect();
        refuse_overwriting_inputs(&args, &files)?;
    }
    args.what_if.apply(&hall, &mut snaps)?;
    let what_if = args.what_if.describe();
    if let Some(what) = &what_if {
        say!("what if: {what} (in every snapshot)");
        let states = snaps.iter().map(|s| &s.state);
        super::plausible::warn_what_if_beyond_halls(what, &hall, states)?;
    }
    let file = args.params.as_deref().map(read_params_file).transpose()?;
    args.openfoam
        .refuse_unless(args.model() == SimulateModel::Openfoam)?;
    match args.model() {
        SimulateModel::Openfoam => {
            return super::simulate_openfoam::run(&args, &hall_path, &hall, &snaps, file.as_ref())
        }
        SimulateModel::Command => {
            return super::simulate_command::run(&args, &hall, &snaps, file.as_ref())
        }
        SimulateModel::Builtin => {}
    }
    if args.of_dir.is_some() {
        return Err(CliError::Input(
            "--of-dir is an OpenFOAM option: add --model openfoam".into(),
        ));
    }
    let recorded = file.as_ref().and_then(|(_, m)| m.as_ref());
    // A calibration's report brings the model it ran: its alpha mode and grid stand
    // unless --grid-m is given.
    if let Some(m) = recorded.filter(|m| m.kind != "builtin") {
        let path = args
            .params
            .as_deref()
            .expect("a record comes from --params");
        let run_it = match m.kind.as_str() {
            "command" => "--model command --config model.toml runs it".to_string(),
            kind => format!("--model {kind} runs it"),
        };
        // Unasked, the built-in simulator would answer for a model it is not.
        if args.model_arg.is_none() {
            return Err(CliError::Input(format!(
                "{}: the calibration ran the {} model: {run_it}, and --model builtin runs the \
                 built-in simulator at its parameters",
                path.display(),
                m.kind
            )));
        }
        eprintln!(
            "note: the calibration ran the {} model; simulate runs the built-in simulator at \
             its parameters, as --model builtin asks ({run_it})",
            m.kind
        );
    }
    let hall = match recorded {
        Some(m) => m.calibrated_hall(&hall),
        None => hall,
    };
    let grid_m = match recorded.filter(|m| m.kind == "builtin") {
        Some(m) => {
            if args.grid_m.is_none() {
                let path = args
                    .params
                    .as_deref()
                    .expect("a record comes from --params");
                m.check_cells(path, &hall)?;
            }
            grid_or_recorded(args.grid_m, Some(m))
        }
        None => args.grid_m,
    };
    let config = sim_config(grid_m)?;
    check_model_cells(&hall, &hall_path, config.cell_m, args.grid_m.is_some())?;
    super::plausible::warn_builtin_hall(&hall_path, &hall, config.cell_m);
    // Before any solve: a factor whose grid is the model's own in this room, or too
    // fine to build, would otherwise fail (or check nothing) after the predictions.
    super::calibrate::check_finer_grids(&hall, config.cell_m, &args.grid_check)?;
    let model = HallModel::new(&hall, config)
        .map_err(|e| e.in_hall_file(&hall_path.display().to_string()))?;
    let space = model.layout().space();
    let params = match (&args.params, &file) {
        (Some(p), Some((json, _))) => load_params(p, json, space)?,
        _ => space.initial(),
    };
    let limit_c = inlet_limit_c(&args)?;
    let mut labels = Vec::with_capacity(snaps.len());
    let mut predicted = Vec::with_capacity(snaps.len());
    let mut air = Vec::new();
    let mut checks = Vec::with_capacity(snaps.len());
    let mut sources = Vec::new();
    let sensor_names: Vec<String> = hall.sensors.iter().map(|s| s.id.clone()).collect();
    for snap in &snaps {
        let state = &snap.state;
        let failed =
            |e: &dyn std::fmt::Display| CliError::Run(format!("snapshot `{}`: {e}", state.label));
        let solution = match &args.heat_sources {
            Some(_) => {
                let (solution, rows) = model.rack_heat(state, &params).map_err(|e| failed(&e))?;
                sources.extend(
                    rows.into_iter()
                        .filter(|r| r.share >= HEAT_SOURCE_MIN_SHARE),
                );
                solution
            }
            None => model.solve(state, &params).map_err(|e| failed(&e))?,
        };
        // Past what any air can be, a what-if's answer is the question's fault: the
        // change is refused by name (exit 2), not reported as a failed model.
        let unpredictable = |e: &dyn std::fmt::Display| match what_if.as_deref() {
            Some(what) => CliError::Input(format!(
                "what if {what}: snapshot `{}`: {e}; the change takes the hall past anything \
                 the model can predict: ask a smaller one",
                state.label
            )),
            None => failed(e),
        };
        if let Some(k) = solution.sensor_c().iter().position(|v| !v.is_finite()) {
            return Err(unpredictable(&format!(
                "sensor `{}` came out as {}",
                hall.sensors[k].id,
                solution.sensor_c()[k]
            )));
        }
        // What calibration refuses as a run (e.g. air at 1e9 C, from a fan speed near 0)
        // is no prediction either.
        kalibre_dc::check_sensor_c(solution.sensor_c(), &sensor_names)
            .map_err(|e| unpredictable(&e))?;
        if let Some(dir) = &args.vtk {
            kalibre_dc::sim::write_vtk(dir, model.simulator(), &solution)?;
        }
        let servers = kalibre_dc::sim::server_air(&hall, state, &solution)?;
        checks.push(kalibre_dc::sim::inlet_check(&servers, limit_c, 3)?);
        if args.servers.is_some() {
            air.extend(servers);
        }
        labels.push(state.label.clone());
        predicted.push(solution.sensor_c().to_vec());
    }
    // Each file whole or not at all, the side tables first: a failure there leaves the
    // predictions of --out as they were, not new predictions beside old tables.
    if let Some(path) = &args.servers {
        kalibre_core::write_atomic(path, kalibre_dc::sim::write_server_air(&air))
            .map_err(|e| io_err(path, e))?;
    }
    if let Some(path) = &args.heat_sources {
        kalibre_core::write_atomic(path, kalibre_dc::sim::write_rack_heat(&sources))
            .map_err(|e| io_err(path, e))?;
    }
    let csv = snapshots::write_predictions(&hall, &labels, &predicted);
    kalibre_core::write_atomic(&args.out, csv).map_err(|e| io_err(&args.out, e))?;
    say_if_uncalibrated(&args);
    for (label, check) in labels.iter().zip(&checks) {
        say!("{}", inlet_line(label, check));
    }
    // Each snapshot's headroom, the least over the finer grids when asked for.
    let mut headroom: Vec<Option<f64>> = checks.iter().map(setpoint_headroom_c).collect();
    if !args.grid_check.is_empty() {
        let fine = finer_headrooms(&hall, &snaps, &params, grid_m, &args)?;
        for (k, label) in labels.iter().enumerate() {
            let shown: Vec<String> = fine
                .iter()
                .map(|(cell_m, rooms)| format!("{:.2} C at {cell_m:.3} m", rooms[k]))
                .collect();
            headroom[k] = fine
                .iter()
                .map(|(_, rooms)| rooms[k])
                .chain(headroom[k])
                .reduce(f64::min);
            say!(
                "{label}: on finer grids the headroom is {}; the least, {:.2} C, allows for the grid",
                shown.join(", "),
                headroom[k].unwrap_or(f64::NAN)
            );
        }
    }
    print_under_read_note(&args, file.as_ref(), &hall, &labels, &headroom)?;
    say!(
        "wrote {} ({} x {} sensors){}",
        args.out.display(),
        super::counted(labels.len(), "snapshot"),
        hall.sensors.len(),
        args.vtk
            .as_ref()
            .map(|d| format!(", VTK fields in {}", d.display()))
            .unwrap_or_default()
    );
    if let Some(path) = &args.heat_sources {
        say!(
            "wrote {} (per snapshot and sensor, the racks giving at least {:.0} % of its warming)",
            path.display(),
            100.0 * HEAT_SOURCE_MIN_SHARE
        );
    }
    print_servers_written(&args, &labels, &hall);
    Ok(())
}

/// Without `--params`, says that the intake figures to follow are the uncalibrated
/// model's: they read as advice, and the hall's initial parameters can be degrees off.
pub(super) fn say_if_uncalibrated(args: &SimulateArgs) {
    if args.params.is_none() {
        say!(
            "at the hall's initial parameters, not calibrated (--params with a calibration's \
             report.json gives the calibrated model's):"
        );
    }
}

/// Says where `--servers` wrote the servers' air, if asked for.
pub(super) fn print_servers_written(args: &SimulateArgs, labels: &[String], hall: &Hall) {
    if let Some(path) = &args.servers {
        say!(
            "wrote {} ({} x {} servers)",
            path.display(),
            super::counted(labels.len(), "snapshot"),
            hall.servers().count()
        );
    }
}
