//! The result of one simulator run: fields, sensor readings, balances, solver figures.

use super::advection::AdvectionStats;
use super::flow::mass_imbalance;
use super::grid::Grid;
use super::linalg::SolveStats;

/// Fields and figures of one solved operating state.
#[derive(Debug, Clone)]
pub struct Solution {
    /// The operating state's label.
    pub label: String,
    /// Pressure per cell (Darcy potential; only differences matter).
    pub pressure: Vec<f64>,
    /// Volume flux (m3/s) through the face between cell `c` and `c + stride(axis)`,
    /// positive towards `+axis`, per axis.
    pub face_flux_m3_s: [Vec<f64>; 3],
    /// Flux (m3/s) out of each cell through a ceiling return (or the gauge outlet).
    pub outlet_flux_m3_s: Vec<f64>,
    /// Fixed outflow (m3/s) per cell into CRAC tops (halls without returns).
    pub fixed_sink_m3_s: Vec<f64>,
    /// Net volume source (m3/s) per cell: supply, server exhausts, minus intakes and the
    /// CRAC tops' fixed sinks, ...
    pub source_m3_s: Vec<f64>,
    /// Temperature per cell (C); NaN in solid cells.
    pub temperature_c: Vec<f64>,
    pub(crate) sensor_c: Vec<f64>,
    /// Flux-weighted mean temperature of the air leaving the room (C).
    pub return_c: f64,
    /// Flux-weighted mean supply temperature (C).
    pub supply_c: f64,
    /// Total supply flow (m3/s).
    pub supply_flow_m3_s: f64,
    /// Total flow leaving through returns (or CRAC tops) (m3/s).
    pub return_flow_m3_s: f64,
    /// Flow per server (m3/s).
    pub server_flow_m3_s: Vec<f64>,
    /// Flow-weighted mean intake temperature per server (C).
    pub server_intake_c: Vec<f64>,
    /// Exhaust temperature per server (C).
    pub server_exhaust_c: Vec<f64>,
    /// Total server power (W).
    pub power_w: f64,
    /// Heat carried out by the air, `rho cp (sum_out q T - sum_in q T)` (W).
    pub heat_removed_w: f64,
    /// Pressure solve figures.
    pub pressure_stats: SolveStats,
    /// Temperature solve figures (iterations summed over the deferred-correction passes).
    pub heat_stats: SolveStats,
    /// Deferred-correction passes of a TVD advection scheme (zero for upwind).
    pub advection_stats: AdvectionStats,
}

impl Solution {
    /// Sensor temperatures (C), hall order.
    pub fn sensor_c(&self) -> &[f64] {
        &self.sensor_c
    }

    /// Relative energy balance error `(heat removed - power) / power` (0 when no power).
    pub fn energy_balance_error(&self) -> f64 {
        if self.power_w > 0.0 {
            (self.heat_removed_w - self.power_w) / self.power_w
        } else {
            0.0
        }
    }

    /// Per-cell mass imbalance (m3/s): net outflow minus sources. The sources already
    /// net out the CRAC tops' fixed sinks (halls without returns), so only the returns'
    /// outflow is added (counting the sinks again once put a whole CRAC top's share in
    /// every top cell's imbalance).
    pub fn mass_imbalance_m3_s(&self, grid: &Grid) -> Vec<f64> {
        mass_imbalance(
            grid,
            &self.face_flux_m3_s,
            &self.outlet_flux_m3_s,
            &self.source_m3_s,
        )
    }

    /// Cell-centred velocity (m/s): the mean of the two face velocities per axis.
    pub fn velocity_m_s(&self, grid: &Grid) -> Vec<[f64; 3]> {
        let n = grid.len();
        (0..n)
            .map(|c| {
                let mut v = [0.0; 3];
                for (a, va) in v.iter_mut().enumerate() {
                    let s = grid.stride(a);
                    let hi = self.face_flux_m3_s[a][c];
                    let lo = if grid.ijk(c)[a] > 0 {
                        self.face_flux_m3_s[a][c - s]
                    } else {
                        0.0
                    };
                    *va = 0.5 * (hi + lo) / grid.face_area(a);
                }
                v
            })
            .collect()
    }
}
