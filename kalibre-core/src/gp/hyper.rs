//! The kernel's hyperparameters: one length scale per input dimension and a nugget,
//! shared by every scenario and output, chosen by the pooled profile log marginal
//! likelihood on a fixed log grid (a deterministic search: no seed, no threads).

use std::time::Instant;

use crate::linalg::{cholesky_jittered, forward_solve, log_det};

/// Length scales (unit box) on the grid `2^(LOG2_MIN + i / 2)`, `i = 0..GRID`: from 1/32
/// (shorter would only model the gaps between a few runs) to 32 (an input the outputs
/// do not depend on).
const LOG2_MIN: f64 = -5.0;
const GRID: usize = 21;
/// The grid index of length 1, the default when no output informs the choice.
const DEFAULT_INDEX: usize = 10;

/// Nugget ratios (noise variance over signal variance) tried.
pub(super) const NUGGETS: [f64; 4] = [1e-8, 1e-6, 1e-4, 1e-2];
/// The default nugget when no output informs the choice.
const DEFAULT_NUGGET: usize = 1;

/// Floor of the profiled signal variance (standardised units): residuals below it are
/// rounding, and a zero variance would make the likelihood infinite.
const VARIANCE_FLOOR: f64 = 1e-12;

/// Coordinate-search rounds per step size (grid steps of a factor 2, then of sqrt 2).
const ROUNDS: [(usize, usize); 2] = [(2, 3), (1, 3)];

/// The length scale at grid index `i`.
pub(super) fn length_at(i: usize) -> f64 {
    (LOG2_MIN + 0.5 * i as f64).exp2()
}

/// One scenario's data as the evidence reads it.
pub(super) struct Group<'a> {
    /// Unit inputs (kernel dimensions only), row-major `n x d`.
    pub z: &'a [f64],
    /// `1 / weight` per sample: the nugget's multiplier.
    pub inv_weight: &'a [f64],
    /// Trend residuals of the outputs that inform the choice, row-major `n x m`.
    pub residuals: Vec<f64>,
    /// Their number.
    pub m: usize,
}

impl Group<'_> {
    fn n(&self) -> usize {
        self.inv_weight.len()
    }
}

/// The kernel matrix `exp(-|z_i - z_j|^2_ls / 2) + nugget / w_i [i = j]`, row-major.
pub(super) fn kernel_matrix(
    z: &[f64],
    inv_weight: &[f64],
    d: usize,
    lengths: &[f64],
    nugget: f64,
) -> Vec<f64> {
    let n = inv_weight.len();
    let inv_len: Vec<f64> = lengths.iter().map(|l| 1.0 / l).collect();
    let mut k = vec![0.0; n * n];
    for i in 0..n {
        k[i * n + i] = 1.0 + nugget * inv_weight[i];
        for j in 0..i {
            let r2: f64 = (0..d)
                .map(|l| {
                    let t = (z[i * d + l] - z[j * d + l]) * inv_len[l];
                    t * t
                })
                .sum();
            let v = (-0.5 * r2).exp();
            k[i * n + j] = v;
            k[j * n + i] = v;
        }
    }
    k
}

/// The sum over groups and outputs of the profile log marginal likelihood, each output's
/// signal variance at its closed-form maximum `r^T K^-1 r / n`.
fn evidence(groups: &[Group<'_>], d: usize, lengths: &[f64], nugget: f64) -> f64 {
    let mut total = 0.0;
    for g in groups.iter().filter(|g| g.m > 0) {
        let (n, m) = (g.n(), g.m);
        let k = kernel_matrix(g.z, g.inv_weight, d, lengths, nugget);
        let Some((l, _)) = cholesky_jittered(&k, n) else {
            return f64::NEG_INFINITY;
        };
        let ld = log_det(&l, n);
        let mut y = g.residuals.clone();
        forward_solve(&l, n, &mut y, m);
        let mut q = vec![0.0; m];
        for row in y.chunks_exact(m) {
            for (qk, v) in q.iter_mut().zip(row) {
                *qk += v * v;
            }
        }
        let nf = n as f64;
        for qk in q {
            let s2 = (qk / nf).max(VARIANCE_FLOOR);
            total -= 0.5 * (nf * s2.ln() + qk / s2 + ld + nf * std::f64::consts::TAU.ln());
        }
    }
    if total.is_nan() {
        f64::NEG_INFINITY
    } else {
        total
    }
}

/// The hyperparameters chosen.
pub(super) struct Choice {
    /// Grid index of each dimension's length scale.
    pub index: Vec<usize>,
    /// Index into [`NUGGETS`].
    pub nugget: usize,
    /// Their evidence (`None` when no output informed the choice).
    pub evidence: Option<f64>,
    /// Candidates evaluated.
    pub evaluated: usize,
    /// The deadline cut the search short.
    pub timed_out: bool,
}

/// The search's state: the best candidate so far and what it cost.
struct Search<'g, 'a> {
    groups: &'g [Group<'a>],
    d: usize,
    deadline: Option<Instant>,
    best: Choice,
    best_value: f64,
}

impl Search<'_, '_> {
    /// Evaluates a candidate and keeps it if it is better; false when not (or when the
    /// deadline has passed: the search then ends with the best so far).
    fn try_candidate(&mut self, index: &[usize], nugget: usize) -> bool {
        if self.best.timed_out {
            return false;
        }
        if self.best.evaluated > 0 && self.deadline.is_some_and(|t| Instant::now() >= t) {
            self.best.timed_out = true;
            return false;
        }
        let lengths: Vec<f64> = index.iter().map(|&i| length_at(i)).collect();
        let value = evidence(self.groups, self.d, &lengths, NUGGETS[nugget]);
        self.best.evaluated += 1;
        // A relative margin, so that rounding on a flat ridge does not steer the search.
        let better = self.best.evaluated == 1
            || value > self.best_value + 1e-10 * self.best_value.abs().max(1.0);
        if better {
            self.best.index = index.to_vec();
            self.best.nugget = nugget;
            self.best_value = value;
        }
        better
    }
}

/// Maximises the pooled evidence over `d` length scales and the nugget: a common length
/// scale on every other grid point with every nugget, then coordinate search per
/// dimension (moving while it improves, in steps of a factor 2, then of sqrt 2) and over
/// the nugget, a few rounds each, stopping early when a round gains nothing.
pub(super) fn choose(groups: &[Group<'_>], d: usize, deadline: Option<Instant>) -> Choice {
    let mut search = Search {
        groups,
        d,
        deadline,
        best: Choice {
            index: vec![DEFAULT_INDEX; d],
            nugget: DEFAULT_NUGGET,
            evidence: None,
            evaluated: 0,
            timed_out: false,
        },
        best_value: f64::NEG_INFINITY,
    };
    // Without an output that the trend leaves unexplained there is nothing to learn.
    if groups.iter().all(|g| g.m == 0) {
        return search.best;
    }
    for i in (0..GRID).step_by(2) {
        for nugget in 0..NUGGETS.len() {
            search.try_candidate(&vec![i; d], nugget);
        }
    }
    for (step, rounds) in ROUNDS {
        for _ in 0..rounds {
            let mut improved = false;
            for j in 0..d {
                for up in [true, false] {
                    let mut moved = false;
                    loop {
                        let mut index = search.best.index.clone();
                        let next = if up {
                            index[j] + step
                        } else {
                            index[j].wrapping_sub(step)
                        };
                        if next >= GRID {
                            break;
                        }
                        index[j] = next;
                        if !search.try_candidate(&index, search.best.nugget) {
                            break;
                        }
                        moved = true;
                    }
                    improved |= moved;
                    if moved {
                        break;
                    }
                }
            }
            let current = search.best.nugget;
            for nugget in (0..NUGGETS.len()).filter(|&k| k != current) {
                let index = search.best.index.clone();
                improved |= search.try_candidate(&index, nugget);
            }
            if !improved || search.best.timed_out {
                break;
            }
        }
    }
    search.best.evidence = Some(search.best_value);
    search.best
}
