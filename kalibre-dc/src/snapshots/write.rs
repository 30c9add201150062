//! Writing `snapshots.csv`: measurements with their operating states, and predictions.
//!
//! Numbers are written in Rust's shortest round-trip decimal form, so that reading a
//! written file gives back exactly the same values.

use std::fmt::Write as _;

use super::HallSnapshot;
use crate::hall::Hall;

/// The snapshots as `snapshots.csv` text: per snapshot, `setpoint_c` and `fan_speed` per
/// CRAC, `power_w` per server and `sensor_c` for each sensor that has a reading.
///
/// Vectors are read in hall order; a snapshot built for another hall (shorter vectors)
/// writes fewer rows, which the reader then rejects by name.
pub fn write_snapshots(hall: &Hall, snapshots: &[HallSnapshot]) -> String {
    let mut out = String::from("snapshot,kind,id,value\n");
    for s in snapshots {
        let label = s.state.label.as_str();
        for (crac, v) in hall.cracs.iter().zip(&s.state.setpoint_c) {
            row(&mut out, label, "setpoint_c", &crac.id, *v);
        }
        for (crac, v) in hall.cracs.iter().zip(&s.state.fan_speed) {
            row(&mut out, label, "fan_speed", &crac.id, *v);
        }
        for (server, v) in hall.servers().zip(&s.state.power_w) {
            row(&mut out, label, "power_w", &server.server.id, *v);
        }
        for (sensor, v) in hall.sensors.iter().zip(&s.sensor_c) {
            if let Some(v) = v {
                row(&mut out, label, "sensor_c", &sensor.id, *v);
            }
        }
    }
    out
}

/// Predicted sensor temperatures in the snapshot format (`kind = sensor_c`): one row per
/// label and sensor, `predicted_c[k][i]` for label `k` and sensor `i` in hall order.
pub fn write_predictions(hall: &Hall, labels: &[String], predicted_c: &[Vec<f64>]) -> String {
    let mut out = String::from("snapshot,kind,id,value\n");
    for (label, values) in labels.iter().zip(predicted_c) {
        for (sensor, v) in hall.sensors.iter().zip(values) {
            row(&mut out, label, "sensor_c", &sensor.id, *v);
        }
    }
    out
}

fn row(out: &mut String, label: &str, kind: &str, id: &str, value: f64) {
    // Writing to a String cannot fail.
    let _ = writeln!(out, "{},{kind},{},{value}", quote(label), quote(id));
}

/// Quotes a field when CSV needs it (separator, quote, line break, or edge whitespace).
pub(crate) fn quote(field: &str) -> std::borrow::Cow<'_, str> {
    let needs = field.contains([',', '"', '\n', '\r'])
        || field.starts_with(char::is_whitespace)
        || field.ends_with(char::is_whitespace);
    if needs {
        format!("\"{}\"", field.replace('"', "\"\"")).into()
    } else {
        field.into()
    }
}
