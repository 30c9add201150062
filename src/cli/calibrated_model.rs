//! What `kalibre calibrate` records in `report.json` about the model it ran (`model`), so
//! that `kalibre diagnose` and `kalibre simulate --params report.json` run the same model
//! without the user repeating its options, and what `diagnose` checks against it.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::operating_state_key;
use kalibre_dc::snapshots::HallSnapshot;
use serde::{Deserialize, Serialize};

use super::{CliError, CliResult};

/// The model a calibration ran: `report.json`'s `model`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibratedModel {
    /// `builtin`, `openfoam` or `command`.
    pub kind: String,
    /// Grid cell size (m) of the built-in simulator or of the OpenFOAM mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid_m: Option<f64>,
    /// How alpha was calibrated (`kalibre calibrate --alpha`, else the hall's own).
    pub alpha: AlphaMode,
    /// OpenFOAM: SIMPLE iterations per solve.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub of_iterations: Option<u32>,
    /// OpenFOAM: processes per solve.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub np: Option<u32>,
    /// The model's fingerprint (`Model::fingerprint`: its hall, effects, grid and
    /// options), so that `diagnose` refuses another hall even when the run journal is
    /// gone. Missing in older reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fingerprint: Option<String>,
    /// Each snapshot's label and the digest of its setpoints, fan speeds and powers
    /// (`Model::scenario_key`), so that `diagnose` refuses a `snapshots.csv` whose
    /// conditions were edited under the same labels (the readings alone would pass).
    /// Missing in older reports and for a command model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario_keys: Option<std::collections::BTreeMap<String, String>>,
}

impl CalibratedModel {
    /// The record as `report.json` stores it.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }

    /// The record of a report (`None` for reports written before it existed, or by the
    /// library); a record that does not parse is an error naming the file.
    pub fn of_report(
        report_path: &Path,
        model: Option<&serde_json::Value>,
    ) -> CliResult<Option<Self>> {
        let Some(m) = model else {
            return Ok(None);
        };
        let bad = |pointer: &str, e: &dyn std::fmt::Display| {
            CliError::Input(format!("{}: {pointer}: {e}", report_path.display()))
        };
        // A model of your own's record (`kalibre calibrate --measurements`) names its
        // model.toml and no hall: its parameters are not a hall's to simulate or diagnose.
        if let Some(config) = m.get("config").and_then(|c| c.as_str()) {
            return Err(bad(
                "/model",
                &format!(
                    "the calibration of a model of your own ({config}, with --measurements), \
                     not of a hall: `--hall` takes a hall's calibration; `kalibre diagnose \
                     --model command --config {config} --measurements ... --calibration {}` \
                     diagnoses that model, and `kalibre simulate --model command --config \
                     {config} --params {}` runs it at its parameters",
                    (report_path.parent())
                        .filter(|d| !d.as_os_str().is_empty())
                        .unwrap_or(Path::new("."))
                        .display(),
                    report_path.display()
                ),
            ));
        }
        let record: Self = serde_json::from_value(m.clone())
            .map_err(|e| bad("/model", &format!("not a kalibre model record: {e}")))?;
        // Checked here so that an edited record is blamed, not a `--grid-m` never given.
        if let Some(dx) = record.grid_m {
            if !(dx.is_finite() && dx > 0.0) {
                return Err(bad(
                    "/model/grid_m",
                    &format!("{dx} is not a cell size in m"),
                ));
            }
            if record.kind == "builtin" {
                kalibre_dc::sim::SimConfig::default()
                    .with_cell_m(dx)
                    .check()
                    .map_err(|e| bad("/model/grid_m", &e))?;
            }
        }
        Ok(Some(record))
    }

    /// Refuses a recorded built-in grid too fine for `hall`'s room, naming the record (the
    /// simulator's own message would blame a `--grid-m` that was never given).
    pub fn check_cells(&self, report_path: &Path, hall: &Hall) -> CliResult {
        use kalibre_dc::sim::{cells_beyond_cap, MAX_CELLS};
        let Some(dx) = self.grid_m.filter(|_| self.kind == "builtin") else {
            return Ok(());
        };
        if let Some(cells) = cells_beyond_cap(hall.room.size_m, dx) {
            return Err(CliError::Input(format!(
                "{}: /model/grid_m: cells of {dx} m need {cells:.3e} cells in hall `{}`; the \
                 built-in simulator takes at most {MAX_CELLS} (give a coarser --grid-m to \
                 run at another grid)",
                report_path.display(),
                hall.name
            )));
        }
        Ok(())
    }

    /// The hall as it was calibrated: its alpha mode set to the calibration's.
    pub fn calibrated_hall(&self, hall: &Hall) -> Hall {
        let mut hall = hall.clone();
        hall.calibrate.alpha = self.alpha;
        hall
    }
}

/// `--grid-m` when given, else the calibration's grid.
pub fn grid_or_recorded(flag: Option<f64>, recorded: Option<&CalibratedModel>) -> Option<f64> {
    flag.or_else(|| recorded.and_then(|m| m.grid_m))
}

/// Refuses measurements other than those the calibration fitted (`report.json`'s residual
/// rows): a diagnosis of other readings would blame the model, or an effect, for the
/// difference. A report with no rows (no run succeeded) has nothing to compare.
pub fn check_same_measurements(
    report_path: &Path,
    residuals: &[kalibre_core::calibrate::Residual],
    snapshots_path: &Path,
    hall: &Hall,
    snaps: &[HallSnapshot],
) -> CliResult {
    match measurement_difference(residuals, hall, snaps) {
        MeasurementDifference::Same => Ok(()),
        MeasurementDifference::Readings(what) => Err(CliError::Input(format!(
            "{}: not the measurements {} was calibrated on: {what}; diagnose with the \
             calibration's snapshots, or calibrate again",
            snapshots_path.display(),
            report_path.display()
        ))),
        MeasurementDifference::Sensor(sensor) => Err(CliError::Input(format!(
            "{}: /residuals: sensor `{sensor}` is not in hall `{}`; this calibration is of \
             another hall",
            report_path.display(),
            hall.name
        ))),
    }
}

/// How a calibration's residual rows compare with `snaps`' readings.
pub enum MeasurementDifference {
    /// The same readings (or no rows to compare).
    Same,
    /// Other readings: the first difference, in words.
    Readings(String),
    /// A sensor the hall does not have: a calibration of another hall.
    Sensor(String),
}

/// The first difference between the readings a calibration fitted (`residuals`) and
/// `snaps`' readings.
pub fn measurement_difference(
    residuals: &[kalibre_core::calibrate::Residual],
    hall: &Hall,
    snaps: &[HallSnapshot],
) -> MeasurementDifference {
    use MeasurementDifference::{Readings, Same, Sensor};
    if residuals.is_empty() {
        return Same;
    }
    let snapshot_at: HashMap<&str, &HallSnapshot> =
        snaps.iter().map(|s| (s.state.label.as_str(), s)).collect();
    let sensor_at: HashMap<&str, usize> = hall
        .sensors
        .iter()
        .enumerate()
        .map(|(i, s)| (s.id.as_str(), i))
        .collect();
    let mut fitted = HashSet::with_capacity(residuals.len());
    for r in residuals {
        let Some(snap) = snapshot_at.get(r.snapshot.as_str()) else {
            return Readings(format!("snapshot `{}` is not there", r.snapshot));
        };
        let Some(&i) = sensor_at.get(r.sensor.as_str()) else {
            // Not a reading the snapshots lack: a sensor the hall does not have.
            return Sensor(r.sensor.clone());
        };
        match snap.sensor_c[i] {
            None => {
                return Readings(format!(
                    "snapshot `{}` has no reading of sensor `{}`",
                    r.snapshot, r.sensor
                ))
            }
            // The report's decimal form parses back to within an ulp or so.
            Some(c) if (c - r.measured_c).abs() > 1e-9 * c.abs().max(1.0) => {
                return Readings(format!(
                    "snapshot `{}`, sensor `{}` reads {c} C, the calibration's {} C",
                    r.snapshot, r.sensor, r.measured_c
                ))
            }
            Some(_) => {}
        }
        fitted.insert((r.snapshot.as_str(), r.sensor.as_str()));
    }
    for s in snaps {
        for (sensor, c) in hall.sensors.iter().zip(&s.sensor_c) {
            if c.is_some() && !fitted.contains(&(s.state.label.as_str(), sensor.id.as_str())) {
                return Readings(format!(
                    "snapshot `{}`, sensor `{}` has a reading the calibration did not have",
                    s.state.label, sensor.id
                ));
            }
        }
    }
    Same
}

/// The conditions each snapshot of a hall calibration ran at, for
/// [`CalibratedModel::scenario_keys`].
pub fn scenario_keys(snaps: &[HallSnapshot]) -> std::collections::BTreeMap<String, String> {
    snaps
        .iter()
        .map(|s| (s.state.label.clone(), operating_state_key(&s.state)))
        .collect()
}

/// Refuses snapshots whose setpoints, fan speeds or powers differ from those the
/// calibration ran under the same label: the calibrated model would be run at conditions
/// it was never fitted at, and the diagnosis would blame an effect for the difference.
/// The keys come from the report's model record, else from the journal's runs
/// (`journal_keys`: each label's keys); a label neither knows is not checked.
pub fn check_same_conditions(
    report_path: &Path,
    recorded: Option<&CalibratedModel>,
    journal_keys: &HashMap<String, HashSet<String>>,
    snapshots_path: &Path,
    snaps: &[HallSnapshot],
) -> CliResult {
    for s in snaps {
        let label = s.state.label.as_str();
        let key = operating_state_key(&s.state);
        let (known, source) = match recorded.and_then(|m| m.scenario_keys.as_ref()) {
            Some(keys) => match keys.get(label) {
                Some(k) => (*k == key, report_path.display().to_string()),
                None => continue,
            },
            None => match journal_keys.get(label) {
                Some(keys) => (keys.contains(&key), "its runs.jsonl".to_string()),
                None => continue,
            },
        };
        if !known {
            return Err(CliError::Input(format!(
                "{}: snapshot `{label}`: its setpoints, fan speeds or powers are not those the \
                 calibration ran at (as {source} records them); diagnose with the \
                 calibration's snapshots, or calibrate again",
                snapshots_path.display()
            )));
        }
    }
    Ok(())
}
