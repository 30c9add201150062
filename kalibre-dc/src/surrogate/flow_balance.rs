//! Mass-balance terms of the thermal graph: recirculation and bypass.
//!
//! The paper's surrogate assumes contained aisles with negligible recirculation, so its
//! cold-aisle outputs ignore alpha. In a real hall (and in the built-in simulator) the
//! servers' total draw `Q_srv = sum_j alpha_j P_j` against the supply `Q_sup` decides
//! both: when servers draw more than the supply, the deficit is made up by exhaust air
//! pulled back to the intakes (recirculation warms the cold aisle); when the supply
//! exceeds the draw, the surplus dilutes the exhaust (bypass cools the hot aisle). Both
//! features are global per snapshot, smooth in alpha, and enter each sensor with its own
//! trained weight (so where the hot air reappears is learned from the runs):
//!
//! - recirculation: `r * dT`, with `r = softplus_w(Q_srv - Q_sup) / Q_srv` the share of
//!   intake air that is recirculated and `dT = sum P / (rho cp Q_srv)` the mean exhaust rise;
//! - bypass: `b * dT`, with `b = softplus_w(Q_sup - Q_srv) / Q_sup`.
//!
//! `softplus_w(x) = w ln(1 + e^(x/w))` with `w` = 2% of the supply keeps the kink smooth.

use super::penalty::M3_S_PER_CFM;
use super::term::{SurrogateTerm, TEMPERATURE_MIN_SCALE_K};
use crate::hall::Hall;
use crate::snapshots::OperatingState;
use crate::ParamLayout;

/// Which side of the mass balance a [`FlowBalanceTerm`] describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlowBalance {
    /// Servers draw more than the supply.
    Recirculation,
    /// The supply exceeds the servers' draw.
    Bypass,
}

/// A mass-balance feature shared by every sensor (see the module docs).
#[derive(Debug, Clone)]
pub struct FlowBalanceTerm {
    kind: FlowBalance,
    layout: ParamLayout,
    rated_flow_m3_s: Vec<f64>,
    rho_cp: f64,
}

/// Smooth `max(0, x)` with width `w`, and its derivative.
fn softplus(x: f64, w: f64) -> (f64, f64) {
    let z = x / w;
    if z > 30.0 {
        (x, 1.0)
    } else if z < -30.0 {
        (w * z.exp(), z.exp())
    } else {
        let e = z.exp();
        (w * e.ln_1p(), e / (1.0 + e))
    }
}

impl FlowBalanceTerm {
    /// The term for `hall` with its parameter layout (air: rho 1.2 kg/m3, cp 1005 J/(kg K)).
    pub fn new(hall: &Hall, layout: &ParamLayout, kind: FlowBalance) -> Self {
        FlowBalanceTerm {
            kind,
            layout: layout.clone(),
            rated_flow_m3_s: hall.cracs.iter().map(|c| c.rated_flow_m3_s).collect(),
            rho_cp: 1.2 * 1005.0,
        }
    }

    /// The feature and its derivative with respect to the servers' total flow `Q_srv`.
    fn feature(&self, s: &OperatingState, q_srv: f64) -> (f64, f64) {
        let q_sup: f64 = s
            .fan_speed
            .iter()
            .zip(&self.rated_flow_m3_s)
            .map(|(v, r)| v * r)
            .sum();
        let power: f64 = s.power_w.iter().sum();
        if !(q_srv > 0.0 && q_sup > 0.0 && power > 0.0) {
            return (0.0, 0.0);
        }
        let w = 0.02 * q_sup;
        let rise = power / (self.rho_cp * q_srv);
        let drise = -rise / q_srv;
        match self.kind {
            FlowBalance::Recirculation => {
                let (d, dd) = softplus(q_srv - q_sup, w);
                let r = d / q_srv;
                let dr = (dd * q_srv - d) / (q_srv * q_srv);
                (r * rise, dr * rise + r * drise)
            }
            FlowBalance::Bypass => {
                let (d, dd) = softplus(q_sup - q_srv, w);
                let b = d / q_sup;
                let db = -dd / q_sup;
                (b * rise, db * rise + b * drise)
            }
        }
    }

    fn server_flow(&self, s: &OperatingState, params: &[f64]) -> f64 {
        let alpha = self.layout.alpha_per_server(params);
        M3_S_PER_CFM
            * s.power_w
                .iter()
                .zip(&alpha)
                .map(|(p, a)| p * a)
                .sum::<f64>()
    }
}

impl SurrogateTerm for FlowBalanceTerm {
    fn name(&self) -> &str {
        match self.kind {
            FlowBalance::Recirculation => "recirculation",
            FlowBalance::Bypass => "bypass",
        }
    }

    fn min_scale(&self) -> f64 {
        TEMPERATURE_MIN_SCALE_K
    }

    fn hall_wide(&self) -> bool {
        true
    }

    fn features(&self, scenario: &OperatingState, params: &[f64], out: &mut [f64]) {
        let (f, _) = self.feature(scenario, self.server_flow(scenario, params));
        out.fill(f);
    }

    fn features_vjp(
        &self,
        scenario: &OperatingState,
        params: &[f64],
        cotangent: &[f64],
        grad: &mut [f64],
    ) {
        let (_, df) = self.feature(scenario, self.server_flow(scenario, params));
        let g: f64 = cotangent.iter().sum::<f64>() * df;
        if g == 0.0 {
            return;
        }
        // d Q_srv / d alpha_j = P_j * M3_S_PER_CFM.
        let per_server: Vec<f64> = scenario
            .power_w
            .iter()
            .map(|p| g * p * M3_S_PER_CFM)
            .collect();
        self.layout.accumulate_alpha_gradient(&per_server, grad);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softplus_is_smooth_max() {
        assert!((softplus(5.0, 0.1).0 - 5.0).abs() < 1e-9);
        assert!(softplus(-5.0, 0.1).0 < 1e-9);
        let (v, d) = softplus(0.0, 0.1);
        assert!((v - 0.1 * 2f64.ln()).abs() < 1e-12 && (d - 0.5).abs() < 1e-12);
        for &x in &[-0.3, -0.05, 0.0, 0.02, 0.4] {
            let h = 1e-6;
            let fd = (softplus(x + h, 0.1).0 - softplus(x - h, 0.1).0) / (2.0 * h);
            assert!((fd - softplus(x, 0.1).1).abs() < 1e-6);
        }
    }
}
