//! The paper's search regulariser: a ReLU penalty on server temperature rises outside a
//! plausible range, weighted by server power, and a report of where it binds.
//!
//! A server's rise is `dT_j = P_j / (rho cp Q_j)` with `Q_j = alpha_j P_j * 4.71947e-4`
//! m3/s, i.e. `dT_j = K / alpha_j` with `K = 1 / (4.71947e-4 rho cp)` (1.757 K cfm/W at
//! rho 1.2 kg/m3, cp 1005 J/(kg K)), independent of the power. The penalty is
//!
//! ```text
//! R(alpha) = mean over snapshots s of
//!            mean over servers j of (P_sj / mean_j P_sj) * (relu(lo - dT_j) + relu(dT_j - hi))
//! ```
//!
//! in kelvin. The paper weights by raw watts and sums over servers, which makes the prior
//! thousands of times larger than the data term (a mean squared error in K^2); weighting by
//! power relative to the mean and averaging keeps a uniform 1 K violation at a cost of 1,
//! comparable with the data. It is a prior, not physics: real servers run rises of
//! 15-20 C, so [`TemperatureRisePenalty::report`] says when and where it binds (a
//! prior-data conflict) instead of silently clamping alpha.

use kalibre_core::{number, Regularizer};
use serde::{Deserialize, Serialize};

use super::adjacency::setting;
use crate::hall::Hall;
use crate::snapshots::OperatingState;
use crate::{Error, ParamLayout, Result};

/// m3/s per cfm.
pub const M3_S_PER_CFM: f64 = 4.71947e-4;

/// The highest plausible rise a prior may name (K): air leaving a server 100 K above its
/// intake is already far beyond any server's limits.
pub const MAX_RISE_C: f64 = 100.0;

/// The largest penalty weight: at 1e6 a violation of 1 mK already costs as much as a 1 K
/// misfit, a hard constraint; larger weights only overflow the search loss.
pub const MAX_WEIGHT: f64 = 1e6;

/// Settings of the [`TemperatureRisePenalty`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `lower_c` | 5 | lowest plausible server temperature rise (K) | `>= 0` |
/// | `upper_c` | 20 | highest plausible rise (K); the paper's 15 ([`Self::paper`]) is below what real servers run (15-20 K) and, where the truth lies above it, pulls every calibration away from the truth | `> lower_c`, `<= 100` ([`MAX_RISE_C`]) |
/// | `weight` | 1 | the paper's lambda: pass it to the objective with the penalty | `[0, 1e6]` ([`MAX_WEIGHT`]) |
/// | `air_density_kg_m3` | 1.2 | rho | `> 0` |
/// | `air_heat_capacity_j_kg_k` | 1005 | cp | `> 0` |
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PenaltySettings {
    /// Lower end of the plausible rise (K).
    pub lower_c: f64,
    /// Upper end of the plausible rise (K).
    pub upper_c: f64,
    /// Weight of the penalty in the search objective.
    pub weight: f64,
    /// Air density (kg/m3).
    pub air_density_kg_m3: f64,
    /// Air heat capacity (J/(kg K)).
    pub air_heat_capacity_j_kg_k: f64,
}

impl Default for PenaltySettings {
    fn default() -> Self {
        PenaltySettings {
            lower_c: 5.0,
            upper_c: 20.0,
            weight: 1.0,
            air_density_kg_m3: 1.2,
            air_heat_capacity_j_kg_k: 1005.0,
        }
    }
}

impl PenaltySettings {
    /// The paper's prior: rises in [5, 15] K, weight 1.
    pub fn paper() -> Self {
        PenaltySettings::default().with_range_c(5.0, 15.0)
    }

    /// Sets the plausible range of server temperature rises (K).
    pub fn with_range_c(mut self, lower_c: f64, upper_c: f64) -> Self {
        self.lower_c = lower_c;
        self.upper_c = upper_c;
        self
    }
    /// Sets the weight.
    pub fn with_weight(mut self, weight: f64) -> Self {
        self.weight = weight;
        self
    }
    /// Sets the air properties.
    pub fn with_air(mut self, density_kg_m3: f64, heat_capacity_j_kg_k: f64) -> Self {
        self.air_density_kg_m3 = density_kg_m3;
        self.air_heat_capacity_j_kg_k = heat_capacity_j_kg_k;
        self
    }
    /// Validates the settings.
    pub fn check(self) -> Result<Self> {
        if !(self.lower_c.is_finite() && self.lower_c >= 0.0) {
            return Err(setting(
                "lower_c",
                format!("must be >= 0, got {}", number(self.lower_c)),
            ));
        }
        if !(self.upper_c.is_finite() && self.upper_c > self.lower_c) {
            return Err(setting(
                "upper_c",
                format!(
                    "must exceed lower_c {}, got {}",
                    number(self.lower_c),
                    number(self.upper_c)
                ),
            ));
        }
        if self.upper_c > MAX_RISE_C {
            return Err(setting(
                "upper_c",
                format!(
                    "must be at most {MAX_RISE_C} K, got {}",
                    number(self.upper_c)
                ),
            ));
        }
        if !(self.weight.is_finite() && (0.0..=MAX_WEIGHT).contains(&self.weight)) {
            return Err(setting(
                "weight",
                format!(
                    "must be in [0, {MAX_WEIGHT:e}], got {}",
                    number(self.weight)
                ),
            ));
        }
        for (name, v) in [
            ("air_density_kg_m3", self.air_density_kg_m3),
            ("air_heat_capacity_j_kg_k", self.air_heat_capacity_j_kg_k),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(setting(
                    name,
                    format!("must be positive, got {}", number(v)),
                ));
            }
        }
        Ok(self)
    }

    /// `K` in `dT = K / alpha` (K cfm/W).
    pub fn rise_coefficient(&self) -> f64 {
        1.0 / (M3_S_PER_CFM * self.air_density_kg_m3 * self.air_heat_capacity_j_kg_k)
    }

    /// The plausible box of `layout`'s parameters: each alpha between `K / upper_c` and
    /// `K / lower_c` (the rises this prior accepts), clipped to its bounds; every other
    /// parameter, and an alpha whose bounds miss that range, over its whole bounds.
    /// For [`kalibre_core::Calibrator::with_design_bounds`].
    pub fn plausible_bounds(&self, layout: &ParamLayout) -> (Vec<f64>, Vec<f64>) {
        let space = layout.space();
        let k = self.rise_coefficient();
        let mut is_alpha = vec![false; space.dim()];
        for p in layout.alpha_index().iter().flatten() {
            is_alpha[*p] = true;
        }
        space
            .params()
            .iter()
            .zip(is_alpha)
            .map(|(p, alpha)| {
                let (lo, hi) = if alpha {
                    let hi = if self.lower_c > 0.0 {
                        k / self.lower_c
                    } else {
                        p.upper
                    };
                    ((k / self.upper_c).max(p.lower), hi.min(p.upper))
                } else {
                    (p.lower, p.upper)
                };
                if lo < hi {
                    (lo, hi)
                } else {
                    (p.lower, p.upper)
                }
            })
            .unzip()
    }
}

/// Which end of the range a server's rise violates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RiseBound {
    /// Below `lower_c` (alpha too large).
    Below,
    /// Above `upper_c` (alpha too small).
    Above,
}

/// One alpha value whose rise lies outside the range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RiseViolation {
    /// The parameter name, or `fixed alpha of server <id>` when alpha is not calibrated.
    pub source: String,
    /// The alpha (cfm/W).
    pub alpha_cfm_per_w: f64,
    /// The rise it implies (K).
    pub rise_c: f64,
    /// Which bound.
    pub bound: RiseBound,
    /// Servers with this alpha.
    pub servers: usize,
}

/// Where the penalty binds at given parameters (a prior-data conflict when it binds at
/// the calibrated optimum).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PenaltyReport {
    /// The unweighted penalty (K).
    pub value: f64,
    /// True when any server's rise lies outside the range.
    pub binds: bool,
    /// The range (K).
    pub range_c: [f64; 2],
    /// Servers below the range.
    pub servers_below: usize,
    /// Servers above the range.
    pub servers_above: usize,
    /// Share of the penalty weight (power-weighted) carried by servers outside the range.
    pub weight_fraction_outside: f64,
    /// Each alpha value outside the range, largest violation first.
    pub violations: Vec<RiseViolation>,
}

impl PenaltyReport {
    /// The report of a prior turned off (weight 0): it binds nothing, whatever rises the
    /// parameters give, since it took no part in the fit.
    pub fn without_prior(self) -> Self {
        PenaltyReport {
            value: 0.0,
            binds: false,
            servers_below: 0,
            servers_above: 0,
            weight_fraction_outside: 0.0,
            violations: Vec::new(),
            ..self
        }
    }
}

/// The paper's power-weighted ReLU penalty on server temperature rises (module docs).
#[derive(Debug, Clone)]
pub struct TemperatureRisePenalty {
    layout: ParamLayout,
    server_ids: Vec<String>,
    /// Per server: mean over snapshots of `P_sj / mean_j P_sj`, divided by the server count.
    server_weight: Vec<f64>,
    settings: PenaltySettings,
    k: f64,
}

impl TemperatureRisePenalty {
    /// The penalty for `hall` with its parameter layout, weighted by the powers of
    /// `scenarios` (the snapshots searched over).
    pub fn new(
        hall: &Hall,
        layout: &ParamLayout,
        scenarios: &[OperatingState],
        settings: PenaltySettings,
    ) -> Result<Self> {
        let settings = settings.check()?;
        let m = hall.server_count();
        if layout.alpha_index().len() != m {
            return Err(Error::Mismatch(format!(
                "parameter layout covers {} servers, hall `{}` has {m}",
                layout.alpha_index().len(),
                hall.name
            )));
        }
        if scenarios.is_empty() {
            return Err(Error::Mismatch(
                "the rise penalty needs at least one snapshot".into(),
            ));
        }
        let mut server_weight = vec![0.0; m];
        for s in scenarios {
            if s.power_w.len() != m || s.power_w.iter().any(|p| !p.is_finite() || *p < 0.0) {
                return Err(Error::Mismatch(format!(
                    "snapshot `{}`: needs {m} finite non-negative server powers",
                    s.label
                )));
            }
            let mean = s.power_w.iter().sum::<f64>() / m.max(1) as f64;
            if mean > 0.0 {
                for (w, p) in server_weight.iter_mut().zip(&s.power_w) {
                    *w += p / mean / (scenarios.len() * m) as f64;
                }
            }
        }
        Ok(TemperatureRisePenalty {
            layout: layout.clone(),
            server_ids: hall.servers().map(|s| s.server.id.clone()).collect(),
            server_weight,
            k: settings.rise_coefficient(),
            settings,
        })
    }

    /// The settings (the weight to use is `settings().weight`).
    pub fn settings(&self) -> &PenaltySettings {
        &self.settings
    }

    /// A server's temperature rise (K) at `alpha` (cfm/W).
    pub fn rise_c(&self, alpha_cfm_per_w: f64) -> f64 {
        self.k / alpha_cfm_per_w
    }

    /// Per-server weights (mean relative power over snapshots, divided by the server count).
    pub fn server_weights(&self) -> &[f64] {
        &self.server_weight
    }

    /// ReLU violation and its derivative with respect to the rise.
    pub(crate) fn violation(&self, rise: f64) -> (f64, f64) {
        relu_outside(self.settings.lower_c, self.settings.upper_c, rise)
    }

    /// `K` in `dT = K / alpha`.
    pub(crate) fn rise_coefficient(&self) -> f64 {
        self.k
    }

    /// Where the penalty binds at physical parameters `params`.
    pub fn report(&self, params: &[f64]) -> PenaltyReport {
        let alpha = self.layout.alpha_per_server(params);
        let space = self.layout.space();
        let mut rep = PenaltyReport {
            value: 0.0,
            binds: false,
            range_c: [self.settings.lower_c, self.settings.upper_c],
            servers_below: 0,
            servers_above: 0,
            weight_fraction_outside: 0.0,
            violations: Vec::new(),
        };
        let total_weight: f64 = self.server_weight.iter().sum();
        // Group servers by the source of their alpha (a parameter or a fixed value).
        let mut groups: Vec<(Option<usize>, usize, RiseViolation, f64)> = Vec::new();
        for (j, (&a, &w)) in alpha.iter().zip(&self.server_weight).enumerate() {
            let rise = self.rise_c(a);
            let (v, _) = self.violation(rise);
            rep.value += w * v;
            // A server that draws no power in any snapshot has no rise to bind.
            if v == 0.0 || w == 0.0 {
                continue;
            }
            let bound = if rise < self.settings.lower_c {
                rep.servers_below += 1;
                RiseBound::Below
            } else {
                rep.servers_above += 1;
                RiseBound::Above
            };
            rep.weight_fraction_outside += w;
            let src = self.layout.alpha_index()[j];
            match groups.iter_mut().find(|g| src.is_some() && g.0 == src) {
                Some(g) => g.2.servers += 1,
                None => groups.push((
                    src,
                    j,
                    RiseViolation {
                        source: match src {
                            Some(i) => space.params()[i].name.clone(),
                            None => format!("fixed alpha of server {}", self.server_ids[j]),
                        },
                        alpha_cfm_per_w: a,
                        rise_c: rise,
                        bound,
                        servers: 1,
                    },
                    v,
                )),
            }
        }
        if total_weight > 0.0 {
            rep.weight_fraction_outside /= total_weight;
        }
        groups.sort_by(|a, b| b.3.total_cmp(&a.3).then(a.1.cmp(&b.1)));
        rep.violations = groups.into_iter().map(|g| g.2).collect();
        rep.binds = rep.servers_below + rep.servers_above > 0;
        rep
    }
}

/// `(lo - x)+ + (x - hi)+` and its slope in `x`, for `lo < hi`.
///
/// Branch-free, since searchers' alphas land on both sides of the range at random: at most
/// one ReLU is non-zero and adding `+0.0` to it is exact, so this equals the `if` / `else`
/// form bit for bit (a NaN gives 0).
pub(super) fn relu_outside(lo: f64, hi: f64, x: f64) -> (f64, f64) {
    let below = (lo - x).max(0.0);
    let above = (x - hi).max(0.0);
    let slope = f64::from(u8::from(above > 0.0)) - f64::from(u8::from(below > 0.0));
    (below + above, slope)
}

impl Regularizer for TemperatureRisePenalty {
    /// The unweighted penalty and its gradient with respect to the parameters:
    /// `dR/dalpha_j = w_j * relu'(...) * (-K / alpha_j^2)`.
    fn value_and_gradient(&self, params: &[f64]) -> (f64, Vec<f64>) {
        let alpha = self.layout.alpha_per_server(params);
        let mut value = 0.0;
        let mut g_alpha = vec![0.0; alpha.len()];
        for ((g, &a), &w) in g_alpha.iter_mut().zip(&alpha).zip(&self.server_weight) {
            let (v, dv) = self.violation(self.k / a);
            value += w * v;
            *g = w * dv * (-self.k / (a * a));
        }
        let mut grad = vec![0.0; params.len()];
        self.layout.accumulate_alpha_gradient(&g_alpha, &mut grad);
        (value, grad)
    }

    /// The same sum as [`Self::value_and_gradient`], in the same order (bit-identical).
    fn value(&self, params: &[f64]) -> f64 {
        let mut value = 0.0;
        for (a, &w) in self
            .layout
            .alpha_per_server_iter(params)
            .zip(&self.server_weight)
        {
            value += w * self.violation(self.k / a).0;
        }
        value
    }
}

#[cfg(test)]
mod tests {
    use super::relu_outside;

    /// The branching form it replaced.
    fn reference(lo: f64, hi: f64, x: f64) -> (f64, f64) {
        if x < lo {
            (lo - x, -1.0)
        } else if x > hi {
            (x - hi, 1.0)
        } else {
            (0.0, 0.0)
        }
    }

    #[test]
    fn the_branch_free_relus_equal_the_branching_form_bit_for_bit() {
        let (lo, hi) = (5.0, 20.0);
        let mut xs = vec![
            lo,
            hi,
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            lo - 1e-15,
            hi + 1e-14,
        ];
        xs.extend((0..2000).map(|i| 1.757 / (0.01 + 0.0015 * i as f64)));
        for x in xs {
            let (v, d) = relu_outside(lo, hi, x);
            let (rv, rd) = reference(lo, hi, x);
            assert_eq!(
                (v.to_bits(), d.to_bits()),
                (rv.to_bits(), rd.to_bits()),
                "x = {x}"
            );
        }
    }
}
