//! Readings and setpoints no state of the hall can produce. Air colder than every
//! running CRAC's supply: mixing only warms supply air (servers add heat, nothing in an
//! air-cooled hall removes it but the CRACs), so such a reading is a faulty sensor or a
//! typing slip, and a least-squares fit would bend every parameter toward it. Air or a
//! setpoint far warmer than any hall's: most often degrees Fahrenheit.

use super::{HallSnapshot, OperatingState};
use crate::hall::Hall;

/// How far below the coldest running CRAC's setpoint a reading may lie before it is
/// named (C): sensor error, a supply a little under its setpoint (a CRAC's control
/// offset, which `crac_supply_offset` models) and stratified supply air stay within it.
pub const BELOW_SUPPLY_MARGIN_C: f64 = 5.0;

/// The setpoints of the CRACs whose fans run in `st` (C): the supply the hall's air
/// comes from.
fn running_setpoints(st: &OperatingState) -> impl Iterator<Item = f64> + '_ {
    st.setpoint_c
        .iter()
        .zip(&st.fan_speed)
        .filter(|(_, &fan)| fan > 0.0)
        .map(|(&c, _)| c)
}

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
        let coldest = running_setpoints(st).fold(f64::INFINITY, f64::min);
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

/// How far above the warmest running CRAC's setpoint a cold-aisle reading may lie
/// before it is named (C): an intake that takes in exhaust warms by a server's rise
/// (5-20 K, the default prior) or so, but not by 30 K, which is 45 C over a 15 C supply,
/// ASHRAE's warmest allowable intake. A reading in degrees Fahrenheit does (18 C is 64 F).
pub const ABOVE_SUPPLY_MARGIN_C: f64 = 30.0;

/// The same for hot-aisle sensors (C): exhaust that is taken in again rises twice, so a
/// dense hall's hot aisle may sit 40 K above its supply; 25 C in Fahrenheit is 77 F.
pub const HOT_AISLE_ABOVE_SUPPLY_MARGIN_C: f64 = 50.0;

/// The warmest CRAC setpoint not named (C): ASHRAE's warmest equipment class allows 45 C
/// at the intake, so no hall supplies air warmer. Setpoints in degrees Fahrenheit are
/// (a data hall's 55-80 F).
pub const MAX_SETPOINT_C: f64 = 45.0;

/// A reading warmer than its snapshot's air can be.
#[derive(Debug, Clone, PartialEq)]
pub struct HotReading {
    /// Snapshot label.
    pub snapshot: String,
    /// Sensor id.
    pub sensor: String,
    /// The reading (C).
    pub reading_c: f64,
    /// The warmest setpoint of a CRAC whose fans run in that snapshot (C).
    pub warmest_supply_c: f64,
}

/// Every reading more than [`ABOVE_SUPPLY_MARGIN_C`] (a hot-aisle sensor's
/// [`HOT_AISLE_ABOVE_SUPPLY_MARGIN_C`]) above the warmest setpoint of the CRACs running in
/// its snapshot (fan speed above 0), as a reading in degrees Fahrenheit is; a snapshot
/// with none running is skipped.
///
/// ```
/// use kalibre_dc::snapshots::{readings_above_supply, HallSnapshot, OperatingState};
/// let hall = kalibre_dc::synth::generate_hall(&Default::default()).unwrap();
/// let state = OperatingState {
///     label: "t0".into(),
///     setpoint_c: vec![18.0; hall.cracs.len()],
///     fan_speed: vec![1.0; hall.cracs.len()],
///     power_w: vec![300.0; hall.server_count()],
/// };
/// let mut sensor_c = vec![Some(35.0); hall.sensors.len()];
/// sensor_c[1] = Some(71.6); // 22 C in Fahrenheit
/// let hot = readings_above_supply(&hall, &[HallSnapshot { state, sensor_c }]);
/// assert_eq!(hot.len(), 1);
/// assert_eq!(hot[0].sensor, hall.sensors[1].id);
/// ```
pub fn readings_above_supply(hall: &Hall, snapshots: &[HallSnapshot]) -> Vec<HotReading> {
    let mut hot = Vec::new();
    for s in snapshots {
        let st = &s.state;
        let warmest = running_setpoints(st).fold(f64::NEG_INFINITY, f64::max);
        if !warmest.is_finite() {
            continue;
        }
        for (sensor, reading) in hall.sensors.iter().zip(&s.sensor_c) {
            let margin = match sensor.aisle {
                crate::hall::Aisle::Hot => HOT_AISLE_ABOVE_SUPPLY_MARGIN_C,
                crate::hall::Aisle::Cold => ABOVE_SUPPLY_MARGIN_C,
            };
            if let Some(c) = reading.filter(|&c| c > warmest + margin) {
                hot.push(HotReading {
                    snapshot: st.label.clone(),
                    sensor: sensor.id.clone(),
                    reading_c: c,
                    warmest_supply_c: warmest,
                });
            }
        }
    }
    hot
}

/// A CRAC setpoint no hall runs at.
#[derive(Debug, Clone, PartialEq)]
pub struct ImplausibleSetpoint {
    /// Snapshot label.
    pub snapshot: String,
    /// CRAC id.
    pub crac: String,
    /// The setpoint (C).
    pub setpoint_c: f64,
}

/// Every CRAC setpoint above [`MAX_SETPOINT_C`], as one in degrees Fahrenheit is.
///
/// ```
/// use kalibre_dc::snapshots::{implausible_setpoints, OperatingState};
/// let hall = kalibre_dc::synth::generate_hall(&Default::default()).unwrap();
/// let mut state = OperatingState {
///     label: "t0".into(),
///     setpoint_c: vec![18.0; hall.cracs.len()],
///     fan_speed: vec![1.0; hall.cracs.len()],
///     power_w: vec![300.0; hall.server_count()],
/// };
/// assert!(implausible_setpoints(&hall, [&state]).is_empty());
/// state.setpoint_c[0] = 64.4; // 18 C in Fahrenheit
/// assert_eq!(implausible_setpoints(&hall, [&state])[0].crac, hall.cracs[0].id);
/// ```
pub fn implausible_setpoints<'a>(
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) -> Vec<ImplausibleSetpoint> {
    let mut found = Vec::new();
    for st in states {
        for (crac, &c) in hall.cracs.iter().zip(&st.setpoint_c) {
            if c > MAX_SETPOINT_C {
                found.push(ImplausibleSetpoint {
                    snapshot: st.label.clone(),
                    crac: crac.id.clone(),
                    setpoint_c: c,
                });
            }
        }
    }
    found
}

/// A sensor that reads the same in every snapshot while the hall's conditions change.
#[derive(Debug, Clone, PartialEq)]
pub struct StuckSensor {
    /// Sensor id.
    pub sensor: String,
    /// The one value it reads (C).
    pub reading_c: f64,
    /// Its readings (snapshots that have one).
    pub snapshots: usize,
}

/// More than this share of the sensors constant is the export's resolution (whole
/// degrees of a steady hall), not stuck sensors: none is named then.
const MOST_STUCK_SHARE: f64 = 0.25;

/// Every sensor whose readings are equal to the last digit in every snapshot that has
/// one, at least three of them, where those snapshots' setpoints, fan speeds or powers
/// are not all equal: a real sensor's noise alone makes readings differ, so a constant
/// one is stuck (a frozen value, a default the export filled in). When more than a
/// quarter of the sensors are, that is the readings' resolution, and none is named.
///
/// ```
/// use kalibre_dc::snapshots::{stuck_sensors, HallSnapshot, OperatingState};
/// let hall = kalibre_dc::synth::generate_hall(&Default::default()).unwrap();
/// let snaps: Vec<HallSnapshot> = (0..3)
///     .map(|t| {
///         let mut sensor_c = vec![Some(25.0 + t as f64 * 0.4); hall.sensors.len()];
///         sensor_c[2] = Some(22.0);
///         HallSnapshot {
///             state: OperatingState {
///                 label: format!("t{t}"),
///                 setpoint_c: vec![18.0 + t as f64; hall.cracs.len()],
///                 fan_speed: vec![1.0; hall.cracs.len()],
///                 power_w: vec![300.0; hall.server_count()],
///             },
///             sensor_c,
///         }
///     })
///     .collect();
/// let stuck = stuck_sensors(&hall, &snaps);
/// assert_eq!(stuck.len(), 1);
/// assert_eq!((stuck[0].sensor.as_str(), stuck[0].snapshots), (hall.sensors[2].id.as_str(), 3));
/// ```
pub fn stuck_sensors(hall: &Hall, snapshots: &[HallSnapshot]) -> Vec<StuckSensor> {
    let mut stuck = Vec::new();
    for (k, sensor) in hall.sensors.iter().enumerate() {
        let read: Vec<(&OperatingState, f64)> = snapshots
            .iter()
            .filter_map(|s| s.sensor_c.get(k).copied().flatten().map(|c| (&s.state, c)))
            .collect();
        let Some(&(first_state, first)) = read.first() else {
            continue;
        };
        let same_conditions = |st: &OperatingState| {
            st.setpoint_c == first_state.setpoint_c
                && st.fan_speed == first_state.fan_speed
                && st.power_w == first_state.power_w
        };
        if read.len() >= 3
            && read.iter().all(|&(_, c)| c == first)
            && !read.iter().all(|&(st, _)| same_conditions(st))
        {
            stuck.push(StuckSensor {
                sensor: sensor.id.clone(),
                reading_c: first,
                snapshots: read.len(),
            });
        }
    }
    if stuck.len() as f64 > MOST_STUCK_SHARE * hall.sensors.len() as f64 {
        return Vec::new();
    }
    stuck
}

/// Air density times heat capacity (J/(m3 K)): rho 1.2 kg/m3, cp 1005 J/(kg K), as in
/// the built-in simulator and the OpenFOAM adapter.
const AIR_RHO_CP: f64 = 1.2 * 1005.0;

/// The highest hall-wide mean rise (K) of the CRACs' return air over their supply that
/// is named as implausible. A server's exhaust rises 5-20 K (the default prior) and the
/// return air mixes it with cooler air, so a mean far above that is a CRAC flow or a
/// power in the wrong unit (0.01 instead of 10 m3/s, W typed for kW), not a hall.
pub const MAX_MEAN_RISE_K: f64 = 40.0;

/// The lowest mean rise (K) not named: below it the servers' heat hardly reaches the
/// sensors, as with powers typed in kW where W are meant, and alpha cannot be told.
pub const MIN_MEAN_RISE_K: f64 = 0.2;

/// A snapshot whose servers' heat and CRACs' air flow give an implausible rise.
#[derive(Debug, Clone, PartialEq)]
pub struct ImplausibleRise {
    /// Snapshot label.
    pub snapshot: String,
    /// Total server power (W).
    pub power_w: f64,
    /// Total CRAC air flow at this snapshot's fan speeds (m3/s).
    pub supply_m3_s: f64,
    /// Mean rise of the return air over the supply that energy balance demands (K).
    pub mean_rise_k: f64,
}

/// Every snapshot whose mean return-air rise, total power over (rho cp x total CRAC
/// flow), lies outside [`MIN_MEAN_RISE_K`]..[`MAX_MEAN_RISE_K`]. In steady state the
/// CRACs carry all the servers' heat away, so this rise holds whatever the air does in
/// between; a snapshot with no CRAC running is skipped (the model refuses it).
///
/// ```
/// use kalibre_dc::snapshots::{implausible_rises, OperatingState};
/// let mut hall = kalibre_dc::synth::generate_hall(&Default::default()).unwrap();
/// let state = OperatingState {
///     label: "t0".into(),
///     setpoint_c: vec![18.0; hall.cracs.len()],
///     fan_speed: vec![1.0; hall.cracs.len()],
///     power_w: vec![300.0; hall.server_count()],
/// };
/// assert!(implausible_rises(&hall, [&state]).is_empty());
/// // Litres per second typed as m3/s: a thousandth of the flow.
/// for c in &mut hall.cracs {
///     c.rated_flow_m3_s /= 1000.0;
/// }
/// let slips = implausible_rises(&hall, [&state]);
/// assert_eq!(slips.len(), 1);
/// assert!(slips[0].mean_rise_k > 1000.0);
/// ```
pub fn implausible_rises<'a>(
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) -> Vec<ImplausibleRise> {
    states
        .into_iter()
        .filter_map(|st| {
            let supply_m3_s: f64 = hall
                .cracs
                .iter()
                .zip(&st.fan_speed)
                .map(|(c, &fan)| c.rated_flow_m3_s * fan)
                .sum();
            let power_w: f64 = st.power_w.iter().sum();
            if supply_m3_s.is_nan() || supply_m3_s <= 0.0 || !power_w.is_finite() {
                return None;
            }
            let mean_rise_k = power_w / (AIR_RHO_CP * supply_m3_s);
            (!(MIN_MEAN_RISE_K..=MAX_MEAN_RISE_K).contains(&mean_rise_k)).then(|| ImplausibleRise {
                snapshot: st.label.clone(),
                power_w,
                supply_m3_s,
                mean_rise_k,
            })
        })
        .collect()
}
