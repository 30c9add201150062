//! One scenario's data made ready for the process: unit inputs, standardised outputs,
//! the affine trend and its residuals; then the process's weights once the
//! hyperparameters are chosen.

use super::hyper;
use super::{ScenarioModel, AFFINE_RMS, TREND_RIDGE_REL};
use crate::linalg::{backward_solve, cholesky_jittered, forward_solve};
use crate::{Error, ParamSpace, Result, Sample};

/// One scenario's data while fitting.
pub(super) struct Prepared {
    pub z: Vec<f64>,
    pub inv_weight: Vec<f64>,
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
    pub trend: Vec<f64>,
    pub residuals: Vec<f64>,
    /// Outputs the trend leaves unexplained: they inform the hyperparameters.
    pub informative: Vec<usize>,
}

/// Unit inputs, standardised outputs, trend and residuals of one scenario's samples.
pub(super) fn prepare(
    space: &ParamSpace,
    group: &[(&Sample, f64)],
    active: &[usize],
    m: usize,
) -> Result<Prepared> {
    let (n, d, p) = (group.len(), active.len(), active.len() + 1);
    let mut z = Vec::with_capacity(n * d);
    for (s, _) in group {
        let unit = space.to_unit(&s.params)?;
        z.extend(active.iter().map(|&i| unit[i]));
    }
    let inv_weight: Vec<f64> = group.iter().map(|(_, w)| 1.0 / w).collect();
    let nf = n as f64;
    let mut mean = vec![0.0; m];
    for (s, _) in group {
        mean.iter_mut()
            .zip(&s.outputs)
            .for_each(|(a, y)| *a += y / nf);
    }
    let mut std = vec![0.0; m];
    for (s, _) in group {
        for ((v, y), mu) in std.iter_mut().zip(&s.outputs).zip(&mean) {
            *v += (y - mu) * (y - mu) / nf;
        }
    }
    for (v, mu) in std.iter_mut().zip(&mean) {
        *v = v.sqrt();
        // A constant output (up to rounding) keeps its scale.
        if *v <= 1e-12 * mu.abs() || *v == 0.0 {
            *v = 1.0;
        }
    }
    let standard: Vec<f64> = (group.iter())
        .flat_map(|(s, _)| {
            s.outputs
                .iter()
                .zip(&mean)
                .zip(&std)
                .map(|((y, mu), sd)| (y - mu) / sd)
        })
        .collect();

    // Weighted ridge least squares for the trend, features [1, z - 0.5]: the normal
    // equations are (d + 1) square, whatever the number of samples.
    let feature = |i: usize| {
        std::iter::once(1.0)
            .chain(z[i * d..(i + 1) * d].iter().map(|u| u - 0.5))
            .collect::<Vec<f64>>()
    };
    let mut a = vec![0.0; p * p];
    let mut b = vec![0.0; p * m];
    let mut total_weight = 0.0;
    for (i, &(_, w)) in group.iter().enumerate() {
        let phi = feature(i);
        total_weight += w;
        for r in 0..p {
            for c in 0..p {
                a[r * p + c] += w * phi[r] * phi[c];
            }
            for k in 0..m {
                b[r * m + k] += w * phi[r] * standard[i * m + k];
            }
        }
    }
    // The intercept is not shrunk: one sample fixes it.
    let ridge = TREND_RIDGE_REL * total_weight;
    for r in 1..p {
        a[r * p + r] += ridge;
    }
    let (l, _) = cholesky_jittered(&a, p)
        .ok_or_else(|| Error::Fit("the trend's normal equations are not finite".into()))?;
    let solve = |mut rhs: Vec<f64>| {
        forward_solve(&l, p, &mut rhs, m);
        backward_solve(&l, p, &mut rhs, m);
        rhs
    };
    let mut trend = solve(b.clone());
    // Iterated ridge: two refinement steps towards least squares remove the ridge's bias
    // along well-determined directions (1e-6 becomes 1e-18) and add nothing along
    // undetermined ones, whose minimum-norm slope stays 0.
    for _ in 0..2 {
        let mut rest = b.clone();
        for r in 0..p {
            for c in 0..p {
                let arc = a[r * p + c] - if r == c && r > 0 { ridge } else { 0.0 };
                for k in 0..m {
                    rest[r * m + k] -= arc * trend[c * m + k];
                }
            }
        }
        let step = solve(rest);
        trend.iter_mut().zip(step).for_each(|(t, s)| *t += s);
    }

    let mut residuals = standard;
    for i in 0..n {
        let phi = feature(i);
        for k in 0..m {
            let fit: f64 = (0..p).map(|r| phi[r] * trend[r * m + k]).sum();
            residuals[i * m + k] -= fit;
        }
    }
    let informative = (0..m)
        .filter(|&k| {
            let ss: f64 = (0..n).map(|i| residuals[i * m + k].powi(2)).sum();
            (ss / nf).sqrt() > AFFINE_RMS
        })
        .collect();
    Ok(Prepared {
        z,
        inv_weight,
        mean,
        std,
        trend,
        residuals,
        informative,
    })
}

/// The process of one scenario at the chosen hyperparameters: `alpha = K^-1 r`.
pub(super) fn finish(
    p: Prepared,
    d: usize,
    m: usize,
    lengths: &[f64],
    nugget: f64,
) -> Result<ScenarioModel> {
    let n = p.inv_weight.len();
    let k = hyper::kernel_matrix(&p.z, &p.inv_weight, d, lengths, nugget);
    let (l, _) = cholesky_jittered(&k, n)
        .ok_or_else(|| Error::Fit("the kernel matrix is not finite".into()))?;
    let mut alpha = p.residuals;
    forward_solve(&l, n, &mut alpha, m);
    backward_solve(&l, n, &mut alpha, m);
    let scaled = (p.z.chunks_exact(d.max(1)))
        .flat_map(|row| row.iter().zip(lengths).map(|(u, l)| u / l))
        .collect();
    Ok(ScenarioModel {
        scaled,
        mean: p.mean,
        std: p.std,
        trend: p.trend,
        alpha,
    })
}
