//! What-if changes to the operating states of `kalibre simulate`: the question an
//! operator asks of a calibrated model (a warmer setpoint, slower fans, more load).

use clap::Args;
use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{number, HallSnapshot, AIR_C_RANGE, MAX_POWER_W};

use super::{CliError, CliResult};

/// What-if options of `kalibre simulate`.
#[derive(Debug, Args)]
pub struct WhatIfArgs {
    /// What if every CRAC's setpoint were this much higher (negative: lower) in every
    /// snapshot (C).
    #[arg(long = "setpoint-offset-c", allow_hyphen_values = true)]
    pub setpoint_offset_c: Option<f64>,
    /// What if every CRAC's fan speed were multiplied by this factor in every snapshot (a
    /// fan speed above 1 is refused).
    #[arg(long = "fan-speed-scale")]
    pub fan_speed_scale: Option<f64>,
    /// What if every server's power were multiplied by this factor in every snapshot.
    #[arg(long = "power-scale")]
    pub power_scale: Option<f64>,
}

impl WhatIfArgs {
    /// The changes in words, e.g. `setpoints +2 C, fan speeds x0.9`; none without any.
    pub fn describe(&self) -> Option<String> {
        let mut parts = Vec::new();
        if let Some(d) = self.setpoint_offset_c {
            parts.push(format!(
                "setpoints {}{} C",
                if d >= 0.0 { "+" } else { "" },
                number(d)
            ));
        }
        if let Some(f) = self.fan_speed_scale {
            parts.push(format!("fan speeds x{}", number(f)));
        }
        if let Some(f) = self.power_scale {
            parts.push(format!("server powers x{}", number(f)));
        }
        (!parts.is_empty()).then(|| parts.join(", "))
    }

    /// Applies the changes to every snapshot's operating state; a change that leaves the
    /// hall's limits (a fan speed above 1, a setpoint outside the air's range, a server
    /// above 10 MW) or is not a number is refused by name.
    pub fn apply(&self, hall: &Hall, snaps: &mut [HallSnapshot]) -> CliResult {
        if let Some(d) = self.setpoint_offset_c {
            if !d.is_finite() {
                return Err(CliError::Input(format!(
                    "--setpoint-offset-c: expected a finite temperature difference in C, got {d}"
                )));
            }
        }
        if let Some(f) = self.fan_speed_scale {
            if !(f.is_finite() && f > 0.0) {
                return Err(CliError::Input(format!(
                    "--fan-speed-scale: expected a factor > 0, got {}",
                    number(f)
                )));
            }
        }
        if let Some(f) = self.power_scale {
            if !(f.is_finite() && f >= 0.0) {
                return Err(CliError::Input(format!(
                    "--power-scale: expected a factor >= 0, got {}",
                    number(f)
                )));
            }
        }
        for snap in snaps.iter_mut() {
            let state = &mut snap.state;
            if let Some(d) = self.setpoint_offset_c {
                for (t, crac) in state.setpoint_c.iter_mut().zip(&hall.cracs) {
                    *t += d;
                    if !AIR_C_RANGE.contains(t) {
                        return Err(CliError::Input(format!(
                            "--setpoint-offset-c {}: CRAC `{}` in snapshot `{}` would supply {} C; expected a setpoint in [{}, {}] C",
                            number(d), crac.id, state.label, number(*t), AIR_C_RANGE.start(), AIR_C_RANGE.end()
                        )));
                    }
                }
            }
            if let Some(f) = self.fan_speed_scale {
                for (speed, crac) in state.fan_speed.iter_mut().zip(&hall.cracs) {
                    *speed *= f;
                    if *speed > 1.0 {
                        // Three decimals, unless that rounds to the very limit exceeded.
                        let speed = match format!("{speed:.3}") {
                            r if r == "1.000" => speed.to_string(),
                            _ if *speed >= 1e6 => number(*speed),
                            r => r,
                        };
                        return Err(CliError::Input(format!(
                            "--fan-speed-scale {}: CRAC `{}` in snapshot `{}` would run at {} of its rated flow; a fan speed is at most 1",
                            number(f), crac.id, state.label, speed
                        )));
                    }
                }
            }
            if let Some(f) = self.power_scale {
                for (p, server) in state.power_w.iter_mut().zip(hall.servers()) {
                    *p *= f;
                    if *p > MAX_POWER_W {
                        return Err(CliError::Input(format!(
                            "--power-scale {}: server `{}` in snapshot `{}` would draw {} W; expected at most {MAX_POWER_W:e} W",
                            number(f), server.server.id, state.label, number(*p)
                        )));
                    }
                }
            }
        }
        Ok(())
    }
}
