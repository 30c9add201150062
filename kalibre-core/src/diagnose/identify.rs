//! Identifiability: can the data tell a hypothesis apart from the current parameters and
//! from the other hypotheses?

use super::linalg::{gram, orthonormal_basis, project_out, sym_eigenvalues};

/// Tolerance under which a column left after projection counts as dependent.
const BASIS_TOL: f64 = 1e-8;

/// The part of a hypothesis outside the current parameters' span.
pub(crate) struct Perp {
    /// Independence: smallest singular value of the unit-norm columns with the current
    /// parameters' span removed (1: orthogonal to it and to each other; 0: dependent).
    pub independence: f64,
    /// Orthonormal basis of that part (empty when dependent).
    pub basis: Vec<Vec<f64>>,
}

/// Measures a hypothesis (`cols`) against the orthonormal basis `qj` of the current
/// parameters' columns. The smallest singular value covers both collinearity with the
/// current parameters and among the hypothesis's own columns; for one column it is the
/// sine of its angle to the current parameters' span.
pub(crate) fn perp(qj: &[Vec<f64>], cols: &[Vec<f64>]) -> Perp {
    let p: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| {
            let n = c.iter().map(|v| v * v).sum::<f64>().sqrt();
            if n == 0.0 {
                return c.clone();
            }
            let mut v: Vec<f64> = c.iter().map(|x| x / n).collect();
            project_out(qj, &mut v);
            v
        })
        .collect();
    let ev = sym_eigenvalues(gram(&p, &p));
    let independence = ev.first().map_or(0.0, |l| l.max(0.0).sqrt()).min(1.0);
    let basis = orthonormal_basis(&p, BASIS_TOL);
    Perp {
        independence,
        basis: if basis.len() == cols.len() {
            basis
        } else {
            Vec::new()
        },
    }
}

/// Sine of the largest principal angle between two spans of equal dimension: near 0 when
/// they are the same directions (the data cannot tell the two hypotheses apart). `None`
/// when the dimensions differ (a nested or overlapping hypothesis stays distinguishable:
/// the complexity penalty arbitrates) or a basis is empty.
pub(crate) fn span_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> Option<f64> {
    if a.is_empty() || a.len() != b.len() {
        return None;
    }
    let m = gram(a, b);
    let q = m.len();
    let mtm: Vec<Vec<f64>> = (0..q)
        .map(|i| {
            (0..q)
                .map(|j| (0..q).map(|k| m[k][i] * m[k][j]).sum())
                .collect()
        })
        .collect();
    let cos2 = sym_eigenvalues(mtm).first().copied().unwrap_or(0.0);
    Some((1.0 - cos2.clamp(0.0, 1.0)).sqrt())
}

/// Whether every direction of `inner` lies in the span of `outer` (both orthonormal
/// bases), to within a sine of `tol`: a nested hypothesis, the same explanation with
/// more freedom. False when either basis is empty.
pub(crate) fn spans_within(inner: &[Vec<f64>], outer: &[Vec<f64>], tol: f64) -> bool {
    if inner.is_empty() || outer.is_empty() {
        return false;
    }
    inner.iter().all(|v| {
        let inside: f64 = outer
            .iter()
            .map(|q| v.iter().zip(q).map(|(a, b)| a * b).sum::<f64>().powi(2))
            .sum();
        (1.0 - inside.clamp(0.0, 1.0)).sqrt() < tol
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn independence_is_the_sine_of_the_angle_for_one_column() {
        let qj = orthonormal_basis(&[vec![1.0, 0.0, 0.0]], BASIS_TOL);
        let a = 0.3f64;
        let p = perp(&qj, &[vec![a.cos(), a.sin(), 0.0]]);
        assert_abs_diff_eq!(p.independence, a.sin(), epsilon = 1e-12);
    }

    #[test]
    fn same_plane_has_zero_distance_and_different_planes_do_not() {
        let a = orthonormal_basis(
            &[vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 1.0, 0.0, 0.0]],
            BASIS_TOL,
        );
        let b = orthonormal_basis(
            &[vec![1.0, 1.0, 0.0, 0.0], vec![1.0, -2.0, 0.0, 0.0]],
            BASIS_TOL,
        );
        let c = orthonormal_basis(
            &[vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]],
            BASIS_TOL,
        );
        assert_abs_diff_eq!(span_distance(&a, &b).unwrap(), 0.0, epsilon = 1e-7);
        assert_abs_diff_eq!(span_distance(&a, &c).unwrap(), 1.0, epsilon = 1e-12);
        assert!(span_distance(&a, &c[..1]).is_none());
    }
}
