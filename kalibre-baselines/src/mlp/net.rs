//! A fully connected network on ndarray with hand-written forward and backward passes.
//!
//! Layer `l` computes `z_l = a_{l-1} W_l^T + b_l` over a batch (rows are samples); hidden
//! layers apply the activation, the output layer is linear. The backward pass returns the
//! gradients of a loss with respect to every weight and to the inputs, given the loss's
//! gradient with respect to the outputs.

use ndarray::{Array1, Array2, ArrayView2, Axis};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// The hidden layers' activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// `tanh`: smooth, so the input gradient the searcher follows is continuous and the
    /// finite-difference checks are clean.
    #[default]
    Tanh,
    /// `max(0, x)`.
    Relu,
}

impl Activation {
    fn apply(self, z: f64) -> f64 {
        match self {
            Activation::Tanh => z.tanh(),
            Activation::Relu => z.max(0.0),
        }
    }
    /// Derivative from the activation's output `a` (both have closed forms in `a`).
    fn derivative_from_output(self, a: f64) -> f64 {
        match self {
            Activation::Tanh => 1.0 - a * a,
            Activation::Relu => f64::from(u8::from(a > 0.0)),
        }
    }
}

/// One dense layer: `weight` is `(outputs, inputs)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    /// Weights, `(outputs, inputs)`.
    pub weight: Array2<f64>,
    /// Biases, one per output.
    pub bias: Array1<f64>,
}

/// Gradients of a loss, one entry per layer (same shapes as the layers).
pub type Gradients = Vec<Dense>;

/// A fully connected network.
#[derive(Debug, Clone, PartialEq)]
pub struct Network {
    layers: Vec<Dense>,
    activation: Activation,
}

/// What the forward pass keeps for the backward pass: every layer's output.
#[derive(Debug, Clone)]
pub struct Tape {
    /// `a_0` (the inputs), `a_1`, ... `a_L` (the outputs).
    pub activations: Vec<Array2<f64>>,
}

impl Tape {
    /// The network's outputs, `(samples, outputs)`.
    pub fn outputs(&self) -> &Array2<f64> {
        self.activations
            .last()
            .expect("a tape has the inputs at least")
    }
}

impl Network {
    /// A network with layer widths `sizes` (inputs first, outputs last), weights drawn
    /// from `N(0, 1 / fan_in)` (LeCun; He `2 / fan_in` for ReLU) and zero biases.
    pub fn new(sizes: &[usize], activation: Activation, rng: &mut impl Rng) -> Self {
        let gain = match activation {
            Activation::Tanh => 1.0,
            Activation::Relu => 2.0,
        };
        let layers = sizes
            .windows(2)
            .map(|w| {
                let std = (gain / w[0].max(1) as f64).sqrt();
                Dense {
                    weight: Array2::from_shape_simple_fn((w[1], w[0]), || {
                        std * rng.sample::<f64, _>(StandardNormal)
                    }),
                    bias: Array1::zeros(w[1]),
                }
            })
            .collect();
        Network { layers, activation }
    }

    /// The layers.
    pub fn layers(&self) -> &[Dense] {
        &self.layers
    }

    /// The activation of the hidden layers.
    pub fn activation(&self) -> Activation {
        self.activation
    }

    /// Number of inputs.
    pub fn inputs(&self) -> usize {
        self.layers.first().map_or(0, |l| l.weight.ncols())
    }

    /// Number of outputs.
    pub fn outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.weight.nrows())
    }

    /// Number of weights and biases.
    pub fn parameter_count(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.weight.len() + l.bias.len())
            .sum()
    }

    /// Every weight and bias in one vector (layer by layer, weights row-major, then biases).
    pub fn to_flat(&self) -> Vec<f64> {
        flatten(&self.layers)
    }

    /// Sets every weight and bias from a vector in [`Self::to_flat`] order.
    pub fn set_flat(&mut self, flat: &[f64]) {
        let mut i = 0;
        for l in &mut self.layers {
            for w in l.weight.iter_mut().chain(l.bias.iter_mut()) {
                *w = flat[i];
                i += 1;
            }
        }
    }

    /// Forward pass over a batch `(samples, inputs)`.
    pub fn forward(&self, x: ArrayView2<'_, f64>) -> Tape {
        let mut activations = Vec::with_capacity(self.layers.len() + 1);
        activations.push(x.to_owned());
        let last = self.layers.len().saturating_sub(1);
        for (i, l) in self.layers.iter().enumerate() {
            let prev = activations.last().expect("inputs pushed first");
            let mut z = prev.dot(&l.weight.t());
            z += &l.bias;
            if i < last {
                let act = self.activation;
                z.mapv_inplace(|v| act.apply(v));
            }
            activations.push(z);
        }
        Tape { activations }
    }

    /// Backward pass: from `d loss / d outputs` (`(samples, outputs)`) to the gradients
    /// with respect to every layer and to the inputs (`(samples, inputs)`).
    pub fn backward(&self, tape: &Tape, grad_out: Array2<f64>) -> (Gradients, Array2<f64>) {
        let n = self.layers.len();
        let mut grads: Vec<Dense> = Vec::with_capacity(n);
        let mut delta = grad_out;
        for i in (0..n).rev() {
            let l = &self.layers[i];
            if i < n - 1 {
                // Through the hidden activation of layer i (its output is activations[i + 1]).
                let act = self.activation;
                delta.zip_mut_with(&tape.activations[i + 1], |d, &a| {
                    *d *= act.derivative_from_output(a)
                });
            }
            let a_prev = &tape.activations[i];
            grads.push(Dense {
                weight: delta.t().dot(a_prev),
                bias: delta.sum_axis(Axis(0)),
            });
            delta = delta.dot(&l.weight);
        }
        grads.reverse();
        (grads, delta)
    }
}

/// Flattens layers (or gradients) in [`Network::to_flat`] order.
pub fn flatten(layers: &[Dense]) -> Vec<f64> {
    layers
        .iter()
        .flat_map(|l| l.weight.iter().chain(l.bias.iter()).copied())
        .collect()
}

/// Adam moments per layer, for training the weights.
pub(crate) struct AdamState {
    m: Vec<Dense>,
    v: Vec<Dense>,
    t: i32,
}

impl AdamState {
    pub(crate) fn new(net: &Network) -> Self {
        let zeros = |l: &Dense| Dense {
            weight: Array2::zeros(l.weight.raw_dim()),
            bias: Array1::zeros(l.bias.len()),
        };
        AdamState {
            m: net.layers.iter().map(zeros).collect(),
            v: net.layers.iter().map(zeros).collect(),
            t: 0,
        }
    }

    /// One Adam step (beta1 0.9, beta2 0.999, epsilon 1e-8) at learning rate `lr`.
    pub(crate) fn step(&mut self, net: &mut Network, grads: &[Dense], lr: f64) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        let upd = |w: &mut f64, m: &mut f64, v: &mut f64, g: f64| {
            *m = B1 * *m + (1.0 - B1) * g;
            *v = B2 * *v + (1.0 - B2) * g * g;
            *w -= lr * (*m / c1) / ((*v / c2).sqrt() + 1e-8);
        };
        for (((l, g), m), v) in net
            .layers
            .iter_mut()
            .zip(grads)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            ndarray::Zip::from(&mut l.weight)
                .and(&g.weight)
                .and(&mut m.weight)
                .and(&mut v.weight)
                .for_each(|w, &g, m, v| upd(w, m, v, g));
            ndarray::Zip::from(&mut l.bias)
                .and(&g.bias)
                .and(&mut m.bias)
                .and(&mut v.bias)
                .for_each(|w, &g, m, v| upd(w, m, v, g));
        }
    }
}
