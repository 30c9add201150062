//! The per-run parameter file `0.orig/include/params`: the only file a run writes.

use std::fmt::Write;

use crate::hall::{Hall, SupplyKind};
use crate::snapshots::OperatingState;

use super::OpenFoamSettings;

/// m3/s per cfm.
pub const M3_S_PER_CFM: f64 = 4.71947e-4;

/// Turbulence of inflowing air (k in m2/s2, epsilon in m2/s3).
const K_IN: f64 = 0.01;
const EPSILON_IN: f64 = 0.01;

/// What one run feeds OpenFOAM, in physical units.
#[derive(Debug, Clone, PartialEq)]
pub struct RunInputs {
    /// Air flow per server (m3/s).
    pub server_flow_m3_s: Vec<f64>,
    /// Heat per server in kinematic units `P / (rho cp)` (K m3/s).
    pub server_heat_k_m3_s: Vec<f64>,
    /// Flow per tile (m3/s).
    pub tile_flow_m3_s: Vec<f64>,
    /// Supply temperature per tile (C).
    pub tile_t_c: Vec<f64>,
    /// Initial temperature of the room (C).
    pub t_init_c: f64,
    /// Total server heat (W).
    pub heat_w: f64,
}

impl RunInputs {
    /// The inputs of `state` at per-server `alpha` (cfm/W) and per-CRAC supply offset (C).
    pub fn new(
        hall: &Hall,
        state: &OperatingState,
        alpha: &[f64],
        supply_offset_c: &[f64],
        st: &OpenFoamSettings,
    ) -> Result<Self, String> {
        let mut floor_q = 0.0;
        let mut floor_qt = 0.0;
        for (c, crac) in hall.cracs.iter().enumerate() {
            if crac.supply == SupplyKind::Floor {
                let q = crac.rated_flow_m3_s * state.fan_speed[c];
                floor_q += q;
                floor_qt +=
                    q * (state.setpoint_c[c] + supply_offset_c.get(c).copied().unwrap_or(0.0));
            }
        }
        let weights: Vec<f64> = hall
            .tiles
            .iter()
            .map(|t| t.size_m[0] * t.size_m[1] * t.open_fraction)
            .collect();
        let w_sum: f64 = weights.iter().sum();
        let supplied = floor_q > 0.0 && w_sum > 0.0;
        if !hall.tiles.is_empty() && !supplied {
            return Err(format!(
                "snapshot `{}`: no floor supply reaches the tiles (fan speeds zero?)",
                state.label
            ));
        }
        let supply_t = if floor_q > 0.0 {
            floor_qt / floor_q
        } else {
            state.setpoint_c[0]
        };
        let server_flow: Vec<f64> = alpha
            .iter()
            .zip(&state.power_w)
            .map(|(a, p)| a * p * M3_S_PER_CFM)
            .collect();
        let rho_cp = st.rho_kg_m3 * st.cp_j_kgk;
        Ok(RunInputs {
            server_heat_k_m3_s: state.power_w.iter().map(|p| p / rho_cp).collect(),
            server_flow_m3_s: server_flow,
            tile_flow_m3_s: weights.iter().map(|w| floor_q * w / w_sum).collect(),
            tile_t_c: vec![supply_t; hall.tiles.len()],
            t_init_c: supply_t,
            heat_w: state.power_w.iter().sum(),
        })
    }

    /// The text of `0.orig/include/params`.
    pub fn render(&self) -> String {
        let mut s = String::from("// Written by kalibre for one run.\n");
        let _ = writeln!(s, "t_init {:.9e};", self.t_init_c);
        let _ = writeln!(s, "k_in {K_IN:e};\nepsilon_in {EPSILON_IN:e};");
        for (i, (q, su)) in self
            .server_flow_m3_s
            .iter()
            .zip(&self.server_heat_k_m3_s)
            .enumerate()
        {
            let _ = writeln!(s, "q_srv{i} {q:.9e};\nsu_srv{i} {su:.9e};");
        }
        for (t, (q, temp)) in self.tile_flow_m3_s.iter().zip(&self.tile_t_c).enumerate() {
            let _ = writeln!(s, "q_tile{t} {q:.9e};\nt_tile{t} {temp:.9e};");
        }
        s
    }
}
