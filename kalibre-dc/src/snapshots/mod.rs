//! Operating conditions and measurements (`snapshots.csv`), resolved against a hall:
//! reading with every rule of `formats.md` section 2 enforced, writing measurements and
//! predictions, and conversion into the core's [`kalibre_core::Observations`].

mod hints;
mod lexical;
mod measurements;
mod plausible;
mod read;
mod write;

use kalibre_core::{Observations, OutputInfo, Snapshot};

use crate::hall::Hall;
use crate::{Error, Result};

pub use measurements::{load_measurements, parse_measurements, Measurements, ScenarioMeasurements};
pub use plausible::{
    implausible_rises, implausible_setpoints, readings_above_supply, readings_below_supply,
    stuck_sensors, ColdReading, HotReading, ImplausibleRise, ImplausibleSetpoint, StuckSensor,
    ABOVE_SUPPLY_MARGIN_C, BELOW_SUPPLY_MARGIN_C, HOT_AISLE_ABOVE_SUPPLY_MARGIN_C, MAX_MEAN_RISE_K,
    MAX_SETPOINT_C, MIN_MEAN_RISE_K,
};
pub use read::{load_snapshots, load_states, parse_snapshots, parse_snapshots_bytes};
pub(crate) use write::quote;
pub use write::{write_predictions, write_snapshots};

/// The air temperatures (C) a data hall's setpoints and sensors can read. Outside them a
/// value is a unit or export error (or below absolute zero), not a measurement.
pub const AIR_C_RANGE: std::ops::RangeInclusive<f64> = -50.0..=150.0;

/// The most power (W) one row may give a server or a rack: 10 MW, a whole hall's worth.
pub const MAX_POWER_W: f64 = 1e7;

/// Why a setpoint or sensor reading `v` (C) is not an air temperature; `None` when it is.
pub(crate) fn air_c_problem(what: &str, v: f64) -> Option<String> {
    let (lo, hi) = (AIR_C_RANGE.start(), AIR_C_RANGE.end());
    (!AIR_C_RANGE.contains(&v)).then(|| {
        format!(
            "{what} is {} C; expected an air temperature in [{lo}, {hi}] C",
            number(v)
        )
    })
}

/// Numbers in messages (kept here for the crate's many callers).
pub use kalibre_core::number;

/// One operating state of the hall: what the model is run at. Vectors are in hall order
/// (CRACs as listed, servers as [`crate::hall::Hall::servers`] yields them).
#[derive(Debug, Clone, PartialEq)]
pub struct OperatingState {
    /// Snapshot label.
    pub label: String,
    /// Supply temperature setpoint per CRAC (C).
    pub setpoint_c: Vec<f64>,
    /// Fan speed ratio per CRAC, in `[0, 1]`.
    pub fan_speed: Vec<f64>,
    /// Power per server (W); rack-level readings already shared out by `height_u`.
    pub power_w: Vec<f64>,
}

/// A snapshot: the operating state and the sensor readings under it.
#[derive(Debug, Clone, PartialEq)]
pub struct HallSnapshot {
    /// The operating state.
    pub state: OperatingState,
    /// Measured temperature per sensor (hall order); `None` for a sensor with no reading.
    pub sensor_c: Vec<Option<f64>>,
}

/// Observations for calibration: one output per sensor in hall order, grouped by aisle
/// (`cold` or `hot`), one core snapshot per hall snapshot with its operating state.
pub fn to_observations(
    hall: &Hall,
    snapshots: &[HallSnapshot],
) -> Result<Observations<OperatingState>> {
    let outputs: Vec<OutputInfo> = hall
        .sensors
        .iter()
        .map(|s| OutputInfo {
            name: s.id.clone(),
            group: s.aisle.as_str().to_string(),
        })
        .collect();
    let (n_cracs, n_servers) = (hall.cracs.len(), hall.server_count());
    for s in snapshots {
        let st = &s.state;
        if st.setpoint_c.len() != n_cracs
            || st.fan_speed.len() != n_cracs
            || st.power_w.len() != n_servers
        {
            return Err(Error::Mismatch(format!(
                "snapshot `{}` has {} setpoints, {} fan speeds and {} powers; the hall has {n_cracs} CRACs and {n_servers} servers",
                st.label,
                st.setpoint_c.len(),
                st.fan_speed.len(),
                st.power_w.len()
            )));
        }
    }
    let core: Vec<Snapshot<OperatingState>> = snapshots
        .iter()
        .map(|s| Snapshot {
            label: s.state.label.clone(),
            scenario: s.state.clone(),
            measured: s.sensor_c.clone(),
        })
        .collect();
    Ok(Observations::new(outputs, core)?)
}
