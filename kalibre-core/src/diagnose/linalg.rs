//! Small dense linear algebra for the diagnosis: pivoted Householder least squares with an
//! optional ridge, orthonormal bases, eigenvalues of small symmetric matrices, and the
//! bisection the likelihood estimates solve their one-dimensional equations with.
//!
//! Matrices are held as columns (`Vec<Vec<f64>>`): the diagnosis works column by column
//! (current parameters, then one hypothesis's parameters), and the problems are small
//! (hundreds of rows, tens of columns), so no dependency is worth its build time.

/// Relative tolerance under which a pivot (on unit-norm columns) counts as zero.
pub(crate) const RANK_TOL: f64 = 1e-10;

/// A least-squares solution and the numerical rank it used.
#[derive(Debug, Clone)]
pub(crate) struct LeastSquares {
    /// One value per column; columns left out of the basis (zero or dependent) get 0.
    pub x: Vec<f64>,
    /// Numerical rank of the (ridge-augmented) matrix.
    pub rank: usize,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Solves `min ||A x - b||^2 + sum_j ridge_j x_j^2` with `A` given by its columns.
///
/// Columns are scaled to unit norm first (parameters of very different units then pivot
/// fairly); Householder QR with column pivoting stops at the first pivot below
/// [`RANK_TOL`], so exactly dependent columns get 0 instead of a huge cancelling pair.
/// The ridge enters as extra rows, which keeps the factorisation as stable as plain QR.
pub(crate) fn lstsq(cols: &[&[f64]], b: &[f64], ridge: &[f64]) -> LeastSquares {
    let n = cols.len();
    let m = b.len();
    let scale: Vec<f64> = cols.iter().map(|c| norm(c)).collect();
    // Active columns: non-zero ones (a zero column cannot explain anything).
    let active: Vec<usize> = (0..n).filter(|&j| scale[j] > 0.0).collect();
    let with_ridge: Vec<usize> = active.iter().copied().filter(|&j| ridge[j] > 0.0).collect();
    let rows = m + with_ridge.len();
    let mut a: Vec<Vec<f64>> = active
        .iter()
        .map(|&j| {
            let mut c: Vec<f64> = cols[j].iter().map(|v| v / scale[j]).collect();
            c.resize(rows, 0.0);
            if let Some(k) = with_ridge.iter().position(|&r| r == j) {
                c[m + k] = ridge[j].sqrt() / scale[j];
            }
            c
        })
        .collect();
    let mut rhs = b.to_vec();
    rhs.resize(rows, 0.0);
    let mut perm: Vec<usize> = (0..active.len()).collect();
    let steps = active.len().min(rows);
    let mut rank = 0;
    for k in 0..steps {
        let (best, best_norm) = (k..a.len())
            .map(|j| (j, norm(&a[j][k..])))
            .fold((k, -1.0), |acc, c| if c.1 > acc.1 { c } else { acc });
        if best_norm <= RANK_TOL {
            break;
        }
        a.swap(k, best);
        perm.swap(k, best);
        let alpha = if a[k][k] >= 0.0 {
            -best_norm
        } else {
            best_norm
        };
        let mut v = a[k][k..].to_vec();
        v[0] -= alpha;
        let vv = dot(&v, &v);
        if vv > 0.0 {
            for col in a.iter_mut().skip(k) {
                let t = 2.0 * dot(&v, &col[k..]) / vv;
                col[k..].iter_mut().zip(&v).for_each(|(c, vi)| *c -= t * vi);
            }
            let t = 2.0 * dot(&v, &rhs[k..]) / vv;
            rhs[k..].iter_mut().zip(&v).for_each(|(c, vi)| *c -= t * vi);
        }
        rank = k + 1;
    }
    // Back substitution on the leading `rank` x `rank` triangle.
    let mut z = vec![0.0; rank];
    for i in (0..rank).rev() {
        let s: f64 = (i + 1..rank).map(|j| a[j][i] * z[j]).sum();
        z[i] = (rhs[i] - s) / a[i][i];
    }
    let mut x = vec![0.0; n];
    for (i, zi) in z.iter().enumerate() {
        let j = active[perm[i]];
        x[j] = zi / scale[j];
    }
    LeastSquares { x, rank }
}

/// The root of `f` in `[lo, hi]` by `steps` bisections, for an `f` positive below its
/// root and not above it: the midpoint of the last bracket.
pub(crate) fn bisect_root(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64, steps: usize) -> f64 {
    for _ in 0..steps {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// `b + A x` for `A` given by columns.
pub(crate) fn residual_after(cols: &[&[f64]], x: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = b.to_vec();
    for (c, xj) in cols.iter().zip(x) {
        if *xj != 0.0 {
            out.iter_mut().zip(c.iter()).for_each(|(o, v)| *o += xj * v);
        }
    }
    out
}

/// Removes from `v` its components along the orthonormal `basis` (twice, which keeps
/// classical Gram-Schmidt as accurate as Householder for our sizes).
pub(crate) fn project_out(basis: &[Vec<f64>], v: &mut [f64]) {
    for _ in 0..2 {
        for q in basis {
            let t = dot(q, v);
            v.iter_mut().zip(q).for_each(|(a, b)| *a -= t * b);
        }
    }
}

/// An orthonormal basis of the span of `cols`: columns are normalised first, and one whose
/// part outside the basis so far is below `tol` (relative) is dropped as dependent.
pub(crate) fn orthonormal_basis(cols: &[Vec<f64>], tol: f64) -> Vec<Vec<f64>> {
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for c in cols {
        let n = norm(c);
        if n == 0.0 {
            continue;
        }
        let mut v: Vec<f64> = c.iter().map(|x| x / n).collect();
        project_out(&basis, &mut v);
        let r = norm(&v);
        if r > tol {
            v.iter_mut().for_each(|x| *x /= r);
            basis.push(v);
        }
    }
    basis
}

/// Gram matrix `A^T B` of two column sets.
pub(crate) fn gram(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    a.iter()
        .map(|x| b.iter().map(|y| dot(x, y)).collect())
        .collect()
}

/// Eigenvalues of a small symmetric matrix by cyclic Jacobi rotations, ascending.
pub(crate) fn sym_eigenvalues(mut a: Vec<Vec<f64>>) -> Vec<f64> {
    let n = a.len();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (kp, kq) = (row[p], row[q]);
                    row[p] = c * kp - s * kq;
                    row[q] = s * kp + c * kq;
                }
                let (lo, hi) = a.split_at_mut(q);
                for (pk, qk) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                    let (x, y) = (*pk, *qk);
                    *pk = c * x - s * y;
                    *qk = s * x + c * y;
                }
            }
        }
    }
    let mut ev: Vec<f64> = (0..n).map(|i| a[i][i]).collect();
    ev.sort_by(f64::total_cmp);
    ev
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn lstsq_solves_an_overdetermined_system_exactly() {
        // b = 2 c0 - 3 c1 with columns of very different scale.
        let c0 = vec![1.0, 2.0, 3.0, 4.0];
        let c1 = vec![1e-3, -2e-3, 5e-3, 1e-3];
        let b: Vec<f64> = c0.iter().zip(&c1).map(|(a, c)| 2.0 * a - 3.0 * c).collect();
        let s = lstsq(&[&c0, &c1], &b, &[0.0, 0.0]);
        assert_eq!(s.rank, 2);
        assert_abs_diff_eq!(s.x[0], 2.0, epsilon = 1e-10);
        assert_abs_diff_eq!(s.x[1], -3.0, epsilon = 1e-7);
    }

    #[test]
    fn lstsq_drops_a_dependent_column_and_still_fits() {
        let c0 = vec![1.0, 0.0, 1.0];
        let c1 = vec![2.0, 0.0, 2.0];
        let c2 = vec![0.0, 1.0, 0.0];
        let b = vec![3.0, 1.0, 3.0];
        let s = lstsq(&[&c0, &c1, &c2], &b, &[0.0; 3]);
        assert_eq!(s.rank, 2);
        let r = residual_after(
            &[&c0, &c1, &c2],
            &s.x,
            &b.iter().map(|v| -v).collect::<Vec<_>>(),
        );
        assert!(r.iter().all(|v| v.abs() < 1e-12), "{r:?}");
        assert!(s.x.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn ridge_matches_the_closed_form_for_one_column() {
        // min (x c - b)^2 + l x^2  =>  x = c.b / (c.c + l)
        let c = vec![1.0, 2.0, 2.0];
        let b = vec![1.0, 1.0, 1.0];
        let s = lstsq(&[&c], &b, &[4.0]);
        assert_abs_diff_eq!(s.x[0], 5.0 / 13.0, epsilon = 1e-12);
    }

    #[test]
    fn jacobi_eigenvalues_of_a_known_matrix() {
        // [[2,1],[1,2]] has eigenvalues 1 and 3; a diagonal block adds 5.
        let ev = sym_eigenvalues(vec![
            vec![2.0, 1.0, 0.0],
            vec![1.0, 2.0, 0.0],
            vec![0.0, 0.0, 5.0],
        ]);
        assert_abs_diff_eq!(ev[0], 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(ev[1], 3.0, epsilon = 1e-12);
        assert_abs_diff_eq!(ev[2], 5.0, epsilon = 1e-12);
    }

    #[test]
    fn basis_is_orthonormal_and_drops_dependent_columns() {
        let cols = vec![
            vec![1.0, 1.0, 0.0],
            vec![2.0, 2.0, 0.0],
            vec![1.0, 0.0, 1.0],
        ];
        let q = orthonormal_basis(&cols, 1e-8);
        assert_eq!(q.len(), 2);
        let g = gram(&q, &q);
        assert_abs_diff_eq!(g[0][0], 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(g[0][1], 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(g[1][1], 1.0, epsilon = 1e-12);
    }
}
