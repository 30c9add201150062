//! The thermal graph surrogate: its settings, its weights and its forward pass.
//!
//! For sensor `k` at operating state (`Tc`, `V`, `P`) and per-server alpha:
//!
//! ```text
//! c_ik      = softmax over the CRACs i with an edge to k of  V_i * Wcs_ik
//! X_cold_k  = sum_i Tc_i * c_ik
//! X_hot_k   = sum_j P_j / alpha_j * Wss_jk                      (hot-aisle sensors)
//! T_cold_k  = a_k * (X_cold_k - mc_k) / sc_k + b_k
//! dT_k      = c_k * (X_hot_k  - mh_k) / sh_k + d_k
//! T_k       = T_cold_k                (cold aisle)
//!           = T_cold_k + dT_k         (hot aisle; the paper's joining formula swaps e)
//!           + sum_t e_tk * (f_tk - mt_tk) / st_tk   (additional terms, see [`super::term`])
//! ```
//!
//! The centring `m` and scaling `s` of the hidden variables are fixed at each fit from the
//! training samples (mean and standard deviation over samples). They change nothing in
//! what the model can express (the paper's affine `a x + b`), but they make every weight
//! of order one, so Adam's fixed step (lr 0.1) means the same thing for every sensor:
//! `X_hot` is of order `1e3` (W per cfm/W) while `X_cold` is of order `20` C.

use kalibre_core::Surrogate;

use super::adjacency::{setting, Adjacency, AdjacencySettings};
use super::term::SurrogateTerm;
use crate::hall::{Aisle, Hall};
use crate::snapshots::OperatingState;
use crate::{Error, ParamLayout, Result};

/// Default [`ThermalGraphSettings::hall_wide_ridge`]: thirty times the default `ridge`.
/// Chosen in the loop (`examples/loop_variants.rs`; `docs/performance.md`): on 8 seeds per
/// hall against 0.01, 0.1, 0.3 and 1, then against 0.1 on 16 seeds.
pub const HALL_WIDE_RIDGE: f64 = 0.03;

/// Training settings of the [`ThermalGraph`] (unchecked; [`Self::check`] validates).
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `epochs` | 150 | full-batch Adam epochs per fit | `>= 0` |
/// | `learning_rate` | 0.1 | Adam's initial step | `> 0` |
/// | `decay_rate` | 0.8 | step multiplier per decay period | `(0, 1]` |
/// | `decay_every_epochs` | 10 | epochs per decay period (staircase: `lr * decay^(epoch / 10)`, 0.0035 at epoch 150) | `>= 1` |
/// | `trainable_adjacency` | false | also train every stored `Wcs`/`Wss` edge | |
/// | `ridge` | 1e-3 | ridge weight of the least-squares start, per sample, in standardised units | `>= 0` |
/// | `adam_ridge` | true | Adam minimises the loss plus the same ridges, so it stays at the start's optimum for a fixed adjacency instead of fitting noise with the slopes of features that hardly varied (docs/experiments.md, Fig. 7: it stops the log-uniform extrapolation blow-up), and the hall-wide terms stay held (docs/performance.md) | |
/// | `hall_wide_ridge` | 0.03 ([`HALL_WIDE_RIDGE`]) | the ridge on the weights of [hall-wide terms](SurrogateTerm::hall_wide) (the mass-balance terms), in the start and, with `adam_ridge`, in Adam: they explain only what the local blocks cannot (see `docs/performance.md`) | `>= 0` |
/// | `adjacency` | see [`AdjacencySettings`] | how the edges are built | |
///
/// The paper gives lr 0.1 and decay 0.8 but not the decay period; a per-epoch decay would
/// freeze training after about 30 of the 150 epochs, so the step decays every 10 epochs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalGraphSettings {
    /// Adam epochs per fit.
    pub epochs: usize,
    /// Initial learning rate.
    pub learning_rate: f64,
    /// Staircase decay factor.
    pub decay_rate: f64,
    /// Epochs per decay period.
    pub decay_every_epochs: usize,
    /// Train the adjacency edges too.
    pub trainable_adjacency: bool,
    /// Ridge weight of the least-squares initialisation.
    pub ridge: f64,
    /// Keep the ridge in Adam's loss too.
    pub adam_ridge: bool,
    /// Ridge weight on the weights of hall-wide terms (instead of `ridge`).
    pub hall_wide_ridge: f64,
    /// Adjacency construction.
    pub adjacency: AdjacencySettings,
}

impl Default for ThermalGraphSettings {
    fn default() -> Self {
        ThermalGraphSettings {
            epochs: 150,
            learning_rate: 0.1,
            decay_rate: 0.8,
            decay_every_epochs: 10,
            trainable_adjacency: false,
            ridge: 1e-3,
            adam_ridge: true,
            hall_wide_ridge: HALL_WIDE_RIDGE,
            adjacency: AdjacencySettings::default(),
        }
    }
}

impl ThermalGraphSettings {
    /// Sets the number of epochs.
    pub fn with_epochs(mut self, epochs: usize) -> Self {
        self.epochs = epochs;
        self
    }
    /// Sets the initial learning rate.
    pub fn with_learning_rate(mut self, lr: f64) -> Self {
        self.learning_rate = lr;
        self
    }
    /// Sets the decay factor and period.
    pub fn with_decay(mut self, rate: f64, every_epochs: usize) -> Self {
        self.decay_rate = rate;
        self.decay_every_epochs = every_epochs;
        self
    }
    /// Makes the adjacency trainable (or fixed).
    pub fn with_trainable_adjacency(mut self, trainable: bool) -> Self {
        self.trainable_adjacency = trainable;
        self
    }
    /// Sets the ridge weight of the least-squares start.
    pub fn with_ridge(mut self, ridge: f64) -> Self {
        self.ridge = ridge;
        self
    }
    /// Keeps the ridge in Adam's loss (or not).
    pub fn with_adam_ridge(mut self, on: bool) -> Self {
        self.adam_ridge = on;
        self
    }
    /// Sets the ridge on the weights of hall-wide terms.
    pub fn with_hall_wide_ridge(mut self, ridge: f64) -> Self {
        self.hall_wide_ridge = ridge;
        self
    }
    /// Sets the adjacency construction.
    pub fn with_adjacency(mut self, adjacency: AdjacencySettings) -> Self {
        self.adjacency = adjacency;
        self
    }

    /// Validates every setting, naming the first bad one.
    pub fn check(self) -> Result<Self> {
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(setting(
                "learning_rate",
                format!("must be positive, got {}", self.learning_rate),
            ));
        }
        if !(self.decay_rate > 0.0 && self.decay_rate <= 1.0) {
            return Err(setting(
                "decay_rate",
                format!("must lie in (0, 1], got {}", self.decay_rate),
            ));
        }
        if self.decay_every_epochs == 0 {
            return Err(setting("decay_every_epochs", "must be at least 1".into()));
        }
        if !(self.ridge.is_finite() && self.ridge >= 0.0) {
            return Err(setting(
                "ridge",
                format!("must be >= 0, got {}", self.ridge),
            ));
        }
        if !(self.hall_wide_ridge.is_finite() && self.hall_wide_ridge >= 0.0) {
            return Err(setting(
                "hall_wide_ridge",
                format!("must be >= 0, got {}", self.hall_wide_ridge),
            ));
        }
        self.adjacency.check()?;
        Ok(self)
    }
}

/// Trainable weights and the per-fit standardisation of the hidden variables.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Weights {
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub c: Vec<f64>,
    pub d: Vec<f64>,
    /// Term weights, term-major (`e[t * n + k]`).
    pub e: Vec<f64>,
    pub cold_mean: Vec<f64>,
    pub cold_scale: Vec<f64>,
    pub hot_mean: Vec<f64>,
    pub hot_scale: Vec<f64>,
    pub term_mean: Vec<f64>,
    pub term_scale: Vec<f64>,
}

impl Weights {
    /// Before any fit: cold sensors read the CRAC mix (`a = 1`, no centring), no rise.
    pub(crate) fn unfitted(n: usize, terms: usize) -> Self {
        Weights {
            a: vec![1.0; n],
            b: vec![0.0; n],
            c: vec![0.0; n],
            d: vec![0.0; n],
            e: vec![0.0; n * terms],
            cold_mean: vec![0.0; n],
            cold_scale: vec![1.0; n],
            hot_mean: vec![0.0; n],
            hot_scale: vec![1.0; n],
            term_mean: vec![0.0; n * terms],
            term_scale: vec![1.0; n * terms],
        }
    }
}

/// The knowledge-based neural surrogate of the Kalibre paper (see the module docs).
///
/// Parameters are the full hall parameter vector of a [`ParamLayout`]: alpha per type or
/// per server (through [`ParamLayout::alpha_per_server`]); effect parameters reach the
/// output only through additional [`SurrogateTerm`]s.
#[derive(Debug)]
pub struct ThermalGraph {
    pub(crate) layout: ParamLayout,
    pub(crate) hot: Vec<bool>,
    pub(crate) n_cracs: usize,
    pub(crate) n_servers: usize,
    /// The geometric adjacency (the start of every fit).
    pub(crate) geometric: Adjacency,
    /// The adjacency in use (equal to `geometric` unless trained).
    pub(crate) adjacency: Adjacency,
    pub(crate) terms: Vec<Box<dyn SurrogateTerm>>,
    pub(crate) settings: ThermalGraphSettings,
    pub(crate) w: Weights,
    pub(crate) fitted: bool,
}

impl ThermalGraph {
    /// A surrogate for `hall` with the parameter layout `layout` (checked settings).
    pub fn new(hall: &Hall, layout: ParamLayout, settings: ThermalGraphSettings) -> Result<Self> {
        let settings = settings.check()?;
        let adjacency = Adjacency::from_hall(hall, &settings.adjacency)?;
        let n_servers = hall.server_count();
        if layout.alpha_index().len() != n_servers {
            return Err(Error::Mismatch(format!(
                "parameter layout covers {} servers, hall `{}` has {n_servers}",
                layout.alpha_index().len(),
                hall.name
            )));
        }
        let n = hall.sensors.len();
        Ok(ThermalGraph {
            layout,
            hot: hall.sensors.iter().map(|s| s.aisle == Aisle::Hot).collect(),
            n_cracs: hall.cracs.len(),
            n_servers,
            geometric: adjacency.clone(),
            adjacency,
            terms: Vec::new(),
            settings,
            w: Weights::unfitted(n, 0),
            fitted: false,
        })
    }

    /// Replaces the adjacency (the start of every fit) with `adjacency`, for instance
    /// [`Adjacency::with_server_influence`]'s edges from the model's air flow; resets the
    /// fit. Its rows must be the sensors, its columns the hall's CRACs and servers.
    pub fn with_adjacency(mut self, adjacency: Adjacency) -> Result<Self> {
        let n = self.hot.len();
        if adjacency.cs.rows() != n || adjacency.ss.rows() != n {
            return Err(Error::Mismatch(format!(
                "adjacency has {} CRAC and {} server rows, the graph {n} sensors",
                adjacency.cs.rows(),
                adjacency.ss.rows()
            )));
        }
        if adjacency.cs.col.iter().any(|&c| c as usize >= self.n_cracs)
            || adjacency
                .ss
                .col
                .iter()
                .any(|&c| c as usize >= self.n_servers)
        {
            return Err(Error::Mismatch(format!(
                "adjacency names a CRAC or server beyond the hall's {} CRACs and {} servers",
                self.n_cracs, self.n_servers
            )));
        }
        if let Some(k) = (0..n).find(|&k| !self.hot[k] && !adjacency.ss.range(k).is_empty()) {
            return Err(Error::Mismatch(format!(
                "adjacency row {k}: a cold-aisle sensor has server edges (only hot-aisle \
                 sensors have a heating block)"
            )));
        }
        self.geometric = adjacency.clone();
        self.adjacency = adjacency;
        self.w = Weights::unfitted(n, self.terms.len());
        self.fitted = false;
        Ok(self)
    }

    /// Adds an additional linear term (resets the fit).
    pub fn with_term(mut self, term: Box<dyn SurrogateTerm>) -> Self {
        self.terms.push(term);
        self.w = Weights::unfitted(self.hot.len(), self.terms.len());
        self.adjacency = self.geometric.clone();
        self.fitted = false;
        self
    }

    /// The parameter layout.
    pub fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    /// The settings.
    pub fn settings(&self) -> &ThermalGraphSettings {
        &self.settings
    }

    /// The adjacency in use (trained when the adjacency is trainable and the model fitted).
    pub fn adjacency(&self) -> &Adjacency {
        &self.adjacency
    }

    /// Number of sensors (outputs).
    pub fn sensor_count(&self) -> usize {
        self.hot.len()
    }

    /// True for hot-aisle sensors, in hall order.
    pub fn hot_mask(&self) -> &[bool] {
        &self.hot
    }

    /// True once fitted.
    pub fn is_fitted(&self) -> bool {
        self.fitted
    }

    /// Checks a scenario and a parameter vector against the hall and the layout.
    pub fn check_inputs(&self, scenario: &OperatingState, params: &[f64]) -> Result<()> {
        let label = &scenario.label;
        let check = |what: &str, got: usize, want: usize| {
            if got == want {
                Ok(())
            } else {
                Err(Error::Mismatch(format!(
                    "snapshot `{label}`: {got} {what} values for {want} in the hall"
                )))
            }
        };
        check("setpoint_c", scenario.setpoint_c.len(), self.n_cracs)?;
        check("fan_speed", scenario.fan_speed.len(), self.n_cracs)?;
        check("power_w", scenario.power_w.len(), self.n_servers)?;
        if params.len() != self.layout.space().dim() {
            return Err(Error::Mismatch(format!(
                "{} parameter values for a layout of {}",
                params.len(),
                self.layout.space().dim()
            )));
        }
        // Branch-free scans (they vectorise): this runs on every prediction.
        let all_finite = |v: &[f64]| v.iter().fold(true, |ok, x| ok & x.is_finite());
        if !(all_finite(&scenario.setpoint_c)
            && all_finite(&scenario.fan_speed)
            && all_finite(&scenario.power_w))
        {
            return Err(Error::Mismatch(format!(
                "snapshot `{label}`: a non-finite input value"
            )));
        }
        if !all_finite(params) {
            let i = params.iter().position(|v| !v.is_finite()).unwrap_or(0);
            return Err(Error::Mismatch(format!("parameter {i} is not finite")));
        }
        // The layout checked the fixed alphas; the parameters may come from anywhere.
        let alphas = &params[self.layout.alpha_params()];
        if !alphas.iter().fold(true, |ok, a| ok & (*a > 0.0)) {
            let a = alphas
                .iter()
                .find(|a| **a <= 0.0)
                .copied()
                .unwrap_or(f64::NAN);
            return Err(Error::Mismatch(format!("alpha must be positive, got {a}")));
        }
        Ok(())
    }

    /// The hidden variables `(X_cold, X_hot)` per sensor (before the linear layers):
    /// the CRAC mix of setpoints (C) and the distance-weighted `P / alpha` (W per cfm/W,
    /// zero for cold-aisle sensors).
    pub fn hidden(
        &self,
        scenario: &OperatingState,
        params: &[f64],
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        self.check_inputs(scenario, params)?;
        let n = self.hot.len();
        let (mut xc, mut xh) = (vec![0.0; n], vec![0.0; n]);
        self.cold_hidden(&self.adjacency.cs.val, scenario, &mut xc, None);
        let h = self.heat_inputs(scenario, params);
        self.hot_hidden(&self.adjacency.ss.val, &h, &mut xh);
        Ok((xc, xh))
    }

    /// `X_cold` for every sensor with the CRAC weights `cs_val`; also the softmax
    /// coefficients per edge when `soft` is given.
    pub(crate) fn cold_hidden(
        &self,
        cs_val: &[f64],
        s: &OperatingState,
        xc: &mut [f64],
        mut soft: Option<&mut [f64]>,
    ) {
        let cs = &self.adjacency.cs;
        for (k, x) in xc.iter_mut().enumerate() {
            let r = cs.range(k);
            let zmax = r
                .clone()
                .map(|e| s.fan_speed[cs.col[e] as usize] * cs_val[e])
                .fold(f64::NEG_INFINITY, f64::max);
            let mut sum = 0.0;
            let mut acc = 0.0;
            for e in r.clone() {
                let i = cs.col[e] as usize;
                let p = (s.fan_speed[i] * cs_val[e] - zmax).exp();
                sum += p;
                acc += p * s.setpoint_c[i];
                if let Some(soft) = soft.as_deref_mut() {
                    soft[e] = p;
                }
            }
            *x = acc / sum;
            if let Some(soft) = soft.as_deref_mut() {
                for e in r {
                    soft[e] /= sum;
                }
            }
        }
    }

    /// `X_hot` for every sensor (zero for cold-aisle sensors) from `h_j = P_j / alpha_j`.
    pub(crate) fn hot_hidden(&self, ss_val: &[f64], h: &[f64], xh: &mut [f64]) {
        let ss = &self.adjacency.ss;
        for (k, x) in xh.iter_mut().enumerate() {
            *x = ss.range(k).map(|e| ss_val[e] * h[ss.col[e] as usize]).sum();
        }
    }

    /// `P_j / alpha_j` per server.
    pub(crate) fn heat_inputs(&self, s: &OperatingState, params: &[f64]) -> Vec<f64> {
        s.power_w
            .iter()
            .zip(self.layout.alpha_per_server_iter(params))
            .map(|(p, a)| p / a)
            .collect()
    }

    /// Raw term features, term-major.
    pub(crate) fn term_features(&self, s: &OperatingState, params: &[f64]) -> Vec<f64> {
        let n = self.hot.len();
        let mut f = vec![0.0; n * self.terms.len()];
        for (t, term) in self.terms.iter().enumerate() {
            term.features(s, params, &mut f[t * n..(t + 1) * n]);
        }
        f
    }

    /// Outputs from raw hidden variables with weights `w`.
    pub(crate) fn join(&self, w: &Weights, xc: &[f64], xh: &[f64], f: &[f64], out: &mut [f64]) {
        let n = self.hot.len();
        for k in 0..n {
            let mut t = w.a[k] * (xc[k] - w.cold_mean[k]) / w.cold_scale[k] + w.b[k];
            if self.hot[k] {
                t += w.c[k] * (xh[k] - w.hot_mean[k]) / w.hot_scale[k] + w.d[k];
            }
            for tt in 0..self.terms.len() {
                let i = tt * n + k;
                t += w.e[i] * (f[i] - w.term_mean[i]) / w.term_scale[i];
            }
            out[k] = t;
        }
    }
}

impl Surrogate for ThermalGraph {
    type Scenario = OperatingState;

    /// Fits on all samples (least-squares start, then Adam); full-batch training uses no randomness,
    /// so `seed` does not change the result.
    fn fit(
        &mut self,
        data: kalibre_core::TrainingSet<'_, OperatingState>,
        seed: u64,
    ) -> kalibre_core::Result<kalibre_core::FitSummary> {
        self.fit_until(data, seed, None)
    }

    /// [`Self::fit`], with Adam's epochs stopped at `deadline` (the least-squares start
    /// always runs: it is one solve, and the weights Adam would refine).
    fn fit_until(
        &mut self,
        data: kalibre_core::TrainingSet<'_, OperatingState>,
        _seed: u64,
        deadline: Option<std::time::Instant>,
    ) -> kalibre_core::Result<kalibre_core::FitSummary> {
        self.fit_checked(data, deadline).map_err(|e| match e {
            Error::Core(c) => c,
            other => kalibre_core::Error::Fit(other.to_string()),
        })
    }

    /// Predicted sensor temperatures (C). Inputs that [`ThermalGraph::check_inputs`]
    /// rejects give NaN for every sensor, which any loss turns into a visible failure.
    /// Before a fit ([`ThermalGraph::is_fitted`] false) every sensor reads the CRACs'
    /// supply mix with no server rise: the graph's form with nothing learned.
    fn predict(&self, scenario: &OperatingState, params: &[f64]) -> Vec<f64> {
        let n = self.hot.len();
        if self.check_inputs(scenario, params).is_err() {
            return vec![f64::NAN; n];
        }
        let (mut xc, mut xh, mut out) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        self.cold_hidden(&self.adjacency.cs.val, scenario, &mut xc, None);
        let h = self.heat_inputs(scenario, params);
        self.hot_hidden(&self.adjacency.ss.val, &h, &mut xh);
        let f = self.term_features(scenario, params);
        self.join(&self.w, &xc, &xh, &f, &mut out);
        out
    }

    /// Gradient of `sum_k g_k T_k` with respect to the parameters: through alpha
    /// (`d X_hot_k / d alpha_j = -Wss_jk P_j / alpha_j^2`) and through the terms.
    fn vjp(&self, scenario: &OperatingState, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        let dim = self.layout.space().dim();
        let n = self.hot.len();
        if self.check_inputs(scenario, params).is_err() || cotangent.len() != n {
            return vec![f64::NAN; dim];
        }
        let ss = &self.adjacency.ss;
        let alpha = self.layout.alpha_per_server(params);
        let mut g_alpha = vec![0.0; self.n_servers];
        for k in (0..n).filter(|&k| self.hot[k]) {
            let gx = cotangent[k] * self.w.c[k] / self.w.hot_scale[k];
            for e in ss.range(k) {
                g_alpha[ss.col[e] as usize] += gx * ss.val[e];
            }
        }
        for ((g, p), a) in g_alpha.iter_mut().zip(&scenario.power_w).zip(&alpha) {
            *g *= -p / (a * a);
        }
        let mut grad = vec![0.0; dim];
        self.layout.accumulate_alpha_gradient(&g_alpha, &mut grad);
        let mut ct = vec![0.0; n];
        for (t, term) in self.terms.iter().enumerate() {
            for k in 0..n {
                let i = t * n + k;
                ct[k] = cotangent[k] * self.w.e[i] / self.w.term_scale[i];
            }
            term.features_vjp(scenario, params, &ct, &mut grad);
        }
        grad
    }
}
