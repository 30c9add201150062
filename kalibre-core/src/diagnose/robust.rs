//! The diagnosis's likelihood: Gaussian, or Student-t fitted by iteratively reweighted
//! least squares (IRLS).
//!
//! A model that is wrong at a few outputs for reasons no hypothesis names (its own
//! physics, a misplaced or faulty sensor) leaves residuals of several noise sigmas there.
//! Under a Gaussian likelihood those few rows set the noise estimate and dominate every
//! sum of squares, so an effect that moves many outputs by one degree can score no
//! better than nothing. Under a Student-t likelihood their weight falls as
//! `(nu + 1) / (nu + (e / s)^2)`, and a hypothesis earns what it explains of the rest;
//! it still earns credit for an outlier it does explain.

use super::linalg::{bisect_root, lstsq, residual_after};

/// The likelihood of the residuals: Gaussian (`nu` none) or Student-t with `nu` degrees
/// of freedom.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Likelihood {
    nu: Option<f64>,
    /// The scale this likelihood fits to Gaussian noise of unit standard deviation.
    unit_scale: f64,
}

/// A fit of the columns to the residuals under a [`Likelihood`].
#[derive(Debug, Clone)]
pub(crate) struct Fit {
    /// Coefficients, one per column.
    pub x: Vec<f64>,
    /// Numerical rank used.
    pub rank: usize,
    /// Residual after the fit, `r + A x`.
    pub e: Vec<f64>,
    /// Scale of the likelihood at the fit (given, or estimated with the coefficients).
    pub scale: f64,
    /// `-2 ln L` without constants: `sum (e / s)^2` (Gaussian, given scale),
    /// `n ln(RSS / n)` (Gaussian, estimated), `(nu + 1) sum ln(1 + e^2 / (nu s^2))`
    /// (Student-t, given) plus `n ln s^2` (Student-t, estimated).
    pub deviance: f64,
}

const MAX_IRLS: usize = 200;

/// The Student-t scale `s` that maximum likelihood fits to standard Gaussian noise: the
/// root of `E[(nu + 1) e^2 / (nu s^2 + e^2)] = 1`, `e ~ N(0, 1)` (the fixed point of the
/// scale's EM update), by Simpson's rule on `[0, 12]` and bisection.
fn t_scale_of_unit_gaussian(nu: f64) -> f64 {
    let expectation = |s: f64| -> f64 {
        let steps = 2400;
        let h = 12.0 / steps as f64;
        let f = |e: f64| {
            let density = 2.0 * (-0.5 * e * e).exp() / (2.0 * std::f64::consts::PI).sqrt();
            density * (nu + 1.0) * e * e / (nu * s * s + e * e)
        };
        let mut sum = f(0.0) + f(12.0);
        for k in 1..steps {
            sum += f(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        sum * h / 3.0
    };
    // The expectation falls from nu + 1 toward 0 as s grows.
    bisect_root(|s| expectation(s) - 1.0, 1e-3, 10.0, 100)
}

impl Likelihood {
    /// A Gaussian likelihood (`nu` none) or a Student-t with `nu` degrees of freedom.
    pub fn new(nu: Option<f64>) -> Self {
        Likelihood {
            nu,
            unit_scale: nu.map_or(1.0, t_scale_of_unit_gaussian),
        }
    }

    /// The likelihood's scale for Gaussian noise of standard deviation `sigma` (`sigma`
    /// itself under a Gaussian), and back: `sigma_of_scale`.
    pub fn scale_of_sigma(&self, sigma: f64) -> f64 {
        sigma * self.unit_scale
    }

    /// The noise standard deviation a fitted scale stands for (see `scale_of_sigma`).
    pub fn sigma_of_scale(&self, scale: f64) -> f64 {
        scale / self.unit_scale
    }

    /// Whether rows are reweighted (Student-t).
    pub fn is_robust(&self) -> bool {
        self.nu.is_some()
    }

    /// IRLS weight of a residual at scale `s` (1 under a Gaussian).
    pub fn weight(&self, e: f64, s: f64) -> f64 {
        match self.nu {
            None => 1.0,
            Some(nu) => (nu + 1.0) / (nu + (e / s).powi(2)),
        }
    }

    /// Per-row contribution to `-2 ln L` at scale `s`, without constants.
    pub fn rho(&self, e: f64, s: f64) -> f64 {
        match self.nu {
            None => (e / s).powi(2),
            Some(nu) => (nu + 1.0) * (e * e / (nu * s * s)).ln_1p(),
        }
    }

    fn rho_sum(&self, e: &[f64], s: f64) -> f64 {
        e.iter().map(|v| self.rho(*v, s)).sum()
    }

    /// Fits `min -2 ln L(r + A x) + sum_j ridge_j x_j^2 / s^2` over `x`, with the scale
    /// fixed at `scale` or (`None`) estimated jointly by maximum likelihood, floored at
    /// `floor`. Under a Gaussian with a given scale this is one least-squares solve;
    /// under a Student-t, IRLS from unit weights (each step cannot raise the objective).
    pub fn fit(
        &self,
        cols: &[Vec<f64>],
        r: &[f64],
        ridge: &[f64],
        scale: Option<f64>,
        floor: f64,
    ) -> Fit {
        let n = r.len();
        let solve = |w: &[f64]| {
            let sw: Vec<f64> = w.iter().map(|v| v.sqrt()).collect();
            let wc: Vec<Vec<f64>> = cols
                .iter()
                .map(|c| c.iter().zip(&sw).map(|(a, s)| a * s).collect())
                .collect();
            let refs: Vec<&[f64]> = wc.iter().map(Vec::as_slice).collect();
            let neg: Vec<f64> = r.iter().zip(&sw).map(|(a, s)| -a * s).collect();
            let sol = lstsq(&refs, &neg, ridge);
            let raw: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
            let e = residual_after(&raw, &sol.x, r);
            (sol, e)
        };
        let rss = |e: &[f64]| e.iter().map(|v| v * v).sum::<f64>();
        if !self.is_robust() {
            let (sol, e) = solve(&vec![1.0; n]);
            let (scale, deviance) = match scale {
                Some(s) => (s, rss(&e) / (s * s)),
                None => {
                    let v = rss(&e).max(floor * floor * n as f64) / n as f64;
                    (v.sqrt(), n as f64 * v.ln())
                }
            };
            return Fit {
                x: sol.x,
                rank: sol.rank,
                e,
                scale,
                deviance,
            };
        }
        let objective = |e: &[f64], s: f64| -> f64 {
            let fixed = self.rho_sum(e, s);
            match scale {
                Some(_) => fixed,
                None => fixed + n as f64 * (s * s).ln(),
            }
        };
        let (sol, e) = solve(&vec![1.0; n]);
        let rms = (rss(&e) / n as f64).sqrt();
        let starts: Vec<f64> = match scale {
            Some(s) => vec![s],
            // The likelihood may have a wide mode (outliers taken for noise) besides the
            // narrow one; start from the RMS and from the median absolute deviation
            // (normal-consistent), and keep the better.
            None => {
                let mut abs: Vec<f64> = e.iter().map(|v| v.abs()).collect();
                abs.sort_by(f64::total_cmp);
                let mad = 1.4826 * abs[n / 2];
                let mut v = vec![rms.max(floor)];
                if mad > floor && mad < rms {
                    v.push(mad);
                }
                v
            }
        };
        if !(starts[0] > 0.0 && starts[0].is_finite()) {
            // An exact fit: no weights to compute, and nothing to reweigh.
            return Fit {
                x: sol.x,
                rank: sol.rank,
                e,
                scale: 0.0,
                deviance: f64::NEG_INFINITY,
            };
        }
        let irls = |s0: f64| -> Fit {
            let (mut sol, mut e, mut s) = (sol.clone(), e.clone(), s0);
            let mut obj = objective(&e, s);
            for _ in 0..MAX_IRLS {
                let w: Vec<f64> = e.iter().map(|v| self.weight(*v, s)).collect();
                let (next_sol, next_e) = solve(&w);
                let next_s = match scale {
                    Some(s) => s,
                    // The EM update of a Student-t scale.
                    None => {
                        let v = next_e
                            .iter()
                            .map(|e| self.weight(*e, s) * e * e)
                            .sum::<f64>()
                            / n as f64;
                        v.sqrt().max(floor)
                    }
                };
                let next_obj = objective(&next_e, next_s);
                let settled = (obj - next_obj).abs() <= 1e-12 * (1.0 + obj.abs());
                // Each step lowers the objective with the ridge; a rise of the objective
                // without it is at most rounding, so stop rather than take it.
                if next_obj > obj + 1e-9 * (1.0 + obj.abs()) {
                    break;
                }
                sol = next_sol;
                e = next_e;
                s = next_s;
                obj = next_obj;
                if settled {
                    break;
                }
            }
            Fit {
                x: sol.x,
                rank: sol.rank,
                e,
                scale: s,
                deviance: obj,
            }
        };
        starts
            .iter()
            .map(|&s0| irls(s0))
            .reduce(|a, b| if b.deviance < a.deviance { b } else { a })
            .expect("at least one start")
    }

    /// Held-out deviance over all folds when `cols` are refit (with `ridge`, at the fixed
    /// scale `s`) on the other rows: `sum_fold sum_(i in fold) rho(r_i + A_i x_(-f))`.
    /// Under a Gaussian this is the held-out sum of squares over `s^2`.
    pub fn held_out(
        &self,
        cols: &[Vec<f64>],
        ridge: &[f64],
        r: &[f64],
        folds: &[Vec<usize>],
        s: f64,
    ) -> f64 {
        let n = r.len();
        let mut total = 0.0;
        let mut held = vec![false; n];
        for fold in folds {
            held.iter_mut().for_each(|h| *h = false);
            fold.iter().for_each(|&i| held[i] = true);
            let train: Vec<usize> = (0..n).filter(|&i| !held[i]).collect();
            let sub: Vec<Vec<f64>> = cols
                .iter()
                .map(|c| train.iter().map(|&i| c[i]).collect())
                .collect();
            let rt: Vec<f64> = train.iter().map(|&i| r[i]).collect();
            let x = self.fit(&sub, &rt, ridge, Some(s), 0.0).x;
            for &i in fold {
                let e = r[i] + cols.iter().zip(&x).map(|(c, xj)| c[i] * xj).sum::<f64>();
                total += self.rho(e, s);
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line_data() -> (Vec<Vec<f64>>, Vec<f64>) {
        // r = -(1 + 0.5 t) + small wiggle, three rows 5 units off.
        let t: Vec<f64> = (0..30).map(|i| i as f64 / 10.0).collect();
        let r: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let wiggle = 0.05 * if i % 2 == 0 { 1.0 } else { -1.0 };
                let outlier = if i % 10 == 3 { 5.0 } else { 0.0 };
                -(1.0 + 0.5 * t) + wiggle + outlier
            })
            .collect();
        (vec![vec![1.0; 30], t], r)
    }

    #[test]
    fn student_t_ignores_outliers_that_bend_least_squares() {
        let (cols, r) = line_data();
        let gauss = Likelihood::new(None).fit(&cols, &r, &[0.0; 2], None, 1e-9);
        let t = Likelihood::new(Some(4.0)).fit(&cols, &r, &[0.0; 2], None, 1e-9);
        assert!((gauss.x[0] - 1.0).abs() > 0.2, "{:?}", gauss.x);
        assert!(
            (t.x[0] - 1.0).abs() < 0.05 && (t.x[1] - 0.5).abs() < 0.05,
            "{:?}",
            t.x
        );
        // The scale is the wiggle's, not the outliers'.
        assert!(
            t.scale < 0.15 && gauss.scale > 1.0,
            "{} {}",
            t.scale,
            gauss.scale
        );
    }

    #[test]
    fn the_t_scale_of_gaussian_noise_solves_its_em_fixed_point() {
        // Large nu tends to the Gaussian; small nu fits a narrower core.
        let big = t_scale_of_unit_gaussian(1e6);
        assert!((big - 1.0).abs() < 1e-3, "{big}");
        let four = t_scale_of_unit_gaussian(4.0);
        assert!(four > 0.6 && four < 0.95, "{four}");
        // Monte Carlo check of the fixed point with a fixed pseudo-random sample.
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut sum = 0.0;
        let draws = 200_000;
        for _ in 0..draws / 2 {
            let (u1, u2) = (uniform(), uniform());
            let r = (-2.0 * u1.ln()).sqrt();
            for e in [
                r * (2.0 * std::f64::consts::PI * u2).cos(),
                r * (2.0 * std::f64::consts::PI * u2).sin(),
            ] {
                sum += 5.0 * e * e / (4.0 * four * four + e * e);
            }
        }
        let mean = sum / draws as f64;
        assert!((mean - 1.0).abs() < 0.01, "{mean}");
    }

    #[test]
    fn gaussian_deviance_matches_its_definition() {
        let (cols, r) = line_data();
        let g = Likelihood::new(None);
        let est = g.fit(&cols, &r, &[0.0; 2], None, 1e-9);
        let rss: f64 = est.e.iter().map(|v| v * v).sum();
        assert!((est.deviance - 30.0 * (rss / 30.0).ln()).abs() < 1e-9);
        let fixed = g.fit(&cols, &r, &[0.0; 2], Some(0.5), 0.0);
        assert!((fixed.deviance - rss / 0.25).abs() < 1e-9);
    }

    #[test]
    fn irls_reaches_a_stationary_point_of_the_t_likelihood() {
        let (cols, r) = line_data();
        let lik = Likelihood::new(Some(4.0));
        let f = lik.fit(&cols, &r, &[0.0; 2], Some(0.1), 0.0);
        // Gradient of sum rho over x: sum rho'(e_i) a_ij = 0 at the optimum.
        for c in &cols {
            let terms: Vec<f64> =
                f.e.iter()
                    .zip(c)
                    .map(|(e, a)| 2.0 * e * lik.weight(*e, 0.1) / 0.01 * a)
                    .collect();
            let g: f64 = terms.iter().sum();
            let size: f64 = terms.iter().map(|t| t.abs()).sum();
            assert!(
                g.abs() < 1e-5 * size,
                "gradient {g} of terms summing to {size}"
            );
        }
        // And no nearby point is better.
        for d in [1e-3, -1e-3] {
            for j in 0..2 {
                let mut x = f.x.clone();
                x[j] += d;
                let e: Vec<f64> = (0..30)
                    .map(|i| r[i] + cols[0][i] * x[0] + cols[1][i] * x[1])
                    .collect();
                assert!(lik.rho_sum(&e, 0.1) >= f.deviance - 1e-9);
            }
        }
    }

    #[test]
    fn held_out_under_a_gaussian_is_the_held_out_sum_of_squares() {
        let (cols, r) = line_data();
        let folds: Vec<Vec<usize>> = (0..3).map(|f| (f * 10..f * 10 + 10).collect()).collect();
        let g = Likelihood::new(None).held_out(&cols, &[0.0; 2], &r, &folds, 2.0);
        // Reference: a straight line through the other rows by the normal equations.
        let t = &cols[1];
        let mut sse = 0.0;
        for fold in &folds {
            let train: Vec<usize> = (0..30).filter(|i| !fold.contains(i)).collect();
            let m = train.len() as f64;
            let mean_t = train.iter().map(|&i| t[i]).sum::<f64>() / m;
            let mean_r = train.iter().map(|&i| r[i]).sum::<f64>() / m;
            let cov: f64 = train
                .iter()
                .map(|&i| (t[i] - mean_t) * (r[i] - mean_r))
                .sum();
            let var: f64 = train.iter().map(|&i| (t[i] - mean_t).powi(2)).sum();
            // r + a + b t = 0 in the least-squares sense.
            let b = -cov / var;
            let a = -mean_r - b * mean_t;
            sse += fold
                .iter()
                .map(|&i| (r[i] + a + b * t[i]).powi(2))
                .sum::<f64>();
        }
        assert!((g * 4.0 - sse).abs() < 1e-9 * sse, "{g} {sse}");
    }
}
