//! Standard test functions over the unit box, with hand-written gradients
//! (checked against finite differences in `tests/search.rs`), and an objective wrapper
//! that watches where a searcher evaluates.

#![allow(dead_code)]

use std::f64::consts::{E, PI};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use kalibre_core::Objective;

/// `sum (u_i - c_i)^2`, optimum `c` (in the unit box or outside it).
pub struct Sphere {
    pub centre: Vec<f64>,
}

impl Objective for Sphere {
    fn dim(&self) -> usize {
        self.centre.len()
    }
    fn cost(&self, u: &[f64]) -> f64 {
        u.iter()
            .zip(&self.centre)
            .map(|(x, c)| (x - c) * (x - c))
            .sum()
    }
    fn cost_and_gradient(&self, u: &[f64]) -> (f64, Vec<f64>) {
        let g = u
            .iter()
            .zip(&self.centre)
            .map(|(x, c)| 2.0 * (x - c))
            .collect();
        (self.cost(u), g)
    }
}

/// Rosenbrock on `x = -2 + 4 u`, optimum `x = 1` (`u = 0.75`), cost 0.
pub struct Rosenbrock {
    pub dim: usize,
}

impl Rosenbrock {
    pub const LO: f64 = -2.0;
    pub const SPAN: f64 = 4.0;
    pub fn optimum(&self) -> Vec<f64> {
        vec![(1.0 - Self::LO) / Self::SPAN; self.dim]
    }
}

impl Objective for Rosenbrock {
    fn dim(&self) -> usize {
        self.dim
    }
    fn cost(&self, u: &[f64]) -> f64 {
        self.cost_and_gradient(u).0
    }
    fn cost_and_gradient(&self, u: &[f64]) -> (f64, Vec<f64>) {
        let x: Vec<f64> = u.iter().map(|v| Self::LO + Self::SPAN * v).collect();
        let mut cost = 0.0;
        let mut g = vec![0.0; x.len()];
        for i in 0..x.len().saturating_sub(1) {
            let a = x[i + 1] - x[i] * x[i];
            let b = 1.0 - x[i];
            cost += 100.0 * a * a + b * b;
            g[i] += -400.0 * a * x[i] - 2.0 * b;
            g[i + 1] += 200.0 * a;
        }
        (cost, g.iter().map(|gi| gi * Self::SPAN).collect())
    }
}

/// Ackley on `x = -5 + 10 u`, shifted to its optimum at `x = shift` (cost 0).
pub struct ShiftedAckley {
    pub shift: Vec<f64>,
}

impl ShiftedAckley {
    pub const LO: f64 = -5.0;
    pub const SPAN: f64 = 10.0;
    pub fn optimum(&self) -> Vec<f64> {
        self.shift
            .iter()
            .map(|s| (s - Self::LO) / Self::SPAN)
            .collect()
    }
}

impl Objective for ShiftedAckley {
    fn dim(&self) -> usize {
        self.shift.len()
    }
    fn cost(&self, u: &[f64]) -> f64 {
        self.cost_and_gradient(u).0
    }
    fn cost_and_gradient(&self, u: &[f64]) -> (f64, Vec<f64>) {
        let d = self.shift.len() as f64;
        let z: Vec<f64> = u
            .iter()
            .zip(&self.shift)
            .map(|(v, s)| Self::LO + Self::SPAN * v - s)
            .collect();
        let r = (z.iter().map(|z| z * z).sum::<f64>() / d).sqrt();
        let c = z.iter().map(|z| (2.0 * PI * z).cos()).sum::<f64>() / d;
        let (e1, e2) = ((-0.2 * r).exp(), c.exp());
        let cost = -20.0 * e1 - e2 + 20.0 + E;
        let g = z
            .iter()
            .map(|zi| {
                // d/dz of -20 exp(-0.2 r) is 4 exp(-0.2 r) z / (d r); 0 at r = 0 (a kink).
                let g1 = if r > 0.0 {
                    4.0 * e1 * zi / (d * r)
                } else {
                    0.0
                };
                let g2 = e2 * 2.0 * PI * (2.0 * PI * zi).sin() / d;
                (g1 + g2) * Self::SPAN
            })
            .collect();
        (cost, g)
    }
}

/// Rastrigin on `x = -5.12 + 10.24 u`, shifted to its optimum at `x = shift` (cost 0).
pub struct ShiftedRastrigin {
    pub shift: Vec<f64>,
}

impl ShiftedRastrigin {
    pub const LO: f64 = -5.12;
    pub const SPAN: f64 = 10.24;
    pub fn optimum(&self) -> Vec<f64> {
        self.shift
            .iter()
            .map(|s| (s - Self::LO) / Self::SPAN)
            .collect()
    }
}

impl Objective for ShiftedRastrigin {
    fn dim(&self) -> usize {
        self.shift.len()
    }
    fn cost(&self, u: &[f64]) -> f64 {
        self.cost_and_gradient(u).0
    }
    fn cost_and_gradient(&self, u: &[f64]) -> (f64, Vec<f64>) {
        let mut cost = 10.0 * self.shift.len() as f64;
        let mut g = Vec::with_capacity(u.len());
        for (v, s) in u.iter().zip(&self.shift) {
            let z = Self::LO + Self::SPAN * v - s;
            cost += z * z - 10.0 * (2.0 * PI * z).cos();
            g.push((2.0 * z + 20.0 * PI * (2.0 * PI * z).sin()) * Self::SPAN);
        }
        (cost, g)
    }
}

/// Wraps an objective, recording whether any evaluated point left the unit box (or had
/// the wrong length), and counting evaluations.
pub struct BoxWatch<'a> {
    pub inner: &'a dyn Objective,
    outside: AtomicBool,
    count: AtomicUsize,
}

impl<'a> BoxWatch<'a> {
    pub fn new(inner: &'a dyn Objective) -> Self {
        BoxWatch {
            inner,
            outside: AtomicBool::new(false),
            count: AtomicUsize::new(0),
        }
    }
    fn check(&self, u: &[f64]) {
        self.count.fetch_add(1, Ordering::Relaxed);
        if u.len() != self.inner.dim() || u.iter().any(|v| !(0.0..=1.0).contains(v)) {
            self.outside.store(true, Ordering::Relaxed);
        }
    }
    pub fn left_box(&self) -> bool {
        self.outside.load(Ordering::Relaxed)
    }
    pub fn evaluations(&self) -> usize {
        self.count.load(Ordering::Relaxed)
    }
}

impl Objective for BoxWatch<'_> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn cost(&self, u: &[f64]) -> f64 {
        self.check(u);
        self.inner.cost(u)
    }
    fn cost_and_gradient(&self, u: &[f64]) -> (f64, Vec<f64>) {
        self.check(u);
        self.inner.cost_and_gradient(u)
    }
}

/// Central finite-difference gradient.
pub fn fd_gradient(f: &dyn Objective, u: &[f64], h: f64) -> Vec<f64> {
    let mut x = u.to_vec();
    (0..u.len())
        .map(|i| {
            x[i] = u[i] + h;
            let up = f.cost(&x);
            x[i] = u[i] - h;
            let down = f.cost(&x);
            x[i] = u[i];
            (up - down) / (2.0 * h)
        })
        .collect()
}

/// Largest absolute coordinate difference.
pub fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}
