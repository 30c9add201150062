//! Readings no state of the hall can produce: air colder than every running CRAC's
//! supply. Mixing only warms supply air (servers add heat, nothing in an air-cooled hall
//! removes it but the CRACs), so such a reading is a faulty sensor or a typing slip, and
//! a least-squares fit would bend every parameter toward it.

use super::HallSnapshot;
use crate::hall::Hall;

/// How far below the coldest running CRAC's setpoint a reading may lie before it is
/// named (C): sensor error, a supply a little under its setpoint (a CRAC's control
/// offset, which `crac_supply_offset` models) and stratified supply air stay within it.
pub const BELOW_SUPPLY_MARGIN_C: f64 = 5.0;

/// A reading colder than its snapshot's supply air.
#[derive(Debug, Clone, PartialEq)]
pub struct ColdReading {
    /// Snapshot label.
    pub snapshot: String,
    /// Sensor id.
    pub sensor: String,
    /// The reading (C).
    pub reading_c: f64,
    /// The coldest setpoint of a CRAC whose fans run in that snapshot (C).
    pub coldest_supply_c: f64,
}

/// Every reading more than [`BELOW_SUPPLY_MARGIN_C`] below the coldest setpoint of the
/// CRACs running in its snapshot (fan speed above 0); a snapshot with none running is
/// skipped (the model refuses it with its own reason).
///
/// ```
/// use kalibre_dc::snapshots::{readings_below_supply, HallSnapshot, OperatingState};
/// let hall = kalibre_dc::synth::generate_hall(&Default::default()).unwrap();
/// let state = OperatingState {
///     label: "t0".into(),
///     setpoint_c: vec![18.0; hall.cracs.len()],
///     fan_speed: vec![1.0; hall.cracs.len()],
///     power_w: vec![300.0; hall.server_count()],
/// };
/// let mut sensor_c = vec![Some(22.0); hall.sensors.len()];
/// sensor_c[1] = Some(-40.0);
/// let cold = readings_below_supply(&hall, &[HallSnapshot { state, sensor_c }]);
/// assert_eq!(cold.len(), 1);
/// assert_eq!(cold[0].sensor, hall.sensors[1].id);
/// ```
pub fn readings_below_supply(hall: &Hall, snapshots: &[HallSnapshot]) -> Vec<ColdReading> {
    let mut cold = Vec::new();
    for s in snapshots {
        let st = &s.state;
        let coldest = st
            .setpoint_c
            .iter()
            .zip(&st.fan_speed)
            .filter(|(_, &fan)| fan > 0.0)
            .map(|(&c, _)| c)
            .fold(f64::INFINITY, f64::min);
        if !coldest.is_finite() {
            continue;
        }
        for (sensor, reading) in hall.sensors.iter().zip(&s.sensor_c) {
            if let Some(c) = reading.filter(|&c| c < coldest - BELOW_SUPPLY_MARGIN_C) {
                cold.push(ColdReading {
                    snapshot: st.label.clone(),
                    sensor: sensor.id.clone(),
                    reading_c: c,
                    coldest_supply_c: coldest,
                });
            }
        }
    }
    cold
}
