//! The paper's search loss `L2` on a fitted thermal graph, specialised for speed.
//!
//! It computes exactly what [`kalibre_core::SurrogateObjective`] computes with a
//! [`ThermalGraph`] and a [`TemperatureRisePenalty`] (the tests check both agree), but
//! precomputes everything that does not depend on the parameters once:
//! - the cooling block (`X_cold` depends only on the operating state) and every offset,
//!   so a cold-aisle sensor's residual is a constant;
//! - for each measured hot-aisle sensor of each snapshot, the sparse row
//!   `(c_k / s_k) * Wss_jk * P_sj` merged per alpha parameter (per type: a handful of
//!   entries per row; per server: the sensor's neighbourhood), so a prediction is
//!   `base + sum_p row_p / alpha_p`;
//! - the penalty's power weights merged per alpha parameter.
//!
//! One evaluation is then one reciprocal (and one `exp` on a log scale) per alpha
//! parameter plus one multiply-add per merged entry, with no allocation beyond two
//! buffers. Effect parameters reach the loss through the graph's additional terms,
//! evaluated per snapshot.

use kalibre_core::search::Objective;
use kalibre_core::Observations;

use super::graph::ThermalGraph;
use super::penalty::{relu_outside, TemperatureRisePenalty};
use crate::snapshots::OperatingState;
use crate::{Error, Result};

/// One measured output whose prediction depends on the parameters.
#[derive(Debug, Clone, Copy)]
struct Row {
    snapshot: usize,
    sensor: usize,
    base: f64,
    measured: f64,
}

/// `1 / x` of a parameter as a function of its unit coordinate `u` (clamped to `[0, 1]`).
#[derive(Debug, Clone, Copy)]
enum InverseMap {
    /// `x = lower * exp(u * ln(upper / lower))`, so `1 / x = exp(-(ln lower + u * ln_ratio))`:
    /// one `exp` per evaluation, the logarithms taken once.
    Log { ln_lower: f64, ln_ratio: f64 },
    /// `x = lower + u * (upper - lower)`.
    Linear { lower: f64, range: f64 },
}

impl InverseMap {
    fn new(p: &kalibre_core::Param) -> Self {
        match p.scale {
            kalibre_core::Scale::Log => InverseMap::Log {
                ln_lower: p.lower.ln(),
                ln_ratio: (p.upper / p.lower).ln(),
            },
            kalibre_core::Scale::Linear => InverseMap::Linear {
                lower: p.lower,
                range: p.upper - p.lower,
            },
        }
    }

    /// `1 / x` and `d(1/x)/du`.
    #[inline]
    fn eval(self, u: f64) -> (f64, f64) {
        let u = u.clamp(0.0, 1.0);
        match self {
            InverseMap::Log { ln_lower, ln_ratio } => {
                let inv = (-(ln_lower + u * ln_ratio)).exp();
                (inv, -ln_ratio * inv)
            }
            InverseMap::Linear { lower, range } => {
                let inv = 1.0 / (lower + u * range);
                (inv, -range * inv * inv)
            }
        }
    }
}

/// Precomputed penalty terms per alpha parameter.
#[derive(Debug, Clone)]
struct SlotPenalty {
    weight: f64,
    lower: f64,
    upper: f64,
    k: f64,
    /// Penalty weight of the servers sharing each alpha parameter.
    slot_weight: Vec<f64>,
    /// Contribution of servers with a fixed alpha.
    fixed: f64,
}

/// `L2` = mean squared error over every measured value + `weight * penalty`, over the
/// unit box of the graph's parameter layout (see the module docs).
#[derive(Debug)]
pub struct ThermalGraphObjective<'a> {
    graph: &'a ThermalGraph,
    observations: &'a Observations<OperatingState>,
    /// Alpha parameters (indices into the parameter vector).
    slot_param: Vec<usize>,
    /// Per parameter: its slot, when it is an alpha parameter.
    param_slot: Vec<Option<usize>>,
    /// Per slot: how a unit coordinate maps to `1 / alpha`.
    slot_map: Vec<InverseMap>,
    /// When the alpha parameters are contiguous and all on a log scale (always so for a
    /// [`crate::ParamLayout`]): the first index, and `1 / alpha = exp(c0 + u * c1)`.
    log_slots: Option<(usize, Vec<f64>, Vec<f64>)>,
    rows: Vec<Row>,
    row_ptr: Vec<usize>,
    col: Vec<u32>,
    val: Vec<f64>,
    /// Sum of squared residuals of the outputs that do not depend on the parameters.
    constant_sq: f64,
    measured_count: f64,
    penalty: Option<SlotPenalty>,
}

impl<'a> ThermalGraphObjective<'a> {
    /// The data term for a fitted graph against `observations` (their scenarios must fit
    /// the graph's hall).
    pub fn new(
        graph: &'a ThermalGraph,
        observations: &'a Observations<OperatingState>,
    ) -> Result<Self> {
        let layout = &graph.layout;
        let space = layout.space();
        let dim = space.dim();
        let n = graph.sensor_count();
        if observations.outputs().len() != n {
            return Err(Error::Mismatch(format!(
                "observations have {} outputs, the hall has {n} sensors",
                observations.outputs().len()
            )));
        }
        let mut param_slot = vec![None; dim];
        let mut slot_param = Vec::new();
        for p in layout.alpha_index().iter().flatten() {
            if param_slot[*p].is_none() {
                param_slot[*p] = Some(slot_param.len());
                slot_param.push(*p);
            }
        }
        let fixed_alpha = layout.alpha_per_server(&space.initial());
        let has_terms = !graph.terms.is_empty();
        let w = &graph.w;
        let ss = &graph.adjacency.ss;
        let slot_map: Vec<InverseMap> = slot_param
            .iter()
            .map(|&p| InverseMap::new(&space.params()[p]))
            .collect();
        let contiguous = slot_param.windows(2).all(|w| w[1] == w[0] + 1);
        let log_slots = if contiguous && !slot_param.is_empty() {
            let logs: Option<Vec<(f64, f64)>> = slot_map
                .iter()
                .map(|m| match *m {
                    InverseMap::Log { ln_lower, ln_ratio } => Some((-ln_lower, -ln_ratio)),
                    InverseMap::Linear { .. } => None,
                })
                .collect();
            logs.map(|l| {
                (
                    slot_param[0],
                    l.iter().map(|x| x.0).collect(),
                    l.iter().map(|x| x.1).collect(),
                )
            })
        } else {
            None
        };
        let mut obj = ThermalGraphObjective {
            graph,
            slot_map,
            log_slots,
            observations,
            param_slot,
            rows: Vec::new(),
            row_ptr: vec![0],
            col: Vec::new(),
            val: Vec::new(),
            constant_sq: 0.0,
            measured_count: observations.measured_count().max(1) as f64,
            penalty: None,
            slot_param,
        };
        let mut scratch = vec![0.0; obj.slot_param.len()];
        let mut in_row = vec![false; obj.slot_param.len()];
        let mut touched: Vec<usize> = Vec::new();
        let mut xc = vec![0.0; n];
        for (si, snap) in observations.snapshots().iter().enumerate() {
            let scen = &snap.scenario;
            graph.check_inputs(scen, &space.initial())?;
            graph.cold_hidden(&graph.adjacency.cs.val, scen, &mut xc, None);
            for (k, m) in snap.measured.iter().enumerate() {
                let Some(m) = *m else { continue };
                let mut base = w.a[k] * (xc[k] - w.cold_mean[k]) / w.cold_scale[k] + w.b[k];
                if graph.hot[k] {
                    let gain = w.c[k] / w.hot_scale[k];
                    base += w.d[k] - gain * w.hot_mean[k];
                    for e in ss.range(k) {
                        let j = ss.col[e] as usize;
                        let coef = gain * ss.val[e] * scen.power_w[j];
                        match layout.alpha_index()[j] {
                            Some(p) => {
                                let sl = obj.param_slot[p].unwrap_or(0);
                                if !in_row[sl] {
                                    in_row[sl] = true;
                                    touched.push(sl);
                                }
                                scratch[sl] += coef;
                            }
                            None => base += coef / fixed_alpha[j],
                        }
                    }
                }
                if !has_terms && touched.is_empty() {
                    obj.constant_sq += (base - m) * (base - m);
                    continue;
                }
                touched.sort_unstable();
                for &sl in &touched {
                    obj.col.push(sl as u32);
                    obj.val.push(scratch[sl]);
                    scratch[sl] = 0.0;
                    in_row[sl] = false;
                }
                touched.clear();
                obj.row_ptr.push(obj.val.len());
                obj.rows.push(Row {
                    snapshot: si,
                    sensor: k,
                    base,
                    measured: m,
                });
            }
        }
        Ok(obj)
    }

    /// Adds `penalty.settings().weight * penalty`.
    pub fn with_penalty(mut self, penalty: &TemperatureRisePenalty) -> Self {
        let layout = &self.graph.layout;
        let fixed_alpha = layout.alpha_per_server(&layout.space().initial());
        let s = penalty.settings();
        let mut p = SlotPenalty {
            weight: s.weight,
            lower: s.lower_c,
            upper: s.upper_c,
            k: penalty.rise_coefficient(),
            slot_weight: vec![0.0; self.slot_param.len()],
            fixed: 0.0,
        };
        for (j, &wj) in penalty.server_weights().iter().enumerate() {
            match layout.alpha_index()[j] {
                Some(i) => p.slot_weight[self.param_slot[i].unwrap_or(0)] += wj,
                None => p.fixed += wj * penalty.violation(p.k / fixed_alpha[j]).0,
            }
        }
        self.penalty = Some(p);
        self
    }

    /// Number of stored merged entries (the work per evaluation).
    pub fn nnz(&self) -> usize {
        self.val.len()
    }

    /// `1 / alpha` and its derivative per slot from unit coordinates; `None` on a
    /// non-finite coordinate.
    fn inverse_alpha(&self, u: &[f64], inv: &mut [f64], dinv: &mut [f64]) -> Option<()> {
        if self.slot_param.iter().any(|&p| !u[p].is_finite()) {
            return None;
        }
        match &self.log_slots {
            // Alpha on a log scale (always so in a `ParamLayout`): one `exp` per parameter,
            // the logarithms taken once at construction.
            Some((start, c0, c1)) => {
                let us = &u[*start..*start + c0.len()];
                for i in 0..c0.len() {
                    let v = (c0[i] + us[i].clamp(0.0, 1.0) * c1[i]).exp();
                    inv[i] = v;
                    dinv[i] = c1[i] * v;
                }
            }
            None => {
                for (sl, (&p, map)) in self.slot_param.iter().zip(&self.slot_map).enumerate() {
                    (inv[sl], dinv[sl]) = map.eval(u[p]);
                }
            }
        }
        Some(())
    }

    fn evaluate(&self, u: &[f64], mut grad: Option<&mut [f64]>) -> f64 {
        let space = self.graph.layout.space();
        if u.len() != space.dim() {
            return f64::NAN;
        }
        let mut inv = vec![0.0; self.slot_param.len()];
        let mut dinv = vec![0.0; self.slot_param.len()];
        if self.inverse_alpha(u, &mut inv, &mut dinv).is_none() {
            return f64::INFINITY;
        }
        let mut g_inv = vec![0.0; if grad.is_some() { inv.len() } else { 0 }];
        let mut pred: Vec<f64> = self.rows.iter().map(|r| r.base).collect();
        let terms = &self.graph.terms;
        let n = self.graph.sensor_count();
        let phys = if terms.is_empty() {
            Vec::new()
        } else {
            match space.from_unit(u) {
                Ok(p) => p,
                Err(_) => return f64::INFINITY,
            }
        };
        let w = &self.graph.w;
        // Term contributions, per snapshot.
        let mut f = vec![0.0; if terms.is_empty() { 0 } else { n * terms.len() }];
        let mut last_snapshot = usize::MAX;
        for (r, row) in self.rows.iter().enumerate() {
            let mut t = pred[r];
            for e in self.row_ptr[r]..self.row_ptr[r + 1] {
                t += self.val[e] * inv[self.col[e] as usize];
            }
            if !terms.is_empty() {
                if row.snapshot != last_snapshot {
                    f = self.graph.term_features(
                        &self.observations.snapshots()[row.snapshot].scenario,
                        &phys,
                    );
                    last_snapshot = row.snapshot;
                }
                for tt in 0..terms.len() {
                    let i = tt * n + row.sensor;
                    t += w.e[i] * (f[i] - w.term_mean[i]) / w.term_scale[i];
                }
            }
            pred[r] = t;
        }
        let mut sq = self.constant_sq;
        for (p, row) in pred.iter_mut().zip(&self.rows) {
            let r = *p - row.measured;
            sq += r * r;
            *p = 2.0 * r / self.measured_count; // now the cotangent
        }
        let mut cost = sq / self.measured_count;
        if let Some(g) = grad.as_deref_mut() {
            g.iter_mut().for_each(|x| *x = 0.0);
            for (r, ct) in pred.iter().enumerate() {
                for e in self.row_ptr[r]..self.row_ptr[r + 1] {
                    g_inv[self.col[e] as usize] += ct * self.val[e];
                }
            }
        }
        if let Some(pen) = &self.penalty {
            let mut value = pen.fixed;
            let with_grad = grad.is_some();
            for (sl, &iv) in inv.iter().enumerate() {
                // Branch-free ReLUs so the loop vectorises.
                let (v, dv) = relu_outside(pen.lower, pen.upper, pen.k * iv);
                value += pen.slot_weight[sl] * v;
                if with_grad {
                    g_inv[sl] += pen.weight * pen.slot_weight[sl] * dv * pen.k;
                }
            }
            cost += pen.weight * value;
        }
        if let Some(g) = grad {
            for (sl, &p) in self.slot_param.iter().enumerate() {
                g[p] = g_inv[sl] * dinv[sl];
            }
            if !terms.is_empty() {
                let mut g_phys = vec![0.0; space.dim()];
                let mut ct = vec![0.0; n];
                for (si, snap) in self.observations.snapshots().iter().enumerate() {
                    for (tt, term) in terms.iter().enumerate() {
                        ct.iter_mut().for_each(|c| *c = 0.0);
                        for (row, c) in self
                            .rows
                            .iter()
                            .zip(&pred)
                            .filter(|(r, _)| r.snapshot == si)
                        {
                            let i = tt * n + row.sensor;
                            ct[row.sensor] = c * w.e[i] / w.term_scale[i];
                        }
                        term.features_vjp(&snap.scenario, &phys, &ct, &mut g_phys);
                    }
                }
                // From the mapped values: no logarithm or exponential per parameter again.
                let dphys = space.dphys_dunit_at_physical(&phys);
                for ((gi, gp), d) in g.iter_mut().zip(&g_phys).zip(&dphys) {
                    *gi += gp * d;
                }
            }
        }
        cost
    }
}

impl Objective for ThermalGraphObjective<'_> {
    fn dim(&self) -> usize {
        self.graph.layout.space().dim()
    }

    fn cost(&self, x_unit: &[f64]) -> f64 {
        self.evaluate(x_unit, None)
    }

    fn cost_and_gradient(&self, x_unit: &[f64]) -> (f64, Vec<f64>) {
        let mut g = vec![0.0; x_unit.len()];
        let c = self.evaluate(x_unit, Some(&mut g));
        (c, g)
    }
}
