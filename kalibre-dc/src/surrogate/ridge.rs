//! The small linear algebra of the thermal graph's least-squares start: weighted
//! standardisation, the ridge (also kept in Adam's loss) and a dense solver for the
//! per-sensor normal equations (a handful of unknowns each).

/// The least-squares start's ridge in the units of the training loss (a mean over samples
/// and sensors): `(ridge / n) * sum (theta - prior)^2` over the slopes `a` (prior: the
/// physical slope, `cold_scale`) and `c` (prior 0), and `(term_ridge[t] / n) * sum e^2`
/// over each term's weights; adds its gradient to `grad`.
/// Adam then minimises what the start minimised: without it, Adam's normalised steps
/// move a weight whose feature hardly varied as far as any other, fitting noise with a
/// slope that a prediction where the feature does vary multiplies.
pub(super) fn ridge_and_grad(
    cold_scale: &[f64],
    ridge: f64,
    term_ridge: &[f64],
    theta: &[f64],
    grad: &mut [f64],
) -> f64 {
    let n = cold_scale.len();
    let nt = term_ridge.len();
    let scale = |r: f64| r / n as f64;
    let mut penalty = 0.0;
    let slopes = (0..n)
        .map(|k| (k, cold_scale[k], scale(ridge)))
        .chain((2 * n..3 * n).map(|i| (i, 0.0, scale(ridge))))
        .chain((4 * n..(4 + nt) * n).map(|i| (i, 0.0, scale(term_ridge[(i - 4 * n) / n]))));
    for (i, prior, sc) in slopes {
        let diff = theta[i] - prior;
        penalty += sc * diff * diff;
        grad[i] += 2.0 * sc * diff;
    }
    penalty
}

/// Weighted mean and standard deviation over samples (weights average 1); a feature that
/// does not vary is scaled by its magnitude instead, so a later change is measured
/// relative to its training value.
pub(super) fn mean_scale(v: impl Iterator<Item = f64> + Clone, wt: &[f64]) -> (f64, f64) {
    let n = v.clone().count().max(1) as f64;
    let mean = v.clone().zip(wt).map(|(x, w)| w * x).sum::<f64>() / n;
    let var = v
        .zip(wt)
        .map(|(x, w)| w * (x - mean) * (x - mean))
        .sum::<f64>()
        / n;
    let sd = var.sqrt();
    let mag = mean.abs().max(1.0);
    (mean, if sd > 1e-9 * mag { sd } else { mag })
}

pub(super) fn wdot(a: &[f64], b: &[f64], w: &[f64]) -> f64 {
    a.iter().zip(b).zip(w).map(|((x, y), w)| w * x * y).sum()
}

/// Solves a small symmetric positive definite system by Gaussian elimination with
/// partial pivoting (the ridge keeps it non-singular).
pub(super) fn solve_spd(a: &mut [f64], b: &mut [f64], m: usize) -> Vec<f64> {
    for col in 0..m {
        let piv = (col..m)
            .max_by(|&i, &j| a[i * m + col].abs().total_cmp(&a[j * m + col].abs()))
            .unwrap_or(col);
        if piv != col {
            for q in 0..m {
                a.swap(col * m + q, piv * m + q);
            }
            b.swap(col, piv);
        }
        let p = a[col * m + col];
        for r in col + 1..m {
            let f = a[r * m + col] / p;
            for q in col..m {
                a[r * m + q] -= f * a[col * m + q];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = vec![0.0; m];
    for r in (0..m).rev() {
        let s: f64 = (r + 1..m).map(|q| a[r * m + q] * x[q]).sum();
        x[r] = (b[r] - s) / a[r * m + r];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_solver_matches_known_solution() {
        let mut a = vec![4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let x = [1.0, -2.0, 0.5];
        let mut b: Vec<f64> = (0..3)
            .map(|r| (0..3).map(|q| a[r * 3 + q] * x[q]).sum())
            .collect();
        let sol = solve_spd(&mut a, &mut b, 3);
        for (s, t) in sol.iter().zip(x) {
            assert!((s - t).abs() < 1e-12);
        }
    }

    #[test]
    fn constant_feature_is_scaled_by_magnitude() {
        let (m, s) = mean_scale([250.0, 250.0, 250.0].into_iter(), &[1.0; 3]);
        assert_eq!((m, s), (250.0, 250.0));
        let (m, s) = mean_scale([1.0, 3.0].into_iter(), &[1.0; 2]);
        assert_eq!((m, s), (2.0, 1.0));
    }
}
