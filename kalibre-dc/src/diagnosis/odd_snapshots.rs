//! Snapshots the model misses at nearly every sensor by the same amount. No effect of the
//! hall shifts one snapshot's air alone: its conditions were not steady (a setpoint or
//! load change the sensors had not caught up with), or its setpoint, fan or power rows
//! are wrong. The diagnosis's effects cannot explain such a shift, so without this note
//! its residual shows up spread over many sensors, each a little off.

use kalibre_core::calibrate::Residual;
use serde::Serialize;

/// The least shift named (C): a snapshot's conditions differ from the others', and the
/// model's own error with them, by a few tenths of a degree.
const MIN_SHIFT_C: f64 = 1.0;
/// The least share of the snapshot's sensors that must be off the same way by at least
/// half the shift (a large error at a few sensors is theirs, not the snapshot's).
const MIN_SHARE_OFF: f64 = 0.8;
/// How many standard errors of its mean the shift must be, the noise measured from the
/// residuals themselves.
const MIN_STANDARD_ERRORS: f64 = 6.0;
/// Sensors a snapshot needs for its shift to be told from a few sensors' own errors.
const MIN_SENSORS: usize = 5;

/// A snapshot whose readings the model misses by one shift.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OddSnapshot {
    /// Snapshot label.
    pub snapshot: String,
    /// Model minus measurement, beyond each sensor's usual residual, on average (C).
    pub shift_c: f64,
    /// Sensors off the same way by at least half the shift.
    pub sensors_off: usize,
    /// Sensors measured in the snapshot.
    pub sensors: usize,
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// The snapshots of a calibration's `residuals` that the model misses by one shift: each
/// sensor's residual less its median over the snapshots (the model's error there, which
/// recurs) averages at least 1 C and 6 standard errors in the snapshot, with at least
/// 80 % of its sensors (and 5 or more) off the same way by half of it or more.
/// Needs three snapshots (of two, either could be the odd one), and names fewer than half
/// of them.
pub fn odd_snapshots(residuals: &[Residual]) -> Vec<OddSnapshot> {
    let mut snapshots: Vec<&str> = Vec::new();
    for r in residuals {
        if !snapshots.contains(&r.snapshot.as_str()) {
            snapshots.push(&r.snapshot);
        }
    }
    if snapshots.len() < 3 {
        return Vec::new();
    }
    let mut by_sensor: std::collections::BTreeMap<&str, Vec<f64>> = Default::default();
    for r in residuals {
        by_sensor
            .entry(&r.sensor)
            .or_default()
            .push(r.predicted_c - r.measured_c);
    }
    let usual: std::collections::BTreeMap<&str, f64> = by_sensor
        .into_iter()
        .map(|(s, mut v)| (s, median(&mut v)))
        .collect();
    // Each reading's residual beyond its sensor's usual one, by snapshot.
    let beyond = |snap: &str| -> Vec<f64> {
        residuals
            .iter()
            .filter(|r| r.snapshot == snap)
            .map(|r| r.predicted_c - r.measured_c - usual[r.sensor.as_str()])
            .filter(|e| e.is_finite())
            .collect()
    };
    let shifts: Vec<(&str, Vec<f64>, f64)> = snapshots
        .iter()
        .map(|&s| {
            let e = beyond(s);
            let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
            (s, e, mean)
        })
        .collect();
    // The noise about each snapshot's shift, robustly (the odd snapshot's own spread is
    // counted too: a shift is no spread).
    let mut spread: Vec<f64> = shifts
        .iter()
        .flat_map(|(_, e, m)| e.iter().map(move |x| (x - m).abs()))
        .collect();
    if spread.is_empty() {
        return Vec::new();
    }
    let sigma = 1.4826 * median(&mut spread);
    let odd: Vec<OddSnapshot> = shifts
        .into_iter()
        .filter_map(|(snapshot, e, shift_c)| {
            let n = e.len();
            let sensors_off = e
                .iter()
                .filter(|x| x.signum() == shift_c.signum() && x.abs() >= 0.5 * shift_c.abs())
                .count();
            let standard_error = sigma / (n as f64).sqrt();
            (n >= MIN_SENSORS
                && shift_c.abs() >= MIN_SHIFT_C
                && shift_c.abs() >= MIN_STANDARD_ERRORS * standard_error
                && sensors_off as f64 >= MIN_SHARE_OFF * n as f64)
                .then(|| OddSnapshot {
                    snapshot: snapshot.to_string(),
                    shift_c,
                    sensors_off,
                    sensors: n,
                })
        })
        .collect();
    // The usual residual is the majority's: when half the snapshots or more stand out,
    // they are two groups of conditions (a load the model errs at), not odd snapshots.
    if 2 * odd.len() >= snapshots.len() {
        return Vec::new();
    }
    odd
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Residuals `residual(sensor, snapshot)` of 10 sensors in `snapshots` snapshots.
    fn rows(snapshots: usize, residual: impl Fn(usize, usize) -> f64) -> Vec<Residual> {
        let mut rows = Vec::new();
        for t in 0..snapshots {
            for k in 0..10 {
                rows.push(Residual {
                    snapshot: format!("t{t}"),
                    sensor: format!("s{k}"),
                    measured_c: 20.0,
                    predicted_c: 20.0 + residual(k, t),
                    weight: None,
                });
            }
        }
        rows
    }

    /// Noise-like residuals in [-0.2, 0.2] C, and a recurring model error at sensor 3.
    fn noise(k: usize, t: usize) -> f64 {
        let n = ((k * 7 + t * 13) % 9) as f64 / 20.0 - 0.2;
        n + if k == 3 { 2.5 } else { 0.0 }
    }

    #[test]
    fn a_snapshot_shifted_at_every_sensor_is_named_and_a_recurring_error_is_not() {
        let odd = odd_snapshots(&rows(5, |k, t| {
            noise(k, t) + if t == 2 { 3.0 } else { 0.0 }
        }));
        assert_eq!(odd.len(), 1, "{odd:?}");
        assert_eq!(odd[0].snapshot, "t2");
        assert!((odd[0].shift_c - 3.0).abs() < 0.3, "{odd:?}");
        assert_eq!((odd[0].sensors_off, odd[0].sensors), (10, 10));
        // Noise and the model's recurring error at one sensor: nothing.
        assert!(odd_snapshots(&rows(5, noise)).is_empty());
        // Two of four shifted: two groups of conditions, neither odd.
        let two = odd_snapshots(&rows(4, |k, t| {
            noise(k, t) + if t >= 2 { 3.0 } else { 0.0 }
        }));
        assert!(two.is_empty(), "{two:?}");
        // Of two snapshots either could be the odd one: nothing said.
        assert!(odd_snapshots(&rows(2, |k, t| noise(k, t) + t as f64 * 3.0)).is_empty());
        // A shift at half the sensors is theirs, not the snapshot's.
        let half = odd_snapshots(&rows(5, |k, t| {
            noise(k, t) + if t == 2 && k < 5 { 3.0 } else { 0.0 }
        }));
        assert!(half.is_empty(), "{half:?}");
        // A shift of half a degree is within what other conditions do to the model.
        let small = odd_snapshots(&rows(5, |k, t| {
            noise(k, t) + if t == 2 { 0.5 } else { 0.0 }
        }));
        assert!(small.is_empty(), "{small:?}");
    }
}
