//! What `kalibre calibrate` records in `report.json` about the model it ran (`model`), so
//! that `kalibre diagnose` and `kalibre simulate --params report.json` run the same model
//! without the user repeating its options.

use std::path::Path;

use kalibre_dc::hall::{AlphaMode, Hall};
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
