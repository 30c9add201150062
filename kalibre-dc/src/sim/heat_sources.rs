//! Where each sensor's warming comes from, rack by rack: the model's answer to "which
//! servers does this sensor see?".
//!
//! At fixed flows a sensor reads the supply plus `sum_j G_kj * rise_j`
//! ([`SensorInfluence`]), so the racks' parts of that sum add up to the sensor's whole
//! warming over the supply (exactly so when the supply is one temperature, as with a
//! floor plenum; with CRACs at different setpoints blowing into the room the rest is
//! their mix). A sensor the model gets wrong points at the racks whose alphas it informs,
//! and at where a missing effect would act.

use std::collections::BTreeMap;
use std::fmt::Write;

use super::{SensorInfluence, Solution};
use crate::hall::Hall;
use crate::snapshots::quote;
use crate::{Error, Result};

/// A sensor the servers' exhausts warm by less than this (K) gets no rows: well under what
/// a sensor resolves, so its shares would attribute nothing.
pub const MIN_WARMING_K: f64 = 0.01;

/// One rack's part in one sensor's warming, in one solved state.
#[derive(Debug, Clone, PartialEq)]
pub struct RackHeat {
    /// The operating state's label.
    pub snapshot: String,
    /// Sensor id.
    pub sensor: String,
    /// Rack id.
    pub rack: String,
    /// How much the rack's exhausts warm the sensor (K): `sum_j G_kj * rise_j` over
    /// the rack's servers.
    pub warming_k: f64,
    /// That over the sensor's warming from every rack.
    pub share: f64,
}

/// Each sensor's racks whose share of its warming is at least `min_share` (in `[0, 1]`),
/// largest first (none for a sensor warmed by less than [`MIN_WARMING_K`]), for the solved state `label` (`solution` and `influence` of the same
/// run, [`super::Simulator::sensor_influence`]).
pub fn rack_heat(
    hall: &Hall,
    label: &str,
    solution: &Solution,
    influence: &SensorInfluence,
    min_share: f64,
) -> Result<Vec<RackHeat>> {
    if !(0.0..=1.0).contains(&min_share) {
        return Err(Error::Mismatch(format!(
            "min_share: {min_share} is outside [0, 1]"
        )));
    }
    let servers: Vec<_> = hall.servers().collect();
    if influence.per_sensor.len() != hall.sensors.len()
        || influence
            .per_sensor
            .iter()
            .any(|row| row.len() != servers.len())
        || solution.server_intake_c.len() != servers.len()
    {
        return Err(Error::Mismatch(format!(
            "the influence or the run does not match hall `{}` ({} sensors, {} servers)",
            hall.name,
            hall.sensors.len(),
            servers.len()
        )));
    }
    let rise: Vec<f64> = solution
        .server_exhaust_c
        .iter()
        .zip(&solution.server_intake_c)
        .map(|(e, i)| e - i)
        .collect();
    let mut rows = Vec::new();
    for (sensor, g) in hall.sensors.iter().zip(&influence.per_sensor) {
        let mut by_rack: BTreeMap<usize, f64> = BTreeMap::new();
        for (s, (g, r)) in servers.iter().zip(g.iter().zip(&rise)) {
            *by_rack.entry(s.rack_index).or_default() += g * r;
        }
        let total: f64 = by_rack.values().sum();
        if total.is_nan() || total < MIN_WARMING_K {
            // No exhaust reaches the sensor to speak of: shares of nothing would be noise.
            continue;
        }
        let mut racks: Vec<(usize, f64)> = by_rack
            .into_iter()
            .filter(|&(_, w)| w / total >= min_share)
            .collect();
        racks.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        rows.extend(racks.into_iter().map(|(rack, warming_k)| RackHeat {
            snapshot: label.to_string(),
            sensor: sensor.id.clone(),
            rack: hall.racks[rack].id.clone(),
            warming_k,
            share: warming_k / total,
        }));
    }
    Ok(rows)
}

/// What warms one sensor in one solved state (see [`sensor_warming`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorWarming<'a> {
    /// The operating state's label.
    pub snapshot: &'a str,
    /// The sensor's whole warming over the supply by the racks' exhausts (K).
    pub warming_k: f64,
    /// The racks giving at least the share asked, largest first.
    pub racks: Vec<&'a RackHeat>,
}

/// What warms `sensor` in the first state of `rows` that has rows for it: its whole
/// warming and the racks giving at least `min_share` of it. `rows` must come from
/// [`rack_heat`] with no cut (`min_share` 0 there), since the whole warming is read off
/// the largest rack's share. `None` when no exhaust reaches the sensor (under
/// [`MIN_WARMING_K`]).
///
/// ```
/// use kalibre_dc::sim::{sensor_warming, RackHeat};
/// let row = |rack: &str, warming_k: f64| RackHeat {
///     snapshot: "t0".into(), sensor: "h-1".into(), rack: rack.into(),
///     warming_k, share: warming_k / 10.0,
/// };
/// let rows = vec![row("A1", 8.0), row("A2", 1.5), row("A3", 0.5)];
/// let w = sensor_warming(&rows, "h-1", 0.1).unwrap();
/// assert!((w.warming_k - 10.0).abs() < 1e-12);
/// assert_eq!(w.racks.iter().map(|r| r.rack.as_str()).collect::<Vec<_>>(), ["A1", "A2"]);
/// assert!(sensor_warming(&rows, "c-1", 0.1).is_none());
/// ```
pub fn sensor_warming<'a>(
    rows: &'a [RackHeat],
    sensor: &str,
    min_share: f64,
) -> Option<SensorWarming<'a>> {
    let first = rows.iter().find(|r| r.sensor == sensor)?;
    let racks = rows
        .iter()
        .filter(|r| r.sensor == sensor && r.snapshot == first.snapshot && r.share >= min_share)
        .collect();
    Some(SensorWarming {
        snapshot: &first.snapshot,
        // Rows come largest first, and each share is the rack's part of the whole.
        warming_k: first.warming_k / first.share,
        racks,
    })
}

/// The rows as CSV: `snapshot,sensor,rack,warming_k,share`.
pub fn write_rack_heat(rows: &[RackHeat]) -> String {
    let mut out = String::from("snapshot,sensor,rack,warming_k,share\n");
    for r in rows {
        let _ = writeln!(
            out,
            "{},{},{},{:.4},{:.4}",
            quote(&r.snapshot),
            quote(&r.sensor),
            quote(&r.rack),
            r.warming_k,
            r.share
        );
    }
    out
}
