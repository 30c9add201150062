//! The crate's little dense Cholesky algebra: a factor (plain, or with a jitter raised
//! until it works, as the Gaussian process needs), one-right-hand-side solves for the
//! loop's small systems, and triangular solves with many right-hand sides. Row-major
//! `Vec<f64>`, sequential loops: the same bits at any thread count.

/// Jitter added to the diagonal, in turn, until the factorisation succeeds. The kernel's
/// diagonal is 1 plus the nugget, so these are relative to the signal variance.
const JITTERS: [f64; 7] = [0.0, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2, 1.0];

/// Lower Cholesky factor `l` (row-major `n x n`, upper part zero) of `a + jitter I`, with
/// the smallest jitter of [`JITTERS`] that works; `None` when even the largest fails
/// (a non-finite matrix).
pub(crate) fn cholesky_jittered(a: &[f64], n: usize) -> Option<(Vec<f64>, f64)> {
    let mut l = vec![0.0; n * n];
    for &jitter in &JITTERS {
        if cholesky_into(a, n, jitter, &mut l) {
            return Some((l, jitter));
        }
    }
    None
}

/// Lower Cholesky factor of the symmetric positive definite `k x k` matrix `a` (row
/// major); none when it is not positive definite.
pub(crate) fn cholesky(a: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; k * k];
    cholesky_into(a, k, 0.0, &mut l).then_some(l)
}

/// Solves `L L^T x = b` with the factor from [`cholesky`].
pub(crate) fn cholesky_solve(l: &[f64], k: usize, b: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; k];
    for i in 0..k {
        y[i] = (b[i] - (0..i).map(|m| l[i * k + m] * y[m]).sum::<f64>()) / l[i * k + i];
    }
    let mut x = vec![0.0; k];
    for i in (0..k).rev() {
        x[i] = (y[i] - (i + 1..k).map(|m| l[m * k + i] * x[m]).sum::<f64>()) / l[i * k + i];
    }
    x
}

/// Factors `a + jitter I` into `l`; false when a pivot is not positive and finite.
fn cholesky_into(a: &[f64], n: usize, jitter: f64, l: &mut [f64]) -> bool {
    l.iter_mut().for_each(|v| *v = 0.0);
    for j in 0..n {
        for i in j..n {
            // Rows i and j of l are contiguous up to column j: a cache-friendly dot product.
            let dot: f64 = (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum();
            let mut s = a[i * n + j] - dot;
            if i == j {
                s += jitter;
                if !(s > 0.0 && s.is_finite()) {
                    return false;
                }
                l[j * n + j] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    true
}

/// `2 sum ln l_ii`: the log-determinant of the factored matrix.
pub(crate) fn log_det(l: &[f64], n: usize) -> f64 {
    2.0 * (0..n).map(|i| l[i * n + i].ln()).sum::<f64>()
}

/// Solves `l y = b` in place for `m` right-hand sides (`b` row-major `n x m`: one row per
/// equation, so each update runs along a contiguous row).
pub(crate) fn forward_solve(l: &[f64], n: usize, b: &mut [f64], m: usize) {
    for i in 0..n {
        let (done, rest) = b.split_at_mut(i * m);
        let row = &mut rest[..m];
        for k in 0..i {
            let lik = l[i * n + k];
            if lik != 0.0 {
                for (r, y) in row.iter_mut().zip(&done[k * m..(k + 1) * m]) {
                    *r -= lik * y;
                }
            }
        }
        let d = l[i * n + i];
        row.iter_mut().for_each(|r| *r /= d);
    }
}

/// Solves `l^T x = y` in place for `m` right-hand sides (row-major `n x m`).
pub(crate) fn backward_solve(l: &[f64], n: usize, y: &mut [f64], m: usize) {
    for i in (0..n).rev() {
        let (head, done) = y.split_at_mut((i + 1) * m);
        let row = &mut head[i * m..];
        for k in i + 1..n {
            let lki = l[k * n + i];
            if lki != 0.0 {
                let xk = &done[(k - i - 1) * m..(k - i) * m];
                for (r, x) in row.iter_mut().zip(xk) {
                    *r -= lki * x;
                }
            }
        }
        let d = l[i * n + i];
        row.iter_mut().for_each(|r| *r /= d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system_and_jitters_a_singular_one() {
        // a = [[4, 2], [2, 3]]; solve a x = [2, 5] for x = [-0.5, 2].
        let a = [4.0, 2.0, 2.0, 3.0];
        let (l, jitter) = cholesky_jittered(&a, 2).unwrap();
        assert_eq!(jitter, 0.0);
        assert!((log_det(&l, 2) - 8f64.ln()).abs() < 1e-12);
        let mut b = [2.0, 5.0];
        forward_solve(&l, 2, &mut b, 1);
        backward_solve(&l, 2, &mut b, 1);
        assert!(
            (b[0] + 0.5).abs() < 1e-12 && (b[1] - 2.0).abs() < 1e-12,
            "{b:?}"
        );

        let ones = [1.0; 9];
        let (_, jitter) = cholesky_jittered(&ones, 3).unwrap();
        assert!(jitter > 0.0);
        assert!(cholesky_jittered(&[f64::NAN], 1).is_none());
    }
}
