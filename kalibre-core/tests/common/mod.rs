//! Shared fixtures: a cheap analytic model with two parameters, a quadratic
//! response-surface surrogate (least squares per snapshot and output), observations.
// Each test crate uses a different part of this module.
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use kalibre_core::{
    FitSummary, Model, ModelError, Observations, OutputInfo, Outputs, ParamSpace, Report, Scale,
    Snapshot, Surrogate, TrainingSet,
};

/// An operating condition: its index (for the surrogate's per-snapshot coefficients) and a load.
#[derive(Debug, Clone)]
pub struct Scen {
    pub id: usize,
    pub load: f64,
}

/// Where the model fails: `Err` for `a > a_err`, NaN outputs for `b < b_nan`.
#[derive(Debug, Clone, Copy)]
pub struct FailZone {
    pub a_err: f64,
    pub b_nan: f64,
}

/// A cheap analytic "expensive" model that counts its runs.
pub struct Poly {
    pub calls: AtomicUsize,
    pub fail: Option<FailZone>,
}

impl Poly {
    pub fn new() -> Self {
        Poly {
            calls: AtomicUsize::new(0),
            fail: None,
        }
    }
    pub fn failing(zone: FailZone) -> Self {
        Poly {
            calls: AtomicUsize::new(0),
            fail: Some(zone),
        }
    }
    pub fn calls(&self) -> usize {
        self.calls.load(Ordering::SeqCst)
    }
}

pub fn poly_outputs(load: f64, p: &[f64]) -> Vec<f64> {
    let (a, b) = (p[0], p[1]);
    vec![
        load * a + b,
        a * b + 10.0,
        load * b * b - a,
        0.5 * a * a + load,
    ]
}

impl Model for Poly {
    type Scenario = Scen;
    fn fingerprint(&self) -> String {
        "poly-v1".into()
    }
    fn evaluate(&self, scenario: &Scen, params: &[f64]) -> Result<Outputs, ModelError> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        let mut out = poly_outputs(scenario.load, params);
        if let Some(z) = self.fail {
            if params[0] > z.a_err {
                return Err(ModelError::failed(format!("diverged at a = {}", params[0])));
            }
            if params[1] < z.b_nan {
                out[2] = f64::NAN;
            }
        }
        Ok(out.into())
    }
}

pub const TRUTH: [f64; 2] = [1.7, 1.2];

pub fn space() -> ParamSpace {
    ParamSpace::new()
        .with("a", 0.0, 4.0, 1.0, Scale::Linear)
        .unwrap()
        .with("b", 0.5, 3.0, 2.0, Scale::Linear)
        .unwrap()
}

/// Two snapshots measured from the model at the truth (one output missing in the second).
pub fn observations() -> Observations<Scen> {
    observations_with(&[1.0, 2.0], |id, k, y| (!(id == 1 && k == 3)).then_some(y))
}

/// One snapshot per load, the model at the truth read through `reading(snapshot, output,
/// value)` (none: not measured).
pub fn observations_with(
    loads: &[f64],
    reading: impl Fn(usize, usize, f64) -> Option<f64>,
) -> Observations<Scen> {
    let outputs = (0..4)
        .map(|k| OutputInfo {
            name: format!("s{k}"),
            group: if k < 2 { "cold" } else { "hot" }.into(),
        })
        .collect();
    let snaps = loads
        .iter()
        .enumerate()
        .map(|(id, &load)| Snapshot {
            label: format!("t{id}"),
            scenario: Scen { id, load },
            measured: poly_outputs(load, &TRUTH)
                .into_iter()
                .enumerate()
                .map(|(k, y)| reading(id, k, y))
                .collect(),
        })
        .collect();
    Observations::new(outputs, snaps).unwrap()
}

/// Quadratic response surface per (snapshot, output): features `[1, a, b, a², ab, b²]`,
/// fitted by ridge-regularised least squares.
#[derive(Debug, Clone, Default)]
pub struct QuadSurface {
    /// `coef[snapshot][output]` = 6 weights.
    pub coef: Vec<Vec<[f64; 6]>>,
}

fn features(p: &[f64]) -> [f64; 6] {
    let (a, b) = (p[0], p[1]);
    [1.0, a, b, a * a, a * b, b * b]
}

/// Solves the symmetric positive definite system `m x = r` (Gaussian elimination, partial pivoting).
fn solve6(mut m: [[f64; 6]; 6], mut r: [f64; 6]) -> [f64; 6] {
    for c in 0..6 {
        let piv = (c..6)
            .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
            .unwrap();
        m.swap(c, piv);
        r.swap(c, piv);
        for i in c + 1..6 {
            let f = m[i][c] / m[c][c];
            let pivot_row = m[c];
            for (mij, pj) in m[i][c..].iter_mut().zip(&pivot_row[c..]) {
                *mij -= f * pj;
            }
            r[i] -= f * r[c];
        }
    }
    let mut x = [0.0; 6];
    for i in (0..6).rev() {
        let s: f64 = (i + 1..6).map(|j| m[i][j] * x[j]).sum();
        x[i] = (r[i] - s) / m[i][i];
    }
    x
}

impl Surrogate for QuadSurface {
    type Scenario = Scen;

    fn fit(&mut self, data: TrainingSet<'_, Scen>, _seed: u64) -> kalibre_core::Result<FitSummary> {
        let n_out = data.samples[0].outputs.len();
        self.coef = vec![vec![[0.0; 6]; n_out]; data.scenarios.len()];
        for (s, coef) in self.coef.iter_mut().enumerate() {
            for (k, w) in coef.iter_mut().enumerate() {
                let mut m = [[0.0; 6]; 6];
                let mut r = [0.0; 6];
                for smp in data.samples.iter().filter(|x| x.snapshot == s) {
                    let f = features(&smp.params);
                    for ((row, ri), fi) in m.iter_mut().zip(r.iter_mut()).zip(&f) {
                        for (mij, fj) in row.iter_mut().zip(&f) {
                            *mij += fi * fj;
                        }
                        *ri += fi * smp.outputs[k];
                    }
                }
                for (i, row) in m.iter_mut().enumerate() {
                    row[i] += 1e-9;
                }
                *w = solve6(m, r);
            }
        }
        let mut se = 0.0;
        let mut n = 0;
        for smp in data.samples {
            let pred = self.predict(&data.scenarios[smp.snapshot], &smp.params);
            for (p, y) in pred.iter().zip(&smp.outputs) {
                se += (p - y) * (p - y);
                n += 1;
            }
        }
        Ok(FitSummary {
            timed_out: false,
            train_mse: se / n.max(1) as f64,
            epochs: 1,
        })
    }

    fn predict(&self, scenario: &Scen, params: &[f64]) -> Vec<f64> {
        let f = features(params);
        self.coef[scenario.id]
            .iter()
            .map(|w| w.iter().zip(&f).map(|(w, f)| w * f).sum())
            .collect()
    }

    fn vjp(&self, scenario: &Scen, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        let (a, b) = (params[0], params[1]);
        // One entry per parameter: those past `a` and `b` it does not read.
        let mut g = vec![0.0; params.len()];
        for (w, c) in self.coef[scenario.id].iter().zip(cotangent) {
            g[0] += c * (w[1] + 2.0 * w[3] * a + w[4] * b);
            g[1] += c * (w[2] + w[4] * a + 2.0 * w[5] * b);
        }
        g
    }
}

/// A fresh, empty directory under the system temp dir.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kalibre-core-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The report with every wall time zeroed, for comparing runs.
pub fn without_timings(r: &Report) -> Report {
    let mut r = r.clone();
    r.wall_s = 0.0;
    r.runs = Default::default();
    r.journal = None;
    r.initial.wall_s = 0.0;
    for h in &mut r.history {
        h.wall_s = Default::default();
    }
    r
}

/// Bit patterns of the best parameters.
pub fn best_bits(r: &Report) -> Vec<u64> {
    r.best.params.values().iter().map(|v| v.to_bits()).collect()
}
