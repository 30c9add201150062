//! Row weights of a diagnosis with a known per-row model uncertainty.
//!
//! Each residual is taken as noise of standard deviation `sigma` plus an independent
//! model error of standard deviation `u_k` (e.g. the discretisation error from a refined
//! grid). Rows are weighed by `sigma / sqrt(sigma^2 + u_k^2)`: 1 where the model is
//! exact, less where its numerics alone could explain the residual.

use super::linalg::{bisect_root, lstsq, residual_after};

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
    // A tiny positive start avoids dividing by a zero uncertainty.
    if slope(hi * 1e-12) <= 0.0 {
        return 0.0;
    }
    while slope(hi) > 0.0 {
        hi *= 2.0;
    }
    bisect_root(slope, 0.0, hi, 200)
}

/// Maximum-likelihood share `c` in `[0, 1]` of a model-form variance `b` (per row), given
/// residuals `e`, the noise variance `v` and the numerical model variances `a`: the root
/// of `sum b (e^2 / t^2 - 1 / t) = 0`, `t = v + a + c b`, clamped to the interval.
fn ml_model_form_share(e: &[f64], v: f64, a: &[f64], b: &[f64]) -> f64 {
    let slope = |c: f64| -> f64 {
        e.iter()
            .zip(a)
            .zip(b)
            .map(|((e, a), b)| {
                let t = v + a + c * b;
                if t > 0.0 {
                    b * (e * e / (t * t) - 1.0 / t)
                } else {
                    0.0
                }
            })
            .sum()
    };
    if slope(0.0) <= 0.0 {
        return 0.0;
    }
    if slope(1.0) >= 0.0 {
        return 1.0;
    }
    bisect_root(slope, 0.0, 1.0, 60)
}

/// What [`row_weights`] settles on.
#[derive(Debug, Clone)]
pub(crate) struct RowWeights {
    /// The noise sigma: given, or estimated.
    pub sigma: f64,
    /// Each row's weight, `sigma / sqrt(sigma^2 + u^2 + c m^2)`.
    pub weights: Vec<f64>,
    /// The fitted share `c` of the model-form variance (`None` without one).
    pub model_form_share: Option<f64>,
}

/// The noise sigma the weights use (`noise_sigma` when given, else the
/// maximum-likelihood estimate) and, with a model-form uncertainty `m`, the share of its
/// variance the residuals bear out (maximum likelihood, at most all of it: on data the
/// model reproduces, another physics' reading is no uncertainty of it), alternated with
/// the weighted refit of the current parameters until they settle; and the weights
/// themselves. `numerical` is each row's numerical uncertainty `u`.
///
/// Both are Gaussian estimates: a few readings far off (a strong effect at one sensor)
/// inflate the noise, and the share can then fall to 0 though the other readings follow
/// the variant. Estimating both under the diagnosis's Student-t was tried and not kept
/// (`docs/diagnosis.md`, "Session 31"): it named more effects on clean held-out halls.
pub(crate) fn row_weights(
    r: &[f64],
    jcols: &[Vec<f64>],
    numerical: Option<&[f64]>,
    model_form: Option<&[f64]>,
    noise_sigma: Option<f64>,
) -> RowWeights {
    let n = r.len();
    let squares = |u: Option<&[f64]>| -> Vec<f64> {
        u.map_or_else(|| vec![0.0; n], |u| u.iter().map(|u| u * u).collect())
    };
    let (a, b) = (squares(numerical), squares(model_form));
    let weights_for = |s: f64, c: f64| -> Vec<f64> {
        a.iter()
            .zip(&b)
            .map(|(a, b)| {
                if s > 0.0 {
                    s / (s * s + a + c * b).sqrt()
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
    // With the noise given and no model form there is nothing to fit.
    if let (Some(s), None) = (noise_sigma, model_form) {
        return RowWeights {
            sigma: s,
            weights: weights_for(s, 0.0),
            model_form_share: None,
        };
    }
    let share = |e: &[f64], s: f64| -> f64 {
        if model_form.is_some() {
            ml_model_form_share(e, s * s, &a, &b)
        } else {
            0.0
        }
    };
    let mut s = noise_sigma.unwrap_or_else(|| {
        let e = refit(&vec![1.0; n]);
        (e.iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt()
    });
    // Floor: a noise-free fit would weigh every uncertain row at 0. Relative to the
    // first estimate, so that it does not compound from round to round (it fell to
    // 1e-120 of the residuals in 20 rounds when the uncertainty covered them all).
    let floor = 1e-6 * s.max(1e-300);
    let mut c = 1.0;
    // As many rounds as before the model-form share existed when there is none.
    let rounds = if model_form.is_some() { 50 } else { 20 };
    for _ in 0..rounds {
        let e = refit(&weights_for(s, c));
        let next_s = match noise_sigma {
            Some(s) => s,
            None => {
                let u2: Vec<f64> = a.iter().zip(&b).map(|(a, b)| a + c * b).collect();
                ml_variance(&e, &u2).sqrt().max(floor)
            }
        };
        let next_c = share(&e, next_s);
        let settled = (next_s - s).abs() <= 1e-6 * s && (next_c - c).abs() <= 1e-6;
        s = next_s;
        c = next_c;
        if settled {
            break;
        }
    }
    RowWeights {
        sigma: s,
        weights: weights_for(s, c),
        model_form_share: model_form.map(|_| c),
    }
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
        let RowWeights {
            sigma: s,
            weights: w,
            ..
        } = row_weights(&r, &[], Some(&u), None, None);
        assert!((s - 0.1).abs() < 0.02, "sigma {s}");
        assert!(w[0] < 0.1 && (w[10] - 1.0).abs() < 1e-12, "{w:?}");
    }

    /// Rows 0-7 of 48 have a model-form uncertainty of 2; the noise is 0.1 everywhere.
    fn model_form_case(model_error: f64) -> (Vec<f64>, Vec<f64>) {
        let r: Vec<f64> = (0..48)
            .map(|i| {
                let noise = 0.1 * if i % 2 == 0 { 1.0 } else { -1.0 };
                let sign = if i % 3 == 0 { 1.0 } else { -1.0 };
                if i < 8 {
                    noise + sign * model_error
                } else {
                    noise
                }
            })
            .collect();
        let mut m = vec![0.0; 48];
        m[..8].iter_mut().for_each(|x| *x = 2.0);
        (r, m)
    }

    #[test]
    fn a_model_form_the_residuals_do_not_bear_out_weighs_nothing() {
        // The model reproduces the data: the other physics' reading is no uncertainty.
        let (r, m) = model_form_case(0.0);
        let w = row_weights(&r, &[], None, Some(&m), None);
        let c = w.model_form_share.unwrap();
        assert!(c < 1e-3, "share {c}");
        assert!((w.sigma - 0.1).abs() < 0.01, "sigma {}", w.sigma);
        assert!(w.weights.iter().all(|x| *x > 0.99), "{:?}", w.weights);
    }

    #[test]
    fn a_model_form_the_residuals_bear_out_weighs_its_rows_down() {
        // Model errors of about the variant's size: all of it counts.
        let (r, m) = model_form_case(2.5);
        let w = row_weights(&r, &[], None, Some(&m), None);
        assert_eq!(w.model_form_share, Some(1.0));
        assert!(w.weights[0] < 0.1 && (w.weights[20] - 1.0).abs() < 1e-12);
        // Errors of half its size: about a quarter of its variance, (1 / 2)^2.
        let (r, m) = model_form_case(1.0);
        let w = row_weights(&r, &[], None, Some(&m), Some(0.1));
        let c = w.model_form_share.unwrap();
        // Its rows' mean square is 1 + 0.01 = sigma^2 + c * 4.
        let expected = 0.25;
        assert!((c - expected).abs() < 0.05, "share {c} vs about {expected}");
        assert_eq!(w.sigma, 0.1);
    }

    #[test]
    fn the_noise_floor_does_not_compound_when_the_uncertainty_covers_every_residual() {
        // Residuals well inside an uncertainty of 1: the maximum-likelihood noise is 0,
        // and the estimate stops at its floor, a millionth of the first estimate (the
        // residuals' root mean square, 0.5), rather than shrinking round after round.
        let r = [1.0, 0.1, -0.1, 0.0];
        let rms = (r.iter().map(|x| x * x).sum::<f64>() / 4.0).sqrt();
        let w = row_weights(&r, &[], Some(&[1.0; 4]), None, None);
        assert!(
            (w.sigma - 1e-6 * rms).abs() < 1e-12 * rms,
            "sigma {} against the floor {}",
            w.sigma,
            1e-6 * rms
        );
        assert!(w.weights.iter().all(|x| x.is_finite() && *x > 0.0));
    }
}
