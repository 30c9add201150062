//! A fully connected network on ndarray with hand-written forward and backward passes.
//!
//! Layer `l` computes `z_l = a_{l-1} W_l^T + b_l` over a batch (rows are samples); hidden
//! layers apply the activation, the output layer is linear. The backward pass returns the
//! gradients of a loss with respect to every weight and to the inputs, given the loss's
//! gradient with respect to the outputs.
//!
//! Large products are split over rayon by output columns ([`dot_into`]): every output
//! element is the same dot product in the same order as in one `dot`, so results are
//! bitwise the same at any thread count.

use ndarray::linalg::general_mat_mul;
use ndarray::{Array1, Array2, ArrayView1, ArrayView2, ArrayViewMut1, ArrayViewMut2, Axis};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
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
    ///
    /// # Panics
    /// When `flat` is shorter than [`Self::to_flat`]'s vector.
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
    ///
    /// # Panics
    /// When the batch's width is not the network's input width (as ndarray's product
    /// does; [`crate::Mlp`] checks its inputs before it gets here).
    pub fn forward(&self, x: ArrayView2<'_, f64>) -> Tape {
        self.forward_owned(x.to_owned())
    }

    /// [`Self::forward`] on a batch the tape may keep (no copy of the inputs).
    pub fn forward_owned(&self, x: Array2<f64>) -> Tape {
        let mut activations = Vec::with_capacity(self.layers.len() + 1);
        activations.push(x);
        for i in 0..self.layers.len() {
            let prev = activations.last().expect("inputs pushed first");
            let z = self.layer(i, prev.view());
            activations.push(z);
        }
        Tape { activations }
    }

    /// The outputs alone, `(samples, outputs)`: [`Self::forward`] without keeping the
    /// hidden layers (bitwise the same values).
    ///
    /// # Panics
    /// As [`Self::forward`].
    pub fn predict(&self, x: ArrayView2<'_, f64>) -> Array2<f64> {
        let mut a: Option<Array2<f64>> = None;
        for i in 0..self.layers.len() {
            let z = self.layer(i, a.as_ref().map_or(x.view(), |a| a.view()));
            a = Some(z);
        }
        a.unwrap_or_else(|| x.to_owned())
    }

    /// Layer `i` on the previous layer's output: `act(prev W^T + b)` (linear for the last).
    fn layer(&self, i: usize, prev: ArrayView2<'_, f64>) -> Array2<f64> {
        let l = &self.layers[i];
        let mut z = Array2::zeros((prev.nrows(), l.weight.nrows()));
        dot_into(prev, l.weight.t(), z.view_mut());
        z += &l.bias;
        if i + 1 < self.layers.len() {
            let act = self.activation;
            let apply = |c: &mut [f64]| c.iter_mut().for_each(|v| *v = act.apply(*v));
            // `tanh` is a good share of a fit; element by element, so split freely.
            match z.as_slice_mut() {
                Some(s) if s.len() >= 2 * ACT_CHUNK => s.par_chunks_mut(ACT_CHUNK).for_each(apply),
                Some(s) => apply(s),
                None => z.mapv_inplace(|v| act.apply(v)),
            }
        }
        z
    }

    /// Backward pass: from `d loss / d outputs` (`(samples, outputs)`) to the gradients
    /// with respect to every layer and to the inputs (`(samples, inputs)`).
    ///
    /// # Panics
    /// When `grad_out` is not `(samples, outputs)` of the tape's batch.
    pub fn backward(&self, tape: &Tape, grad_out: Array2<f64>) -> (Gradients, Array2<f64>) {
        let (grads, dx) = self.backward_parts(tape, grad_out, true, true);
        (grads, dx.expect("input gradient asked for"))
    }

    /// [`Self::backward`] without the input gradient (what training needs; it saves the
    /// first layer's largest product).
    pub fn backward_weights(&self, tape: &Tape, grad_out: Array2<f64>) -> Gradients {
        self.backward_parts(tape, grad_out, true, false).0
    }

    /// [`Self::backward`] without the weight gradients: `d loss / d inputs` alone (what a
    /// vector-Jacobian product needs).
    pub fn input_gradient(&self, tape: &Tape, grad_out: Array2<f64>) -> Array2<f64> {
        self.backward_parts(tape, grad_out, false, true)
            .1
            .expect("input gradient asked for")
    }

    fn backward_parts(
        &self,
        tape: &Tape,
        grad_out: Array2<f64>,
        weights: bool,
        inputs: bool,
    ) -> (Gradients, Option<Array2<f64>>) {
        let n = self.layers.len();
        let mut grads: Vec<Dense> = Vec::with_capacity(if weights { n } else { 0 });
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
            if weights {
                let a_prev = &tape.activations[i];
                let mut gw = Array2::zeros(l.weight.raw_dim());
                dot_into(delta.t(), a_prev.view(), gw.view_mut());
                grads.push(Dense {
                    weight: gw,
                    bias: delta.sum_axis(Axis(0)),
                });
            }
            if i > 0 || inputs {
                let mut next = Array2::zeros((delta.nrows(), l.weight.ncols()));
                dot_into(delta.view(), l.weight.view(), next.view_mut());
                delta = next;
            }
        }
        grads.reverse();
        (grads, inputs.then_some(delta))
    }
}

/// Activations per rayon task (a batch's stay on one thread, a full-batch pass splits).
const ACT_CHUNK: usize = 8192;

/// Multiply-adds per rayon task at least: a training batch's products stay on one thread
/// (measured on 2 busy cores, their hand-offs cost more than they saved), a full-batch
/// pass over a few hundred samples splits. Each part also repacks `a`.
const PAR_MIN_WORK: usize = 1 << 22;

/// `c = a b`, split by `b`'s (and `c`'s) columns into one part per rayon thread while
/// each part stays large. Each element of `c` is computed exactly as by `a.dot(&b)`, so
/// the split (and the thread count) does not change a bit of the result.
pub fn dot_into(a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>, c: ArrayViewMut2<'_, f64>) {
    let work = a.nrows() * a.ncols() * b.ncols();
    let parts = rayon::current_num_threads()
        .min(work / PAR_MIN_WORK)
        .min(b.ncols() / 8)
        .max(1);
    dot_parts(a, b, c, parts);
}

fn dot_parts(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    c: ArrayViewMut2<'_, f64>,
    parts: usize,
) {
    if parts <= 1 {
        let mut c = c;
        general_mat_mul(1.0, &a, &b, 0.0, &mut c);
        return;
    }
    let left = parts / 2;
    let mid = b.ncols() * left / parts;
    let (b1, b2) = b.split_at(Axis(1), mid);
    let (c1, c2) = c.split_at(Axis(1), mid);
    rayon::join(
        || dot_parts(a, b1, c1, left),
        || dot_parts(a, b2, c2, parts - left),
    );
}

/// Flattens layers (or gradients) in [`Network::to_flat`] order.
pub fn flatten(layers: &[Dense]) -> Vec<f64> {
    layers
        .iter()
        .flat_map(|l| l.weight.iter().chain(l.bias.iter()).copied())
        .collect()
}

/// Parameters per rayon task in an Adam step.
const ADAM_CHUNK: usize = 1 << 15;

/// The elements of a weight matrix (every one here is built in standard layout).
fn slice_mut(a: &mut Array2<f64>) -> &mut [f64] {
    a.as_slice_mut().expect("weights are in standard layout")
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
        // Element by element, so chunks may run on any thread in any order.
        let step = |w: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64]| {
            w.par_chunks_mut(ADAM_CHUNK)
                .zip(g.par_chunks(ADAM_CHUNK))
                .zip(m.par_chunks_mut(ADAM_CHUNK))
                .zip(v.par_chunks_mut(ADAM_CHUNK))
                .for_each(|(((w, g), m), v)| {
                    ndarray::Zip::from(ArrayViewMut1::from(w))
                        .and(ArrayView1::from(g))
                        .and(ArrayViewMut1::from(m))
                        .and(ArrayViewMut1::from(v))
                        .for_each(|w, &g, m, v| upd(w, m, v, g));
                });
        };
        for (((l, g), m), v) in net
            .layers
            .iter_mut()
            .zip(grads)
            .zip(&mut self.m)
            .zip(&mut self.v)
        {
            step(
                slice_mut(&mut l.weight),
                g.weight
                    .as_slice()
                    .expect("gradients are in standard layout"),
                slice_mut(&mut m.weight),
                slice_mut(&mut v.weight),
            );
            step(
                l.bias.as_slice_mut().expect("a vector is contiguous"),
                g.bias.as_slice().expect("a vector is contiguous"),
                m.bias.as_slice_mut().expect("a vector is contiguous"),
                v.bias.as_slice_mut().expect("a vector is contiguous"),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn random(rng: &mut Xoshiro256PlusPlus, rows: usize, cols: usize) -> Array2<f64> {
        Array2::from_shape_simple_fn((rows, cols), || rng.random_range(-1.0..1.0))
    }

    #[test]
    fn split_products_are_bitwise_one_dot_at_any_thread_count() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        // Large enough to split into several parts.
        let (a, b) = (random(&mut rng, 256, 500), random(&mut rng, 500, 130));
        let want = a.dot(&b);
        for threads in [1, 2, 3, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut c = Array2::zeros((256, 130));
            pool.install(|| dot_into(a.view(), b.view(), c.view_mut()));
            assert!(
                c.iter().zip(&want).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{threads} threads"
            );
        }
    }

    #[test]
    fn partial_backward_passes_are_bitwise_the_full_one() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(6);
        let net = Network::new(&[40, 128, 32, 9], Activation::Tanh, &mut rng);
        let x = random(&mut rng, 33, 40);
        let g = random(&mut rng, 33, 9);
        let tape = net.forward(x.view());
        let (grads, dx) = net.backward(&tape, g.clone());
        assert_eq!(net.backward_weights(&tape, g.clone()), grads);
        assert_eq!(net.input_gradient(&tape, g), dx);
        assert_eq!(&net.predict(x.view()), tape.outputs());
    }
}
