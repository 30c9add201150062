//! The sensors a calibrated hall model misses most, and which racks warm them in the
//! model's flow: where a missing effect would act, for `kalibre diagnose --json` and the
//! story's `diagnosis-N.json`.

use std::collections::BTreeMap;

use kalibre_core::calibrate::Residual;
use serde_json::{json, Value};

use crate::hall::Hall;
use crate::report::WARMING_RACK_MIN_SHARE;
use crate::sim::{sensor_warming, RackHeat};

/// How many of the worst sensors a diagnosis document describes.
pub const WORST_SENSORS_SHOWN: usize = 5;

/// Mean residual (model minus measurement, C) per sensor over the snapshots of a
/// calibration's `residuals`, largest magnitude first (ties in sensor order).
///
/// ```
/// use kalibre_core::calibrate::Residual;
/// let row = |sensor: &str, snapshot: &str, predicted_c: f64| Residual {
///     snapshot: snapshot.into(),
///     sensor: sensor.into(),
///     measured_c: 20.0,
///     predicted_c,
///     weight: None,
/// };
/// let residuals = [
///     row("s1", "t0", 20.5), row("s1", "t1", 20.3),
///     row("s2", "t0", 18.0), row("s2", "t1", 19.0),
/// ];
/// let worst = kalibre_dc::diagnosis::worst_sensors(&residuals);
/// assert_eq!(worst[0].0, "s2");
/// assert!((worst[0].1 + 1.5).abs() < 1e-12);
/// assert!((worst[1].1 - 0.4).abs() < 1e-12);
/// ```
pub fn worst_sensors(residuals: &[Residual]) -> Vec<(&str, f64)> {
    let mut by_sensor: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
    for r in residuals {
        let s = by_sensor.entry(r.sensor.as_str()).or_default();
        s.0 += r.predicted_c - r.measured_c;
        s.1 += 1;
    }
    let mut worst: Vec<(&str, f64)> = by_sensor
        .iter()
        .map(|(k, (s, n))| (*k, s / *n as f64))
        .collect();
    worst.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    worst
}

/// `worst_sensors` of a diagnosis document: the [`WORST_SENSORS_SHOWN`] sensors the
/// calibrated model misses most, each with where it is, the mean residual, and, given
/// the racks' heat in the built-in model's flow (`heat`, [`crate::HallModel::rack_heat`]),
/// which racks warm it (`warming`, `null` when no exhaust reaches it; absent without
/// `heat`, as with a model whose flow kalibre does not have).
pub fn worst_sensors_json(hall: &Hall, residuals: &[Residual], heat: Option<&[RackHeat]>) -> Value {
    worst_sensors(residuals)
        .iter()
        .take(WORST_SENSORS_SHOWN)
        .map(|(sensor, mean_c)| {
            let s = hall.sensors.iter().find(|s| s.id == *sensor);
            let mut entry = json!({
                "sensor": sensor,
                "aisle": s.map(|s| s.aisle.as_str()),
                "position_m": s.map(|s| s.position_m),
                "mean_residual_c": mean_c,
            });
            if let Some(rows) = heat {
                entry["warming"] = sensor_warming(rows, sensor, WARMING_RACK_MIN_SHARE)
                    .map_or(Value::Null, |w| {
                        let racks: Vec<Value> = w
                            .racks
                            .iter()
                            .map(|r| json!({"rack": r.rack, "warming_k": r.warming_k, "share": r.share}))
                            .collect();
                        json!({"snapshot": w.snapshot, "warming_k": w.warming_k, "racks": racks})
                    });
            }
            entry
        })
        .collect()
}

impl super::HallDiagnosis {
    /// The document `kalibre diagnose --json` prints and the story writes as
    /// `diagnosis-N.json`: [`Self::to_json`] with where the calibration fails beside the
    /// ranking, `worst_sensors` ([`worst_sensors_json`]) and `odd_snapshots`
    /// ([`super::odd_snapshots()`]) of its `residuals`.
    pub fn document(
        &self,
        hall: &Hall,
        residuals: &[Residual],
        heat: Option<&[RackHeat]>,
    ) -> Value {
        let mut doc = self.to_json();
        doc["worst_sensors"] = worst_sensors_json(hall, residuals, heat);
        doc["odd_snapshots"] = json!(super::odd_snapshots(residuals));
        doc
    }
}
