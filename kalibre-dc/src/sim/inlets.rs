//! What a calibrated model is for: each server's predicted intake and exhaust air under
//! one operating state, where no sensor measures it, and how many intakes exceed a
//! recommended limit.
//!
//! A sensor reads the air at one point; the servers' own intakes are what equipment
//! guidelines bound. ASHRAE TC 9.9 recommends 18-27 C at the server inlet for classes
//! A1-A4, so 27 C is the default limit of [`inlet_check`].

use std::collections::BTreeMap;
use std::fmt::Write;

use kalibre_core::calibrate::Residual;

use super::Solution;
use crate::hall::{Aisle, Hall};
use crate::snapshots::{quote, OperatingState};
use crate::{Error, Result};

/// ASHRAE TC 9.9's recommended upper bound of server inlet air, classes A1-A4 (C).
pub const RECOMMENDED_MAX_INLET_C: f64 = 27.0;

/// One server's air under one solved operating state.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerAir {
    /// The operating state's label.
    pub snapshot: String,
    /// Server id.
    pub server: String,
    /// Id of its rack.
    pub rack: String,
    /// Its server type.
    pub server_type: String,
    /// Power (W).
    pub power_w: f64,
    /// Air flow (m3/s).
    pub flow_m3_s: f64,
    /// Flow-weighted mean temperature of the air it draws (C).
    pub intake_c: f64,
    /// Temperature of the air it blows out (C).
    pub exhaust_c: f64,
}

/// Every server's air in `solution`, hall order. The solution must be of `hall` at `state`.
///
/// ```
/// use kalibre_dc::sim::{server_air, SimConfig, Simulator};
/// use kalibre_dc::synth::{generate, Preset, SynthOptions};
///
/// let truth = generate(&SynthOptions::new(Preset::Demo, 1)).unwrap();
/// let hall = &truth.hall;
/// let sim = Simulator::new(hall, SimConfig::default().with_cell_m(0.4)).unwrap();
/// let state = &truth.snapshots[0].state;
/// let alpha = vec![0.12; state.power_w.len()];
/// let solution = sim.solve(state, &alpha, &[]).unwrap();
/// let air = server_air(hall, state, &solution).unwrap();
/// assert_eq!(air.len(), hall.servers().count());
/// assert!(air.iter().all(|s| s.exhaust_c >= s.intake_c));
/// ```
pub fn server_air(
    hall: &Hall,
    state: &OperatingState,
    solution: &Solution,
) -> Result<Vec<ServerAir>> {
    let n = hall.servers().count();
    let lengths = [
        state.power_w.len(),
        solution.server_flow_m3_s.len(),
        solution.server_intake_c.len(),
        solution.server_exhaust_c.len(),
    ];
    if lengths.iter().any(|&l| l != n) {
        return Err(Error::Mismatch(format!(
            "server air of snapshot `{}`: the hall has {n} servers, but the state has {} \
             powers and the solution {} flows",
            state.label, lengths[0], lengths[1]
        )));
    }
    Ok(hall
        .servers()
        .map(|s| {
            let i = s.index;
            ServerAir {
                snapshot: state.label.clone(),
                server: s.server.id.clone(),
                rack: s.rack.id.clone(),
                server_type: s.server.server_type.clone(),
                power_w: state.power_w[i],
                flow_m3_s: solution.server_flow_m3_s[i],
                intake_c: solution.server_intake_c[i],
                exhaust_c: solution.server_exhaust_c[i],
            }
        })
        .collect())
}

/// The rows as CSV: `snapshot,server,rack,type,power_w,flow_m3_s,intake_c,exhaust_c`.
pub fn write_server_air(rows: &[ServerAir]) -> String {
    let mut out = String::from("snapshot,server,rack,type,power_w,flow_m3_s,intake_c,exhaust_c\n");
    for r in rows {
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{}",
            quote(&r.snapshot),
            quote(&r.server),
            quote(&r.rack),
            quote(&r.server_type),
            r.power_w,
            r.flow_m3_s,
            r.intake_c,
            r.exhaust_c
        );
    }
    out
}

/// Server intakes of one snapshot against a limit.
#[derive(Debug, Clone, PartialEq)]
pub struct InletCheck {
    /// The limit (C).
    pub limit_c: f64,
    /// Servers checked.
    pub servers: usize,
    /// Servers drawing air above the limit.
    pub above_limit: usize,
    /// The hottest intakes, hottest first.
    pub hottest: Vec<ServerAir>,
}

/// Counts the intakes of `rows` (one snapshot) above `limit_c` and keeps the `top`
/// hottest. A limit that is not finite is an error.
pub fn inlet_check(rows: &[ServerAir], limit_c: f64, top: usize) -> Result<InletCheck> {
    if !limit_c.is_finite() {
        return Err(Error::Mismatch(format!(
            "inlet limit: expected a finite temperature in C, got {limit_c}"
        )));
    }
    let mut sorted: Vec<&ServerAir> = rows.iter().collect();
    // Ties keep hall order, so the listing is deterministic.
    sorted.sort_by(|a, b| b.intake_c.total_cmp(&a.intake_c));
    Ok(InletCheck {
        limit_c,
        servers: rows.len(),
        above_limit: rows.iter().filter(|r| r.intake_c > limit_c).count(),
        hottest: sorted.into_iter().take(top).cloned().collect(),
    })
}

/// The limit minus the hottest intake of a check (C): how far every setpoint can rise.
/// At fixed flows the temperatures are linear in the supply's and the servers' rises do
/// not move, so a uniform setpoint change moves every intake by exactly as much.
pub fn setpoint_headroom_c(check: &InletCheck) -> Option<f64> {
    check.hottest.first().map(|h| check.limit_c - h.intake_c)
}

/// From a calibration's residuals: the cold-aisle sensor the model reads coldest against
/// the measurements, with the mean of predicted minus measured over the snapshots (C,
/// negative); `None` when it reads no cold-aisle sensor colder than measured. Inlet
/// sensors are the measurements nearest the intakes: where the model reads one colder
/// than measured, intakes near it may be as much warmer than it predicts, so a headroom
/// less this much is what the measurements support.
pub fn coldest_under_read(hall: &Hall, residuals: &[Residual]) -> Option<(String, f64)> {
    let mut sums: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
    for r in residuals {
        let cold = hall
            .sensors
            .iter()
            .find(|s| s.id == r.sensor)
            .is_some_and(|s| s.aisle == Aisle::Cold);
        if cold {
            let e = sums.entry(r.sensor.as_str()).or_default();
            e.0 += r.predicted_c - r.measured_c;
            e.1 += 1;
        }
    }
    sums.into_iter()
        .map(|(id, (sum, n))| (id.to_string(), sum / n as f64))
        .filter(|(_, mean)| *mean < 0.0)
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// How far a model's server intakes are from known true ones (a synthetic hall's
/// `truth.json`, or OpenFOAM's), over one or more snapshots.
#[derive(Debug, Clone, PartialEq)]
pub struct IntakeError {
    /// Mean absolute error over every server and snapshot (C).
    pub mae_c: f64,
    /// The warmest true intake: that server's row, and its true temperature (C).
    pub warmest_true: (ServerAir, f64),
    /// The largest error: that server's row, and its true temperature (C).
    pub worst: (ServerAir, f64),
}

/// Compares `predicted` (rows of any snapshots) with `truth` (per snapshot label, by
/// server id). A server or snapshot the truth lacks is an error naming it.
pub fn intake_error(
    predicted: &[ServerAir],
    truth: &dyn Fn(&str, &str) -> Option<f64>,
) -> Result<IntakeError> {
    let mut sum = 0.0;
    let mut warmest: Option<(ServerAir, f64)> = None;
    let mut worst: Option<(ServerAir, f64)> = None;
    for row in predicted {
        let t = truth(&row.snapshot, &row.server).ok_or_else(|| {
            Error::Mismatch(format!(
                "no true intake for server `{}` in snapshot `{}`",
                row.server, row.snapshot
            ))
        })?;
        sum += (row.intake_c - t).abs();
        if warmest.as_ref().is_none_or(|(_, w)| t > *w) {
            warmest = Some((row.clone(), t));
        }
        if worst
            .as_ref()
            .is_none_or(|(r, w)| (row.intake_c - t).abs() > (r.intake_c - w).abs())
        {
            worst = Some((row.clone(), t));
        }
    }
    let none = || Error::Mismatch("no server intakes to compare".into());
    Ok(IntakeError {
        mae_c: sum / predicted.len() as f64,
        warmest_true: warmest.ok_or_else(none)?,
        worst: worst.ok_or_else(none)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn air(server: &str, intake_c: f64) -> ServerAir {
        ServerAir {
            snapshot: "t0".into(),
            server: server.into(),
            rack: "A1".into(),
            server_type: "web".into(),
            power_w: 300.0,
            flow_m3_s: 0.02,
            intake_c,
            exhaust_c: intake_c + 12.0,
        }
    }

    #[test]
    fn check_counts_strictly_above_and_lists_hottest_first() {
        let rows = [
            air("a", 25.0),
            air("b", 27.0),
            air("c", 29.5),
            air("d", 27.5),
        ];
        let c = inlet_check(&rows, 27.0, 2).unwrap();
        assert_eq!((c.servers, c.above_limit), (4, 2));
        let names: Vec<&str> = c.hottest.iter().map(|s| s.server.as_str()).collect();
        assert_eq!(names, ["c", "d"]);
        assert!(inlet_check(&rows, f64::NAN, 2).is_err());
        assert_eq!(inlet_check(&[], 27.0, 5).unwrap().hottest.len(), 0);
    }

    #[test]
    fn intake_error_is_the_mean_gap_and_finds_the_warmest_true_intake() {
        let rows = [air("a", 20.0), air("b", 25.0)];
        let truth = |_: &str, s: &str| match s {
            "a" => Some(21.0),
            "b" => Some(28.0),
            _ => None,
        };
        let e = intake_error(&rows, &truth).unwrap();
        assert!((e.mae_c - 2.0).abs() < 1e-12);
        assert_eq!(e.warmest_true.0.server, "b");
        assert_eq!(e.warmest_true.1, 28.0);
        assert_eq!((e.worst.0.server.as_str(), e.worst.1), ("b", 28.0));
        assert!(intake_error(&[air("c", 20.0)], &truth).is_err());
        assert!(intake_error(&[], &truth).is_err());
    }

    #[test]
    fn csv_has_a_header_and_quotes_what_needs_it() {
        let mut odd = air("x,1", 20.0);
        odd.rack = "rack \"B\"".into();
        let csv = write_server_air(&[air("a", 21.5), odd]);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(
            lines[0],
            "snapshot,server,rack,type,power_w,flow_m3_s,intake_c,exhaust_c"
        );
        assert_eq!(lines[1], "t0,a,A1,web,300,0.02,21.5,33.5");
        assert_eq!(lines[2], "t0,\"x,1\",\"rack \"\"B\"\"\",web,300,0.02,20,32");
    }
}
