//! `kalibre simulate`: the built-in simulator on a hall's snapshots.

use std::path::{Path, PathBuf};

use clap::Args;
use kalibre_core::{Model, ParamSpace};
use kalibre_dc::hall::Hall;
use kalibre_dc::sim::SimConfig;
use kalibre_dc::snapshots;
use kalibre_dc::HallModel;

use super::{io_err, CliError, CliResult};

/// Options of `kalibre simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// The hall (`hall.json`).
    #[arg(long)]
    hall: PathBuf,
    /// Operating conditions (`snapshots.csv`); sensor readings in it are ignored.
    #[arg(long)]
    snapshots: PathBuf,
    /// Parameter values: a JSON object `{ "alpha/<type>": 0.12, ... }`, or a calibration's
    /// `report.json` (its best parameters). Parameters not given keep the hall's initial values.
    #[arg(long)]
    params: Option<PathBuf>,
    /// Where to write the predicted sensor readings (snapshot CSV format, kind `sensor_c`).
    #[arg(long)]
    out: PathBuf,
    /// Also write temperature, pressure and velocity fields as VTK files (one per snapshot)
    /// into this directory, for ParaView.
    #[arg(long)]
    vtk: Option<PathBuf>,
    /// Grid cell size of the built-in simulator (m).
    #[arg(long = "grid-m")]
    grid_m: Option<f64>,
}

/// Reads parameter values by name from a JSON object or a report's `best.params`.
pub fn load_params(path: &Path, space: &ParamSpace) -> CliResult<Vec<f64>> {
    let file = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    let json: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| CliError::Input(format!("{file}: not valid JSON: {e}")))?;
    let (map, pointer) = match json.get("best").and_then(|b| b.get("params")) {
        Some(p) => (p, "/best/params"),
        None => (&json, ""),
    };
    let map = map.as_object().ok_or_else(|| {
        CliError::Input(format!(
            "{file}: {}: expected an object of parameter name -> value",
            if pointer.is_empty() { "/" } else { pointer }
        ))
    })?;
    let mut values = space.initial();
    for (name, v) in map {
        let i = space.index_of(name).ok_or_else(|| {
            CliError::Input(format!(
                "{file}: {pointer}/{name}: unknown parameter (known: {})",
                space.names().join(", ")
            ))
        })?;
        let x = v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
            CliError::Input(format!(
                "{file}: {pointer}/{name}: expected a finite number"
            ))
        })?;
        values[i] = x;
    }
    space
        .check_physical(&values)
        .map_err(|e| CliError::Input(format!("{file}: {e}")))?;
    Ok(values)
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

/// Runs `kalibre simulate`.
pub fn run(args: SimulateArgs) -> CliResult {
    let hall = Hall::load(&args.hall)?;
    kalibre_dc::effects::EffectRegistry::builtin()
        .check_hall(&hall, &args.hall.display().to_string())?;
    let snaps = snapshots::load_snapshots(&hall, &args.snapshots)?;
    let model = HallModel::new(&hall, sim_config(args.grid_m)?)?;
    let space = model.layout().space();
    let params = match &args.params {
        Some(p) => load_params(p, space)?,
        None => space.initial(),
    };
    let mut labels = Vec::with_capacity(snaps.len());
    let mut predicted = Vec::with_capacity(snaps.len());
    for snap in &snaps {
        let state = &snap.state;
        let values = match &args.vtk {
            Some(dir) => {
                let solution = model.solve(state, &params)?;
                kalibre_dc::sim::write_vtk(dir, model.simulator(), &solution)?;
                solution.sensor_c().to_vec()
            }
            None => {
                model
                    .evaluate(state, &params)
                    .map_err(|e| CliError::Run(format!("snapshot `{}`: {e}", state.label)))?
                    .values
            }
        };
        labels.push(state.label.clone());
        predicted.push(values);
    }
    let csv = snapshots::write_predictions(&hall, &labels, &predicted);
    std::fs::write(&args.out, csv).map_err(|e| io_err(&args.out, e))?;
    println!(
        "wrote {} ({} snapshots x {} sensors){}",
        args.out.display(),
        labels.len(),
        hall.sensors.len(),
        args.vtk
            .as_ref()
            .map(|d| format!(", VTK fields in {}", d.display()))
            .unwrap_or_default()
    );
    Ok(())
}
