//! Operating conditions and measurements (`snapshots.csv`), resolved against a hall.

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
