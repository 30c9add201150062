//! The per-run parameter file `0.orig/include/params`: the only file a run writes.

use std::fmt::Write;

use crate::hall::{Hall, SupplyKind};
use crate::snapshots::OperatingState;

use super::geometry::PANEL_LAYER_CELLS;
use super::{panel_loss_coefficient, OpenFoamSettings};

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
    /// Flow per bypass opening (m3/s), in the geometry's order.
    pub opening_flow_m3_s: Vec<f64>,
    /// Supply temperature per bypass opening (C).
    pub opening_t_c: Vec<f64>,
    /// Each `front` CRAC's supply through its face: (CRAC index, flow m3/s, temperature
    /// C), hall order; what openings take of its flow is not in it.
    pub front_supply: Vec<(usize, f64, f64)>,
    /// With no return grilles, each CRAC's flow drawn in at its top: (CRAC index, m3/s),
    /// hall order; empty otherwise.
    pub crac_return_flow: Vec<(usize, f64)>,
    /// Flow through each recirculation gap (m3/s), in the geometry's order.
    pub gap_flow_m3_s: Vec<f64>,
    /// Forchheimer coefficient of each containment panel plane's porous zone (1/m2,
    /// along its normal), in the geometry's order; see [`Self::with_panels`].
    pub panel_forchheimer_per_m2: Vec<f64>,
    /// Initial temperature of the room (C).
    pub t_init_c: f64,
    /// Total server heat (W).
    pub heat_w: f64,
}

impl RunInputs {
    /// The inputs of `state` at per-server `alpha` (cfm/W), per-CRAC supply offset (C),
    /// per-opening share of the supply (of every CRAC's flow, as the built-in simulator
    /// takes it; the tiles and `front` CRACs deliver the rest) and per-gap (rack index,
    /// fraction of the rack's server flow).
    pub fn new(
        hall: &Hall,
        state: &OperatingState,
        alpha: &[f64],
        supply_offset_c: &[f64],
        opening_share: &[f64],
        gap_fraction: &[(usize, f64)],
        st: &OpenFoamSettings,
    ) -> Result<Self, String> {
        if let Some((_, f)) = gap_fraction
            .iter()
            .find(|(_, f)| f.is_nan() || *f < 0.0 || f.is_infinite())
        {
            return Err(format!(
                "a recirculation gap takes a fraction {f} of its rack's flow; must be >= 0"
            ));
        }
        let open_share: f64 = opening_share.iter().sum();
        if !(0.0..1.0).contains(&open_share) || opening_share.iter().any(|s| s.is_nan() || *s < 0.0)
        {
            return Err(format!(
                "bypass openings take a share {open_share} of the supply; must be in [0, 1)"
            ));
        }
        let mut floor_q = 0.0;
        let mut floor_qt = 0.0;
        let (mut all_q, mut all_qt) = (0.0, 0.0);
        let mut front_supply = Vec::new();
        let mut crac_return_flow = Vec::new();
        for (c, crac) in hall.cracs.iter().enumerate() {
            let q = crac.rated_flow_m3_s * state.fan_speed[c];
            let t = state.setpoint_c[c] + supply_offset_c.get(c).copied().unwrap_or(0.0);
            all_q += q;
            all_qt += q * t;
            match crac.supply {
                SupplyKind::Floor => {
                    floor_q += q;
                    floor_qt += q * t;
                }
                SupplyKind::Front => front_supply.push((c, (1.0 - open_share) * q, t)),
            }
            if hall.returns.is_empty() {
                crac_return_flow.push((c, q));
            }
        }
        let weights: Vec<f64> = hall.tiles.iter().map(|t| t.open_area_m2()).collect();
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
        } else if all_q > 0.0 {
            all_qt / all_q
        } else {
            state.setpoint_c[0]
        };
        // Openings mix every CRAC's air (the plenum's alone when every CRAC is a floor
        // one, as before `front` CRACs could be solved).
        let (opening_q, opening_t) = if all_q > floor_q {
            (all_q, all_qt / all_q)
        } else {
            (floor_q, supply_t)
        };
        let server_flow: Vec<f64> = alpha
            .iter()
            .zip(&state.power_w)
            .map(|(a, p)| a * p * M3_S_PER_CFM)
            .collect();
        let rho_cp = st.rho_kg_m3 * st.cp_j_kgk;
        let mut rack_flow = vec![0.0; hall.racks.len()];
        for (s, q) in hall.servers().zip(&server_flow) {
            rack_flow[s.rack_index] += q;
        }
        let gap_flow: Vec<f64> = gap_fraction
            .iter()
            .map(|(r, f)| f * rack_flow.get(*r).copied().unwrap_or(0.0))
            .collect();
        Ok(RunInputs {
            server_heat_k_m3_s: state.power_w.iter().map(|p| p / rho_cp).collect(),
            server_flow_m3_s: server_flow,
            tile_flow_m3_s: weights
                .iter()
                .map(|w| (1.0 - open_share) * floor_q * w / w_sum)
                .collect(),
            tile_t_c: vec![supply_t; hall.tiles.len()],
            opening_flow_m3_s: opening_share.iter().map(|s| s * opening_q).collect(),
            opening_t_c: vec![opening_t; opening_share.len()],
            front_supply,
            crac_return_flow,
            gap_flow_m3_s: gap_flow,
            panel_forchheimer_per_m2: Vec::new(),
            t_init_c: supply_t,
            heat_w: state.power_w.iter().sum(),
        })
    }

    /// Sets the containment panels' resistance: `opened` per panel plane is the open
    /// fraction the `containment_leakage` effect gives it (0 for closed panels). As in the
    /// built-in simulator, a plane is open by `leak + (1 - leak) opened`, with `leak` the
    /// panels' own [`OpenFoamSettings::containment_leak_fraction`]; its porous zone,
    /// `PANEL_LAYER_CELLS` cells thick, gets `F = K / (2 h)` ([`panel_loss_coefficient`]).
    pub fn with_panels(mut self, opened: &[f64], st: &OpenFoamSettings) -> Result<Self, String> {
        if let Some(f) = opened.iter().find(|f| !(0.0..=1.0).contains(*f)) {
            return Err(format!(
                "a containment panel opened by {f}; the open fraction must be in [0, 1]"
            ));
        }
        let leak = st.containment_leak_fraction;
        self.panel_forchheimer_per_m2 = opened
            .iter()
            .map(|o| {
                panel_loss_coefficient(leak + (1.0 - leak) * o)
                    / (PANEL_LAYER_CELLS as f64 * st.grid_m)
            })
            .collect();
        Ok(self)
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
        for (b, (q, temp)) in self
            .opening_flow_m3_s
            .iter()
            .zip(&self.opening_t_c)
            .enumerate()
        {
            let _ = writeln!(s, "q_byp{b} {q:.9e};\nt_byp{b} {temp:.9e};");
        }
        for (r, q) in self.gap_flow_m3_s.iter().enumerate() {
            let _ = writeln!(s, "q_rec{r} {q:.9e};");
        }
        for (c, q, t) in &self.front_supply {
            let _ = writeln!(s, "q_sup{c} {q:.9e};\nt_sup{c} {t:.9e};");
        }
        // Printed as the inflows are, so that the fixed fluxes balance to rounding.
        for (c, q) in &self.crac_return_flow {
            let _ = writeln!(s, "q_crt{c} {q:.9e};");
        }
        for (k, f) in self.panel_forchheimer_per_m2.iter().enumerate() {
            let _ = writeln!(s, "f_panel{k} {f:.9e};");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn dev() -> (Hall, OperatingState) {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/openfoam/of-dev-clean");
        let hall = Hall::load(&dir.join("hall.json")).unwrap();
        let snaps = crate::snapshots::load_snapshots(&hall, &dir.join("snapshots.csv")).unwrap();
        (hall, snaps[0].state.clone())
    }

    /// Mass balance: the openings take their share of the floor supply and the tiles
    /// deliver the rest, so the total is the CRACs' flow whatever the share.
    #[test]
    fn openings_take_their_share_and_the_tiles_the_rest() {
        let (hall, state) = dev();
        let alpha = vec![0.15; state.power_w.len()];
        let st = OpenFoamSettings::default();
        let plain = RunInputs::new(&hall, &state, &alpha, &[], &[], &[], &st).unwrap();
        let with = RunInputs::new(&hall, &state, &alpha, &[], &[0.1, 0.05], &[], &st).unwrap();
        let total =
            |r: &RunInputs| -> f64 { r.tile_flow_m3_s.iter().chain(&r.opening_flow_m3_s).sum() };
        let crac: f64 = hall.cracs[0].rated_flow_m3_s * state.fan_speed[0];
        assert!((total(&plain) - crac).abs() < 1e-12);
        assert!((total(&with) - crac).abs() < 1e-12);
        assert!((with.opening_flow_m3_s[0] - 0.1 * crac).abs() < 1e-12);
        for (a, b) in plain.tile_flow_m3_s.iter().zip(&with.tile_flow_m3_s) {
            assert!((b - 0.85 * a).abs() < 1e-12);
        }
        assert_eq!(with.opening_t_c, vec![state.setpoint_c[0]; 2]);
        let text = with.render();
        assert!(
            text.contains("q_byp1 ") && text.contains("t_byp0 "),
            "{text}"
        );
    }

    /// A closed panel resists as an orifice of the leak fraction, an opened one as the
    /// built-in simulator opens it (`leak + (1 - leak) opened`), a fully open one not at
    /// all; the resistance is per unit length over the two-cell zone.
    #[test]
    fn panels_resist_as_orifices_of_their_open_fraction() {
        let (hall, state) = dev();
        let alpha = vec![0.15; state.power_w.len()];
        let st = OpenFoamSettings::default();
        let inputs = RunInputs::new(&hall, &state, &alpha, &[], &[], &[], &st)
            .unwrap()
            .with_panels(&[0.0, 0.5, 1.0], &st)
            .unwrap();
        let f = &inputs.panel_forchheimer_per_m2;
        let k = |open: f64| ((1.0 - open) / (0.61 * open)).powi(2);
        assert!((f[0] - k(0.02) / 0.4).abs() < 1e-9 * f[0]);
        assert!((f[1] - k(0.02 + 0.98 * 0.5) / 0.4).abs() < 1e-9 * f[0]);
        assert_eq!(f[2], 0.0);
        assert!(f[0] > f[1]);
        let text = inputs.render();
        assert!(text.contains("f_panel2 0.0"), "{text}");
        for bad in [-0.1, 1.5, f64::NAN] {
            let err = RunInputs::new(&hall, &state, &alpha, &[], &[], &[], &st)
                .unwrap()
                .with_panels(&[bad], &st)
                .unwrap_err();
            assert!(err.contains("open fraction must be in [0, 1]"), "{err}");
        }
    }

    /// Mass balance with a `front` CRAC and no grilles: what the tiles, the front and
    /// the openings let in is what the CRAC tops draw, each CRAC its own flow; the
    /// openings take their share of every CRAC's flow, as the built-in simulator does.
    #[test]
    fn a_front_crac_and_crac_tops_balance_the_supply() {
        let (mut hall, mut state) = dev();
        hall.cracs.push(hall.cracs[0].clone());
        hall.cracs[1].id = "crac-2".into();
        hall.cracs[1].supply = SupplyKind::Front;
        hall.cracs[1].rated_flow_m3_s = 2.0;
        state.fan_speed.push(0.5);
        state.setpoint_c.push(state.setpoint_c[0] + 4.0);
        hall.returns.clear();
        let alpha = vec![0.15; state.power_w.len()];
        let st = OpenFoamSettings::default();
        let r = RunInputs::new(&hall, &state, &alpha, &[0.0, 1.0], &[0.1], &[], &st).unwrap();
        let floor_q = hall.cracs[0].rated_flow_m3_s * state.fan_speed[0];
        let total = floor_q + 1.0;
        let inflow: f64 = r
            .tile_flow_m3_s
            .iter()
            .chain(&r.opening_flow_m3_s)
            .sum::<f64>()
            + r.front_supply.iter().map(|(_, q, _)| q).sum::<f64>();
        let outflow: f64 = r.crac_return_flow.iter().map(|(_, q)| q).sum();
        assert!((inflow - total).abs() < 1e-12 && (outflow - total).abs() < 1e-12);
        assert_eq!(r.crac_return_flow, vec![(0, floor_q), (1, 1.0)]);
        let (c, q, t) = r.front_supply[0];
        assert_eq!(c, 1);
        assert!((q - 0.9).abs() < 1e-12);
        assert!(
            (t - (state.setpoint_c[0] + 5.0)).abs() < 1e-12,
            "offset added: {t}"
        );
        assert!((r.opening_flow_m3_s[0] - 0.1 * total).abs() < 1e-12);
        let mixed = (floor_q * state.setpoint_c[0] + t) / total;
        assert!((r.opening_t_c[0] - mixed).abs() < 1e-9);
        let text = r.render();
        assert!(
            text.contains("q_sup1 ") && text.contains("t_sup1 "),
            "{text}"
        );
        assert!(
            text.contains("q_crt0 ") && text.contains("q_crt1 "),
            "{text}"
        );
        // With grilles and floor CRACs only, the file is as before: no CRAC faces.
        let (hall, state) = dev();
        let plain = RunInputs::new(&hall, &state, &alpha, &[], &[], &[], &st).unwrap();
        assert!(!plain.render().contains("_sup") && !plain.render().contains("q_crt"));
    }

    #[test]
    fn a_share_of_the_whole_supply_or_nan_is_refused() {
        let (hall, state) = dev();
        let alpha = vec![0.15; state.power_w.len()];
        let st = OpenFoamSettings::default();
        for shares in [vec![0.6, 0.4], vec![f64::NAN], vec![-0.1]] {
            let err = RunInputs::new(&hall, &state, &alpha, &[], &shares, &[], &st).unwrap_err();
            assert!(
                err.contains("bypass openings take a share"),
                "{shares:?}: {err}"
            );
        }
    }
}
