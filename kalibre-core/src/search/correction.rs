//! The model-minus-surrogate discrepancy added to the surrogate during a search.
//!
//! Zero order: per snapshot and output, the model's output minus the surrogate's at the
//! best run, so the corrected surrogate matches the model there (trust-region model
//! management). First order: a linear term in the unit box, fitted by weighted,
//! ridge-regularised least squares to the discrepancy at the other runs, so the corrected
//! surrogate also follows the model's slopes along the directions already explored (a
//! multi-point secant correction, as in space mapping). With fewer runs than parameters
//! the fit is the minimum-norm one: directions no run has explored keep the surrogate's
//! own slopes.

use crate::linalg::{cholesky, cholesky_solve};

/// Length scale (root-mean-square distance per coordinate, unit box) of the weights of
/// the runs in the linear fit: far runs say little about slopes at the best point.
pub const CORRECTION_LENGTH_UNIT: f64 = 0.05;
/// Ridge of the linear fit, relative to the mean squared weighted distance of the runs:
/// damps slopes read from two runs very close together.
pub const CORRECTION_RIDGE_REL: f64 = 1e-2;

/// An additive correction of the surrogate's predictions, per snapshot and output.
///
/// ```
/// use kalibre_core::search::OutputCorrection;
/// // One snapshot, one output; the model reads 1.0 above the surrogate at the best run
/// // (unit 0.5) and 2.0 above it at unit 0.7: the slope is 5 per unit.
/// let c = OutputCorrection::fit(
///     &[0.5],
///     vec![vec![1.0]],
///     &[(vec![0.7], vec![vec![2.0]])],
///     1.0,
///     1e-9,
/// );
/// assert!((c.value(0, 0, &[0.6]) - 1.5).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct OutputCorrection {
    /// Per snapshot, per output: the discrepancy at the anchor.
    offsets: Vec<Vec<f64>>,
    /// The anchor (best run), unit box.
    anchor: Vec<f64>,
    /// Rows `sqrt(w_j) (u_j - anchor)`: the explored directions (K x d).
    directions: Vec<Vec<f64>>,
    /// Per snapshot, per output: coefficients on `directions . (u - anchor)` (K each).
    coefficients: Vec<Vec<Vec<f64>>>,
}

impl OutputCorrection {
    /// The zero-order correction: constant offsets per snapshot and output.
    pub fn constant(offsets: Vec<Vec<f64>>) -> Self {
        OutputCorrection {
            offsets,
            anchor: Vec::new(),
            directions: Vec::new(),
            coefficients: Vec::new(),
        }
    }

    /// Fits the correction anchored at `anchor` (unit box) with discrepancy
    /// `anchor_discrepancy` (model minus surrogate, per snapshot and output), and a linear
    /// term from `others`: (unit point, its discrepancy). Runs weigh
    /// `exp(-(rms distance / length)^2 / 2)`; `ridge_rel` scales the ridge by the mean
    /// squared weighted distance. Runs whose discrepancy is not finite or whose shape
    /// differs from the anchor's are left out.
    pub fn fit(
        anchor: &[f64],
        anchor_discrepancy: Vec<Vec<f64>>,
        others: &[(Vec<f64>, Vec<Vec<f64>>)],
        length: f64,
        ridge_rel: f64,
    ) -> Self {
        let d = anchor.len().max(1) as f64;
        let same_shape = |e: &Vec<Vec<f64>>| {
            e.len() == anchor_discrepancy.len()
                && e.iter()
                    .zip(&anchor_discrepancy)
                    .all(|(a, b)| a.len() == b.len() && a.iter().all(|v| v.is_finite()))
        };
        let mut directions = Vec::new();
        let mut deltas: Vec<Vec<Vec<f64>>> = Vec::new();
        for (u, e) in others {
            if u.len() != anchor.len() || !same_shape(e) {
                continue;
            }
            let dx: Vec<f64> = u.iter().zip(anchor).map(|(a, b)| a - b).collect();
            let rms = (dx.iter().map(|v| v * v).sum::<f64>() / d).sqrt();
            if rms <= 1e-12 {
                continue;
            }
            let sw = (-0.25 * (rms / length).powi(2)).exp();
            directions.push(dx.iter().map(|v| sw * v).collect::<Vec<f64>>());
            deltas.push(
                e.iter()
                    .zip(&anchor_discrepancy)
                    .map(|(es, as_)| es.iter().zip(as_).map(|(a, b)| sw * (a - b)).collect())
                    .collect(),
            );
        }
        let k = directions.len();
        if k == 0 {
            return Self::constant(anchor_discrepancy);
        }
        let mut gram = vec![0.0; k * k];
        for i in 0..k {
            for j in 0..=i {
                let g: f64 = directions[i]
                    .iter()
                    .zip(&directions[j])
                    .map(|(a, b)| a * b)
                    .sum();
                gram[i * k + j] = g;
                gram[j * k + i] = g;
            }
        }
        let ridge = ridge_rel * (0..k).map(|i| gram[i * k + i]).sum::<f64>() / k as f64;
        for i in 0..k {
            gram[i * k + i] += ridge.max(1e-300);
        }
        let Some(chol) = cholesky(&gram, k) else {
            return Self::constant(anchor_discrepancy);
        };
        let coefficients = anchor_discrepancy
            .iter()
            .enumerate()
            .map(|(s, outs)| {
                (0..outs.len())
                    .map(|o| {
                        let rhs: Vec<f64> = deltas.iter().map(|e| e[s][o]).collect();
                        cholesky_solve(&chol, k, &rhs)
                    })
                    .collect()
            })
            .collect();
        OutputCorrection {
            offsets: anchor_discrepancy,
            anchor: anchor.to_vec(),
            directions,
            coefficients,
        }
    }

    /// Runs in the linear term (0: zero order only).
    pub fn directions(&self) -> usize {
        self.directions.len()
    }

    /// Projections of `u - anchor` on the explored directions (empty when zero order).
    pub fn projections(&self, unit: &[f64]) -> Vec<f64> {
        self.directions
            .iter()
            .map(|dir| {
                dir.iter()
                    .zip(unit)
                    .zip(&self.anchor)
                    .map(|((w, u), a)| w * (u - a))
                    .sum()
            })
            .collect()
    }

    /// The correction at `unit` given its [`Self::projections`].
    pub fn value_at(&self, snapshot: usize, output: usize, projections: &[f64]) -> f64 {
        let offset = self
            .offsets
            .get(snapshot)
            .and_then(|o| o.get(output))
            .copied()
            .unwrap_or(0.0);
        let linear: f64 = self
            .coefficients
            .get(snapshot)
            .and_then(|c| c.get(output))
            .map_or(0.0, |c| c.iter().zip(projections).map(|(a, p)| a * p).sum());
        offset + linear
    }

    /// The correction at a point of the unit box.
    pub fn value(&self, snapshot: usize, output: usize, unit: &[f64]) -> f64 {
        self.value_at(snapshot, output, &self.projections(unit))
    }

    /// Adds to `grad_unit` the gradient of `sum cotangent[o] * correction(snapshot, o)`
    /// with respect to unit coordinates.
    pub fn add_vjp(&self, snapshot: usize, cotangent: &[f64], grad_unit: &mut [f64]) {
        let Some(coef) = self.coefficients.get(snapshot) else {
            return;
        };
        let mut along = vec![0.0; self.directions.len()];
        for (c, co) in cotangent.iter().zip(coef) {
            if *c != 0.0 {
                for (a, v) in along.iter_mut().zip(co) {
                    *a += c * v;
                }
            }
        }
        for (a, dir) in along.iter().zip(&self.directions) {
            for (g, w) in grad_unit.iter_mut().zip(dir) {
                *g += a * w;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_discrepancy_is_recovered_along_explored_directions() {
        // Discrepancy e(u) = 1 + 2 u0 - 3 u1 on one output; runs explore both directions.
        let e = |u: &[f64]| vec![vec![1.0 + 2.0 * u[0] - 3.0 * u[1]]];
        let anchor = [0.5, 0.5];
        let others: Vec<(Vec<f64>, Vec<Vec<f64>>)> = [[0.6, 0.5], [0.5, 0.4], [0.55, 0.58]]
            .iter()
            .map(|u| (u.to_vec(), e(u)))
            .collect();
        let c = OutputCorrection::fit(&anchor, e(&anchor), &others, 10.0, 1e-10);
        for u in [[0.3, 0.7], [0.52, 0.49], [0.9, 0.1]] {
            assert!((c.value(0, 0, &u) - e(&u)[0][0]).abs() < 1e-6);
        }
        // The gradient of the correction is the discrepancy's slope.
        let mut g = vec![0.0; 2];
        c.add_vjp(0, &[1.0], &mut g);
        assert!(
            (g[0] - 2.0).abs() < 1e-6 && (g[1] + 3.0).abs() < 1e-6,
            "{g:?}"
        );
    }

    #[test]
    fn unexplored_directions_get_no_slope() {
        let anchor = [0.5, 0.5];
        let others = vec![(vec![0.7, 0.5], vec![vec![3.0]])];
        let c = OutputCorrection::fit(&anchor, vec![vec![1.0]], &others, 10.0, 1e-10);
        // Along u0 the slope is 10; along u1 nothing was explored.
        assert!((c.value(0, 0, &[0.6, 0.5]) - 2.0).abs() < 1e-6);
        assert!((c.value(0, 0, &[0.5, 0.9]) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn malformed_runs_are_left_out_and_constant_is_zero_order() {
        let anchor = [0.5];
        let others = vec![
            (vec![0.6], vec![vec![f64::NAN]]),
            (vec![0.6, 0.1], vec![vec![2.0]]),
            (vec![0.5], vec![vec![2.0]]),
        ];
        let c = OutputCorrection::fit(&anchor, vec![vec![1.0]], &others, 1.0, 1e-2);
        assert_eq!(c.directions(), 0);
        assert_eq!(c.value(0, 0, &[0.9]), 1.0);
        assert_eq!(
            OutputCorrection::constant(vec![vec![2.0]]).value(0, 0, &[0.1]),
            2.0
        );
    }

    #[test]
    fn far_runs_weigh_less() {
        // A near run says slope 1, a far run disagrees; the near one dominates.
        let anchor = [0.5];
        let others = vec![
            (vec![0.55], vec![vec![0.05]]),
            (vec![1.0], vec![vec![-5.0]]),
        ];
        let c = OutputCorrection::fit(&anchor, vec![vec![0.0]], &others, 0.1, 1e-6);
        let slope = (c.value(0, 0, &[0.51]) - c.value(0, 0, &[0.5])) / 0.01;
        assert!((slope - 1.0).abs() < 0.05, "{slope}");
    }
}
