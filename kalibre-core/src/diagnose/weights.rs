//! Row weights of a diagnosis with a known per-row model uncertainty.
//!
//! Each residual is taken as noise of standard deviation `sigma` plus an independent
//! model error of standard deviation `u_k` (e.g. the discretisation error from a refined
//! grid). Rows are weighed by `sigma / sqrt(sigma^2 + u_k^2)`: 1 where the model is
//! exact, less where its numerics alone could explain the residual.

use super::linalg::{lstsq, residual_after};

/// Maximum-likelihood noise variance `v` given residuals `e` and per-row model variances
/// `u2`: the root of `sum e^2 / (v + u2)^2 - 1 / (v + u2) = 0` (0 when even `v = 0`
/// leaves the residuals smaller than the model uncertainty).
fn ml_variance(e: &[f64], u2: &[f64]) -> f64 {
    let slope = |v: f64| -> f64 {
        e.iter()
            .zip(u2)
            .map(|(e, u2)| {
                let t = v + u2;
                if t > 0.0 {
                    e * e / (t * t) - 1.0 / t
                } else {
                    0.0
                }
            })
            .sum()
    };
    let mut hi = e.iter().map(|x| x * x).fold(0.0, f64::max).max(1e-300);
    let mut lo = 0.0;
    // A tiny positive start avoids dividing by a zero uncertainty.
    if slope(hi * 1e-12) <= 0.0 {
        return 0.0;
    }
    while slope(hi) > 0.0 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if slope(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The noise sigma the weights use: `noise_sigma` when given, else the maximum-likelihood
/// estimate, alternated with the weighted refit of the current parameters until it
/// settles; and the weights themselves.
pub(crate) fn row_weights(
    r: &[f64],
    jcols: &[Vec<f64>],
    uncertainty: &[f64],
    noise_sigma: Option<f64>,
) -> (f64, Vec<f64>) {
    let n = r.len();
    let u2: Vec<f64> = uncertainty.iter().map(|u| u * u).collect();
    let weights_for = |s: f64| -> Vec<f64> {
        u2.iter()
            .map(|u2| {
                if s > 0.0 {
                    s / (s * s + u2).sqrt()
                } else {
                    1.0
                }
            })
            .collect()
    };
    let refit = |w: &[f64]| -> Vec<f64> {
        let cols: Vec<Vec<f64>> = jcols
            .iter()
            .map(|c| c.iter().zip(w).map(|(x, w)| x * w).collect())
            .collect();
        let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
        let rw: Vec<f64> = r.iter().zip(w).map(|(x, w)| x * w).collect();
        let neg: Vec<f64> = rw.iter().map(|v| -v).collect();
        let fit = lstsq(&refs, &neg, &vec![0.0; cols.len()]);
        residual_after(&refs, &fit.x, &rw)
            .iter()
            .zip(w)
            .map(|(e, w)| e / w)
            .collect()
    };
    if let Some(s) = noise_sigma {
        return (s, weights_for(s));
    }
    let e = refit(&vec![1.0; n]);
    let mut s = (e.iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt();
    for _ in 0..20 {
        let e = refit(&weights_for(s));
        // Floor: a noise-free fit would weigh every uncertain row at 0.
        let next = ml_variance(&e, &u2).sqrt().max(1e-6 * s.max(1e-300));
        let settled = (next - s).abs() <= 1e-6 * s;
        s = next;
        if settled {
            break;
        }
    }
    (s, weights_for(s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ml_variance_without_uncertainty_is_the_mean_square() {
        let e = [0.3, -0.1, 0.2, -0.4];
        let v = ml_variance(&e, &[0.0; 4]);
        let ms = e.iter().map(|x| x * x).sum::<f64>() / 4.0;
        assert!((v - ms).abs() < 1e-12 * ms.max(1.0), "{v} vs {ms}");
    }

    #[test]
    fn rows_with_large_uncertainty_weigh_less_and_the_noise_is_recovered() {
        // Noise 0.1 on every row; rows 0-3 also carry a model error of about 2.
        let r: Vec<f64> = (0..40)
            .map(|i| {
                let noise = 0.1 * if i % 2 == 0 { 1.0 } else { -1.0 };
                if i < 4 {
                    noise + 2.0
                } else {
                    noise
                }
            })
            .collect();
        let mut u = vec![0.0; 40];
        u[..4].iter_mut().for_each(|x| *x = 2.0);
        let (s, w) = row_weights(&r, &[], &u, None);
        assert!((s - 0.1).abs() < 0.02, "sigma {s}");
        assert!(w[0] < 0.1 && (w[10] - 1.0).abs() < 1e-12, "{w:?}");
    }
}
