//! Linear diagnosis problems with a known answer, shared by the diagnosis tests.
// Each test crate uses a different part of this module.
#![allow(dead_code)]

use kalibre_core::diagnose::{Diagnosis, Hypothesis, HypothesisParam, Residuals, RowInfo};
use ndarray::Array2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

pub const SIGMA: f64 = 0.1;
/// Mean absolute value of N(0, sigma): sigma * sqrt(2 / pi).
pub const NOISE_MAE: f64 = SIGMA * 0.797_884_560_802_865_4;

/// `snapshots x outputs` rows.
pub fn rows(snapshots: usize, outputs: usize) -> Vec<RowInfo> {
    (0..snapshots * outputs)
        .map(|i| RowInfo {
            output: format!("s{}", i % outputs),
            group: if i % 2 == 0 { "cold" } else { "hot" }.into(),
            snapshot: format!("t{}", i / outputs),
        })
        .collect()
}

pub fn gaussian(rng: &mut Xoshiro256PlusPlus, n: usize, sd: f64) -> Vec<f64> {
    let d = Normal::new(0.0, sd).unwrap();
    (0..n).map(|_| d.sample(rng)).collect()
}

pub fn matrix(n: usize, cols: &[Vec<f64>]) -> Array2<f64> {
    Array2::from_shape_fn((n, cols.len()), |(i, j)| cols[j][i])
}

/// A problem with two calibrated parameters and three candidate hypotheses:
/// `a` (one column), `b` (one column) and `c` (two columns), all random patterns.
pub struct Problem {
    pub n: usize,
    pub rows: Vec<RowInfo>,
    pub j: Vec<Vec<f64>>,
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub c: Vec<Vec<f64>>,
    pub noise: Vec<f64>,
}

impl Problem {
    pub fn new(seed: u64, snapshots: usize, outputs: usize) -> Self {
        let n = snapshots * outputs;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let j = vec![gaussian(&mut rng, n, 1.0), gaussian(&mut rng, n, 1.0)];
        let a = gaussian(&mut rng, n, 1.0);
        let b = gaussian(&mut rng, n, 1.0);
        let c = vec![gaussian(&mut rng, n, 1.0), gaussian(&mut rng, n, 1.0)];
        let noise = gaussian(&mut rng, n, SIGMA);
        Problem {
            n,
            rows: rows(snapshots, outputs),
            j,
            a,
            b,
            c,
            noise,
        }
    }

    /// Residuals of a model missing `amount` of `b`, with the current parameters a little
    /// off their optimum: `r = J d - amount * b + noise` (the fit must give `dq = amount`).
    pub fn residuals(&self, amount: f64) -> Residuals {
        let r: Vec<f64> = (0..self.n)
            .map(|i| 0.3 * self.j[0][i] - 0.2 * self.j[1][i] - amount * self.b[i] + self.noise[i])
            .collect();
        Residuals::new(
            self.rows.clone(),
            r,
            matrix(self.n, &self.j),
            vec!["alpha/a".into(), "alpha/b".into()],
        )
        .unwrap()
    }

    pub fn hypotheses(&self) -> Vec<Hypothesis> {
        vec![hyp1("a", &self.a), hyp1("b", &self.b), hyp("c", &self.c)]
    }
}

pub fn hyp(name: &str, cols: &[Vec<f64>]) -> Hypothesis {
    let n = cols[0].len();
    let params = (0..cols.len())
        .map(|k| HypothesisParam::bounded(format!("{name}/q{k}"), -2.0, 2.0))
        .collect();
    Hypothesis::new(name, params, matrix(n, cols))
}

pub fn hyp1(name: &str, col: &[f64]) -> Hypothesis {
    hyp(name, &[col.to_vec()])
}

pub fn find<'a>(d: &'a Diagnosis, name: &str) -> &'a kalibre_core::diagnose::HypothesisResult {
    d.hypotheses.iter().find(|h| h.name == name).unwrap()
}
