//! Dense LU factorisation with partial pivoting, for the coarsest multigrid level.

/// Dense LU with partial pivoting of the coarsest operator.
#[derive(Debug, Clone)]
pub(crate) struct DenseLu {
    m: usize,
    lu: Vec<f64>,
    piv: Vec<usize>,
}

impl DenseLu {
    /// Factorises the row-major `m x m` matrix `a`.
    pub fn new(m: usize, mut a: Vec<f64>) -> Self {
        let mut piv = vec![0; m];
        for k in 0..m {
            let p = (k..m)
                .max_by(|&i, &j| a[i * m + k].abs().total_cmp(&a[j * m + k].abs()))
                .unwrap_or(k);
            piv[k] = p;
            if p != k {
                for j in 0..m {
                    a.swap(k * m + j, p * m + j);
                }
            }
            let d = a[k * m + k];
            if d == 0.0 {
                continue; // singular direction: left to the smoother
            }
            for i in k + 1..m {
                let f = a[i * m + k] / d;
                if f != 0.0 {
                    a[i * m + k] = f;
                    for j in k + 1..m {
                        a[i * m + j] -= f * a[k * m + j];
                    }
                }
            }
        }
        DenseLu { m, lu: a, piv }
    }

    /// Solves in place (`x` holds the right-hand side on entry).
    pub fn solve(&self, x: &mut [f64]) {
        let (m, a) = (self.m, &self.lu);
        for k in 0..m {
            x.swap(k, self.piv[k]);
        }
        for i in 0..m {
            let mut v = x[i];
            for j in 0..i {
                v -= a[i * m + j] * x[j];
            }
            x[i] = v;
        }
        for i in (0..m).rev() {
            let mut v = x[i];
            for j in i + 1..m {
                v -= a[i * m + j] * x[j];
            }
            let d = a[i * m + i];
            x[i] = if d != 0.0 { v / d } else { 0.0 };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_system_that_needs_pivoting() {
        // A zero leading entry forces a row swap.
        let a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let x_true = [1.0, -2.0, 3.0];
        let mut b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a[i * 3 + j] * x_true[j]).sum())
            .collect();
        DenseLu::new(3, a).solve(&mut b);
        for (x, t) in b.iter().zip(x_true) {
            assert!((x - t).abs() < 1e-12, "{x} vs {t}");
        }
    }
}
