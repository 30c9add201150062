//! The paper's "vanilla" neural surrogate: a fully connected network from a hall's
//! operating state and alpha to every sensor, knowing nothing of the hall's physics.
//!
//! Inputs, in order: supply setpoint and fan speed per CRAC, power per server, alpha per
//! server (expanded from per-type parameters through the hall's [`ParamLayout`]), then
//! any effect parameters; or, with [`InputLevel::Rack`], power and mean alpha per rack. The input layer's width is therefore the hall's (the paper's
//! 518 on its hall A); the default hidden layers are the paper's 128 and 32 neurons,
//! followed by a linear output per sensor. Inputs and outputs are standardised over the
//! training samples (a constant feature keeps scale 1); training is mini-batch Adam on
//! the weighted mean squared error, with seeded initialisation and shuffling, keeping the
//! weights of the epoch with the lowest full-batch loss.

mod net;

pub use net::{flatten, Activation, Dense, Gradients, Network, Tape};

use kalibre_core::{FitSummary, Surrogate, TrainingSet};
use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::ParamLayout;
use ndarray::{Array2, Axis};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::error::require;
use crate::Result;
use net::AdamState;

/// At which level power and alpha enter the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InputLevel {
    /// Power and alpha of every server (two inputs per server).
    #[default]
    Server,
    /// Total power of every rack and its power-weighted mean alpha (the rack's air flow
    /// per watt; the plain mean for a rack without power): two inputs per rack. On a
    /// hall of thousands of servers this keeps the input layer at the paper's size
    /// (518 inputs for its hall A) and the fit affordable.
    Rack,
}

/// Settings of the [`Mlp`], checked by [`MlpSettings::check`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `inputs` | per server | power and alpha per server, or per rack (see [`InputLevel`]) | server, rack |
/// | `hidden` | [128, 32] | widths of the hidden layers (the paper's 518-128-32 with the hall's inputs) | each >= 1 |
/// | `activation` | tanh | activation of the hidden layers | tanh, relu |
/// | `epochs` | 300 | passes over the training samples per fit | >= 1 |
/// | `batch_size` | 32 | samples per Adam step | >= 1 |
/// | `learning_rate` | 0.005 | initial Adam learning rate (standardised units) | > 0 |
/// | `decay` | 0.8 | learning-rate factor per `decay_every` epochs | (0, 1] |
/// | `decay_every` | 30 | epochs per decay factor | >= 1 |
#[derive(Debug, Clone, PartialEq)]
pub struct MlpSettings {
    /// Power and alpha per server or per rack.
    pub inputs: InputLevel,
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// Epochs per fit.
    pub epochs: usize,
    /// Samples per step.
    pub batch_size: usize,
    /// Initial learning rate.
    pub learning_rate: f64,
    /// Learning-rate factor per `decay_every` epochs.
    pub decay: f64,
    /// Epochs per decay factor.
    pub decay_every: usize,
}

impl Default for MlpSettings {
    fn default() -> Self {
        MlpSettings {
            inputs: InputLevel::Server,
            hidden: vec![128, 32],
            activation: Activation::Tanh,
            epochs: 300,
            batch_size: 32,
            learning_rate: 0.005,
            decay: 0.8,
            decay_every: 30,
        }
    }
}

impl MlpSettings {
    /// Power and alpha per server or per rack.
    pub fn with_inputs(mut self, inputs: InputLevel) -> Self {
        self.inputs = inputs;
        self
    }
    /// Hidden layer widths.
    pub fn with_hidden(mut self, hidden: Vec<usize>) -> Self {
        self.hidden = hidden;
        self
    }
    /// Hidden activation.
    pub fn with_activation(mut self, activation: Activation) -> Self {
        self.activation = activation;
        self
    }
    /// Epochs per fit.
    pub fn with_epochs(mut self, epochs: usize) -> Self {
        self.epochs = epochs;
        self
    }
    /// Samples per Adam step.
    pub fn with_batch_size(mut self, batch_size: usize) -> Self {
        self.batch_size = batch_size;
        self
    }
    /// Initial learning rate.
    pub fn with_learning_rate(mut self, learning_rate: f64) -> Self {
        self.learning_rate = learning_rate;
        self
    }

    /// Checks every setting, naming the first one out of range.
    pub fn check(&self) -> Result<()> {
        require(self.hidden.iter().all(|&w| w >= 1), "hidden", || {
            format!("every width must be at least 1, got {:?}", self.hidden)
        })?;
        require(self.epochs >= 1, "epochs", || "must be at least 1".into())?;
        require(self.batch_size >= 1, "batch_size", || {
            "must be at least 1".into()
        })?;
        require(
            self.learning_rate.is_finite() && self.learning_rate > 0.0,
            "learning_rate",
            || format!("must be finite and > 0, got {}", self.learning_rate),
        )?;
        require(self.decay > 0.0 && self.decay <= 1.0, "decay", || {
            format!("must be in (0, 1], got {}", self.decay)
        })?;
        require(self.decay_every >= 1, "decay_every", || {
            "must be at least 1".into()
        })
    }
}

/// Per-feature standardisation `(x - mean) / scale`.
#[derive(Debug, Clone, PartialEq)]
struct Scaler {
    mean: Vec<f64>,
    scale: Vec<f64>,
}

impl Scaler {
    fn fit(x: &Array2<f64>) -> Self {
        let n = x.nrows().max(1) as f64;
        let mean: Vec<f64> = x.sum_axis(Axis(0)).iter().map(|s| s / n).collect();
        let scale = x
            .axis_iter(Axis(1))
            .zip(&mean)
            .map(|(col, m)| {
                let sd = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt();
                // A feature constant over the samples keeps unit scale.
                if sd > 1e-9 * (1.0 + m.abs()) {
                    sd
                } else {
                    1.0
                }
            })
            .collect();
        Scaler { mean, scale }
    }
}

/// A fitted network with its scalers.
#[derive(Debug, Clone, PartialEq)]
struct Fitted {
    net: Network,
    x: Scaler,
    y: Scaler,
}

/// The vanilla MLP surrogate of a hall; a [`kalibre_core::Surrogate`] over the hall's
/// [`ParamLayout`]. Before the first fit it predicts NaN.
#[derive(Debug, Clone)]
pub struct Mlp {
    settings: MlpSettings,
    layout: ParamLayout,
    n_cracs: usize,
    n_servers: usize,
    n_sensors: usize,
    /// Server index range of every rack (servers are in rack order).
    racks: Vec<std::ops::Range<usize>>,
    /// Parameter indices that are not alpha (effect parameters), fed to the net as is.
    extra_params: Vec<usize>,
    fitted: Option<Fitted>,
}

impl Mlp {
    /// An unfitted MLP for `hall` with parameters laid out by `layout`.
    pub fn new(hall: &Hall, layout: ParamLayout, settings: MlpSettings) -> Result<Self> {
        settings.check()?;
        let n_servers = hall.server_count();
        if layout.alpha_index().len() != n_servers {
            return Err(crate::Error::Mismatch(format!(
                "parameter layout has {} servers, hall `{}` has {n_servers}",
                layout.alpha_index().len(),
                hall.name
            )));
        }
        let dim = layout.space().dim();
        let extra_params = (0..dim)
            .filter(|i| !layout.alpha_index().contains(&Some(*i)))
            .collect();
        Ok(Mlp {
            settings,
            layout,
            n_cracs: hall.cracs.len(),
            n_servers,
            n_sensors: hall.sensors.len(),
            racks: {
                let mut start = 0;
                hall.racks
                    .iter()
                    .map(|r| {
                        start += r.servers.len();
                        start - r.servers.len()..start
                    })
                    .collect()
            },
            extra_params,
            fitted: None,
        })
    }

    /// Number of network inputs for this hall.
    pub fn input_count(&self) -> usize {
        2 * self.n_cracs + 2 * self.units() + self.extra_params.len()
    }

    /// Number of power (and alpha) inputs: servers or racks.
    fn units(&self) -> usize {
        match self.settings.inputs {
            InputLevel::Server => self.n_servers,
            InputLevel::Rack => self.racks.len(),
        }
    }

    /// Per rack: the servers' weights in its mean alpha (power shares, or equal shares
    /// for a rack without power), `[server]`.
    fn rack_shares(&self, power_w: &[f64]) -> Vec<f64> {
        let mut w = vec![0.0; self.n_servers];
        for r in &self.racks {
            let total: f64 = power_w[r.clone()].iter().sum();
            for j in r.clone() {
                w[j] = if total > 0.0 {
                    power_w[j] / total
                } else {
                    1.0 / r.len() as f64
                };
            }
        }
        w
    }

    /// The fitted network (`None` before the first fit).
    pub fn network(&self) -> Option<&Network> {
        self.fitted.as_ref().map(|f| &f.net)
    }

    /// The settings.
    pub fn settings(&self) -> &MlpSettings {
        &self.settings
    }

    /// Raw input features; `None` when the lengths do not fit the hall.
    pub fn features(&self, s: &OperatingState, params: &[f64]) -> Option<Vec<f64>> {
        if s.setpoint_c.len() != self.n_cracs
            || s.fan_speed.len() != self.n_cracs
            || s.power_w.len() != self.n_servers
            || params.len() != self.layout.space().dim()
        {
            return None;
        }
        let mut f = Vec::with_capacity(self.input_count());
        f.extend_from_slice(&s.setpoint_c);
        f.extend_from_slice(&s.fan_speed);
        let alpha = self.layout.alpha_per_server(params);
        match self.settings.inputs {
            InputLevel::Server => {
                f.extend_from_slice(&s.power_w);
                f.extend(alpha);
            }
            InputLevel::Rack => {
                let share = self.rack_shares(&s.power_w);
                f.extend(
                    self.racks
                        .iter()
                        .map(|r| s.power_w[r.clone()].iter().sum::<f64>()),
                );
                f.extend(
                    self.racks
                        .iter()
                        .map(|r| r.clone().map(|j| share[j] * alpha[j]).sum::<f64>()),
                );
            }
        }
        f.extend(self.extra_params.iter().map(|&i| params[i]));
        Some(f)
    }

    fn standardised_row(&self, fit: &Fitted, s: &OperatingState, p: &[f64]) -> Option<Array2<f64>> {
        let f = self.features(s, p)?;
        let row: Vec<f64> = f
            .iter()
            .zip(fit.x.mean.iter().zip(&fit.x.scale))
            .map(|(v, (m, sc))| (v - m) / sc)
            .collect();
        Array2::from_shape_vec((1, row.len()), row).ok()
    }

    fn fit_checked(
        &mut self,
        data: TrainingSet<'_, OperatingState>,
        seed: u64,
        deadline: Option<std::time::Instant>,
    ) -> Result<FitSummary> {
        let fail = |m: String| crate::Error::Core(kalibre_core::Error::Fit(m));
        let n = data.samples.len();
        if n == 0 {
            return Err(fail("the MLP has no training sample".into()));
        }
        let d_in = self.input_count();
        let mut x = Array2::zeros((n, d_in));
        let mut y = Array2::zeros((n, self.n_sensors));
        let mut w = Vec::with_capacity(n);
        for (i, s) in data.samples.iter().enumerate() {
            let scen = data.scenarios.get(s.snapshot).ok_or_else(|| {
                fail(format!(
                    "sample {i} refers to missing snapshot {}",
                    s.snapshot
                ))
            })?;
            let f = self.features(scen, &s.params).ok_or_else(|| {
                fail(format!(
                    "sample {i}: {} parameters or snapshot `{}` do not fit the hall",
                    s.params.len(),
                    scen.label
                ))
            })?;
            if s.outputs.len() != self.n_sensors {
                return Err(fail(format!(
                    "sample {i} has {} outputs for {} sensors",
                    s.outputs.len(),
                    self.n_sensors
                )));
            }
            if f.iter().chain(&s.outputs).any(|v| !v.is_finite())
                || !(s.weight.is_finite() && s.weight >= 0.0)
            {
                return Err(fail(format!("sample {i} has a non-finite value or weight")));
            }
            x.row_mut(i).assign(&ndarray::ArrayView1::from(&f[..]));
            y.row_mut(i)
                .assign(&ndarray::ArrayView1::from(&s.outputs[..]));
            w.push(s.weight);
        }
        let w_mean = w.iter().sum::<f64>() / n as f64;
        if w_mean <= 0.0 {
            return Err(fail("every sample weight is zero".into()));
        }
        let w: Vec<f64> = w.iter().map(|v| v / w_mean).collect();
        let (xs, ys) = (Scaler::fit(&x), Scaler::fit(&y));
        standardise(&mut x, &xs);
        standardise(&mut y, &ys);

        let st = &self.settings;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut sizes = vec![d_in];
        sizes.extend(&st.hidden);
        sizes.push(self.n_sensors);
        let net = Network::new(&sizes, st.activation, &mut rng);
        // On a pool thread, the products' and Adam's rayon splits are cheap pushes to the
        // local queue instead of a hand-over from an outside thread per call.
        let best = rayon::scope(|_| train(net, &x, &y, &w, st, &mut rng, deadline));
        if !best.0.is_finite() {
            return Err(fail(format!("training loss is not finite ({})", best.0)));
        }
        let net = best.1;
        // Train MSE in the outputs' own units (C^2), unweighted.
        let pred = net.predict(x.view());
        let mut se = 0.0;
        for (r, t) in pred.rows().into_iter().zip(y.rows()) {
            for ((p, t), sc) in r.iter().zip(t).zip(&ys.scale) {
                se += ((p - t) * sc).powi(2);
            }
        }
        self.fitted = Some(Fitted { net, x: xs, y: ys });
        Ok(FitSummary {
            train_mse: se / (n * self.n_sensors) as f64,
            epochs: best.2,
            timed_out: best.2 < st.epochs,
        })
    }
}

/// Mini-batch Adam from `net` over the rows of `x`; the lowest full-batch loss and its
/// weights.
fn train(
    mut net: Network,
    x: &Array2<f64>,
    y: &Array2<f64>,
    w: &[f64],
    st: &MlpSettings,
    rng: &mut Xoshiro256PlusPlus,
    deadline: Option<std::time::Instant>,
) -> (f64, Network, usize) {
    let mut adam = AdamState::new(&net);
    let mut order: Vec<usize> = (0..x.nrows()).collect();
    let mut best = (epoch_loss(&net, x, y, w, &order), net.clone());
    for epoch in 0..st.epochs {
        if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
            return (best.0, best.1, epoch);
        }
        let lr = st.learning_rate * st.decay.powf((epoch / st.decay_every) as f64);
        order.shuffle(rng);
        for batch in order.chunks(st.batch_size) {
            let (_, grads) = loss_and_gradients(&net, x, y, w, batch);
            adam.step(&mut net, &grads, lr);
        }
        let loss = epoch_loss(&net, x, y, w, &order);
        if loss < best.0 {
            best = (loss, net.clone());
        }
    }
    (best.0, best.1, st.epochs)
}

fn standardise(a: &mut Array2<f64>, s: &Scaler) {
    for mut row in a.rows_mut() {
        for ((v, m), sc) in row.iter_mut().zip(&s.mean).zip(&s.scale) {
            *v = (*v - m) / sc;
        }
    }
}

/// Weighted mean squared error over the rows `idx` and its gradient with respect to the
/// outputs: `L = sum_i w_i |f(x_i) - y_i|^2 / (sum_i w_i * outputs)`.
fn weighted_mse(
    net: &Network,
    x: &Array2<f64>,
    y: &Array2<f64>,
    w: &[f64],
    idx: &[usize],
) -> (f64, Array2<f64>, Tape) {
    let yb = y.select(Axis(0), idx);
    let tape = net.forward_owned(x.select(Axis(0), idx));
    let denom = loss_denominator(w, idx, y.ncols());
    let mut diff = tape.outputs() - &yb;
    let mut loss = 0.0;
    for (mut r, &i) in diff.rows_mut().into_iter().zip(idx) {
        loss += w[i] * r.iter().map(|d| d * d).sum::<f64>();
        r.mapv_inplace(|d| 2.0 * w[i] * d / denom);
    }
    (loss / denom, diff, tape)
}

/// The weighted MSE's denominator over the rows `idx`: their total weight times the
/// outputs per row (kept positive so that all-zero weights give a zero loss, not NaN).
fn loss_denominator(w: &[f64], idx: &[usize], outputs: usize) -> f64 {
    let wsum: f64 = idx.iter().map(|&i| w[i]).sum();
    wsum.max(f64::MIN_POSITIVE) * outputs as f64
}

/// The training loss on the rows `idx` (standardised inputs and outputs) and its
/// gradients with respect to every weight.
pub fn loss_and_gradients(
    net: &Network,
    x: &Array2<f64>,
    y: &Array2<f64>,
    w: &[f64],
    idx: &[usize],
) -> (f64, Gradients) {
    let (loss, grad_out, tape) = weighted_mse(net, x, y, w, idx);
    (loss, net.backward_weights(&tape, grad_out))
}

/// The loss of [`weighted_mse`] alone over every row, summed in the order `idx` (a
/// permutation of the rows): the forward pass runs on `x` as it is, since a row's
/// outputs do not depend on its place in the batch.
fn epoch_loss(net: &Network, x: &Array2<f64>, y: &Array2<f64>, w: &[f64], idx: &[usize]) -> f64 {
    let out = net.predict(x.view());
    let denom = loss_denominator(w, idx, y.ncols());
    let mut loss = 0.0;
    for &i in idx {
        let se = out
            .row(i)
            .iter()
            .zip(y.row(i))
            .map(|(p, t)| (p - t) * (p - t))
            .sum::<f64>();
        loss += w[i] * se;
    }
    loss / denom
}

impl Surrogate for Mlp {
    type Scenario = OperatingState;

    fn fit(
        &mut self,
        data: TrainingSet<'_, OperatingState>,
        seed: u64,
    ) -> kalibre_core::Result<FitSummary> {
        self.fit_until(data, seed, None)
    }

    fn fit_until(
        &mut self,
        data: TrainingSet<'_, OperatingState>,
        seed: u64,
        deadline: Option<std::time::Instant>,
    ) -> kalibre_core::Result<FitSummary> {
        self.fit_checked(data, seed, deadline).map_err(|e| match e {
            crate::Error::Core(c) => c,
            other => kalibre_core::Error::Fit(other.to_string()),
        })
    }

    /// Predicted sensor temperatures (C); NaN for every sensor before the first fit or
    /// when the inputs do not fit the hall.
    fn predict(&self, scenario: &OperatingState, params: &[f64]) -> Vec<f64> {
        let nan = vec![f64::NAN; self.n_sensors];
        let Some(fit) = &self.fitted else { return nan };
        let Some(row) = self.standardised_row(fit, scenario, params) else {
            return nan;
        };
        fit.net
            .predict(row.view())
            .iter()
            .zip(fit.y.mean.iter().zip(&fit.y.scale))
            .map(|(v, (m, sc))| v * sc + m)
            .collect()
    }

    /// `d(sum_k g_k T_k) / d params` by backpropagation to the inputs, then through the
    /// input standardisation and the per-server alpha expansion.
    fn vjp(&self, scenario: &OperatingState, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        let dim = self.layout.space().dim();
        let nan = vec![f64::NAN; dim];
        let Some(fit) = &self.fitted else { return nan };
        let Some(row) = self.standardised_row(fit, scenario, params) else {
            return nan;
        };
        if cotangent.len() != self.n_sensors {
            return nan;
        }
        let tape = fit.net.forward_owned(row);
        let g: Vec<f64> = cotangent
            .iter()
            .zip(&fit.y.scale)
            .map(|(g, s)| g * s)
            .collect();
        let g = Array2::from_shape_vec((1, g.len()), g).expect("one row of outputs");
        let dx = fit.net.input_gradient(&tape, g);
        let dx: Vec<f64> = dx.iter().zip(&fit.x.scale).map(|(d, s)| d / s).collect();
        let mut grad = vec![0.0; dim];
        let units = self.units();
        let alpha0 = 2 * self.n_cracs + units;
        let d_alpha = &dx[alpha0..alpha0 + units];
        let per_server: Vec<f64> = match self.settings.inputs {
            InputLevel::Server => d_alpha.to_vec(),
            InputLevel::Rack => {
                let mut g = self.rack_shares(&scenario.power_w);
                for (r, d) in self.racks.iter().zip(d_alpha) {
                    g[r.clone()].iter_mut().for_each(|v| *v *= d);
                }
                g
            }
        };
        self.layout
            .accumulate_alpha_gradient(&per_server, &mut grad);
        for (k, &i) in self.extra_params.iter().enumerate() {
            grad[i] += dx[alpha0 + units + k];
        }
        grad
    }
}
