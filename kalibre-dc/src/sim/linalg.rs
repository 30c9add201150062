//! Matrix-free Krylov solvers: preconditioned CG (symmetric pressure system) and
//! right-preconditioned BiCGSTAB (advection-diffusion), with a Jacobi or a multigrid
//! preconditioner. Vector operations run on rayon in fixed chunks, and
//! every reduction sums the per-chunk partial sums in chunk order, so results are
//! bit-identical at any thread count.

use rayon::prelude::*;

/// Chunk length of parallel vector operations (fixed: it defines the summation order).
pub(crate) const CHUNK: usize = 8192;

/// A linear operator on cell vectors with a Jacobi preconditioner.
pub(crate) trait Operator: Sync {
    /// `y = A x`.
    fn apply(&self, x: &[f64], y: &mut [f64]);
    /// `1 / diag(A)` (1 on rows that are identities).
    fn inv_diag(&self) -> &[f64];
}

/// A preconditioner: `z ~ A^-1 r` (a fixed linear map; it may keep scratch space).
pub(crate) trait Precond {
    /// `z = M^-1 r`.
    fn apply(&mut self, r: &[f64], z: &mut [f64]);
}

/// Diagonal (Jacobi) preconditioning.
pub(crate) struct Jacobi<'a>(pub &'a [f64]);

impl Precond for Jacobi<'_> {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        z.par_chunks_mut(CHUNK)
            .zip(r.par_chunks(CHUNK).zip(self.0.par_chunks(CHUNK)))
            .for_each(|(z, (r, m))| {
                for i in 0..z.len() {
                    z[i] = r[i] * m[i];
                }
            });
    }
}

/// Outcome of one linear solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveStats {
    /// Iterations taken.
    pub iterations: usize,
    /// Final residual norm relative to the right-hand side norm.
    pub rel_residual: f64,
}

/// Deterministic dot product.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let parts: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>())
        .collect();
    parts.iter().sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Per-chunk partial sums added in chunk order (deterministic at any thread count).
fn sum_parts<const K: usize>(parts: Vec<[f64; K]>) -> [f64; K] {
    parts.iter().fold([0.0; K], |mut acc, p| {
        for k in 0..K {
            acc[k] += p[k];
        }
        acc
    })
}

/// The residual `b - A x` of the initial guess, and `|b|` (floored above zero) for the
/// relative stopping test.
fn initial_residual(op: &dyn Operator, b: &[f64], x: &[f64]) -> (Vec<f64>, f64) {
    let mut r = vec![0.0; b.len()];
    op.apply(x, &mut r);
    r.par_iter_mut()
        .zip(b.par_iter())
        .for_each(|(r, b)| *r = b - *r);
    (r, norm(b).max(f64::MIN_POSITIVE))
}

/// Preconditioned conjugate gradients; `x` holds the initial guess and the answer.
pub(crate) fn pcg(
    op: &dyn Operator,
    pc: &mut dyn Precond,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
) -> SolveStats {
    let n = b.len();
    let (mut r, bnorm) = initial_residual(op, b, x);
    let mut z = vec![0.0; n];
    pc.apply(&r, &mut z);
    let mut p = z.clone();
    let mut ap = vec![0.0; n];
    let mut rz = dot(&r, &z);
    let mut rel = norm(&r) / bnorm;
    let mut it = 0;
    while rel > tol && it < max_iter {
        op.apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap <= 0.0 || !pap.is_finite() {
            break;
        }
        let alpha = rz / pap;
        // The update and the new residual norm in one pass.
        let [rr] = sum_parts(
            x.par_chunks_mut(CHUNK)
                .zip(r.par_chunks_mut(CHUNK))
                .zip(p.par_chunks(CHUNK).zip(ap.par_chunks(CHUNK)))
                .map(|((x, r), (p, ap))| {
                    let mut rr = 0.0;
                    for i in 0..x.len() {
                        x[i] += alpha * p[i];
                        r[i] -= alpha * ap[i];
                        rr += r[i] * r[i];
                    }
                    [rr]
                })
                .collect(),
        );
        it += 1;
        rel = rr.sqrt() / bnorm;
        if rel <= tol {
            break;
        }
        pc.apply(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_chunks_mut(CHUNK)
            .zip(z.par_chunks(CHUNK))
            .for_each(|(p, z)| {
                for i in 0..p.len() {
                    p[i] = z[i] + beta * p[i];
                }
            });
    }
    SolveStats {
        iterations: it,
        rel_residual: rel,
    }
}

/// Restarts of [`bicgstab`] after a breakdown before it gives up.
const MAX_RESTARTS: usize = 8;

/// Right-preconditioned BiCGSTAB; `x` holds the initial guess and the answer. A breakdown
/// (a zero `r0 . r`, `r0 . v` or `omega`, e.g. for a sensor in a stagnant room corner)
/// restarts from the current answer with its residual as the new shadow vector, as
/// Saad's *Iterative Methods* (sec. 7.4) advises, rather than failing.
pub(crate) fn bicgstab(
    op: &dyn Operator,
    pc: &mut dyn Precond,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
) -> SolveStats {
    let mut total = SolveStats {
        iterations: 0,
        rel_residual: f64::INFINITY,
    };
    for _ in 0..=MAX_RESTARTS {
        let (stats, broke_down) = bicgstab_once(op, pc, b, x, tol, max_iter - total.iterations);
        total.iterations += stats.iterations;
        total.rel_residual = stats.rel_residual;
        let progressed = stats.iterations > 0;
        if !broke_down || !progressed || total.rel_residual <= tol || total.iterations >= max_iter {
            break;
        }
    }
    total
}

/// One BiCGSTAB cycle; also says whether it stopped on a breakdown.
fn bicgstab_once(
    op: &dyn Operator,
    pc: &mut dyn Precond,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
) -> (SolveStats, bool) {
    let n = b.len();
    let (mut r, bnorm) = initial_residual(op, b, x);
    let r0 = r.clone();
    let (mut rho, mut alpha, mut omega) = (1.0, 1.0, 1.0);
    let mut v = vec![0.0; n];
    let mut p = vec![0.0; n];
    let mut phat = vec![0.0; n];
    let mut s = vec![0.0; n];
    let mut shat = vec![0.0; n];
    let mut t = vec![0.0; n];
    let mut rel = norm(&r) / bnorm;
    let mut r0r = dot(&r0, &r);
    let mut it = 0;
    let mut broke_down = false;
    while rel > tol && it < max_iter {
        let rho_new = r0r;
        if rho_new == 0.0 || !rho_new.is_finite() {
            broke_down = true;
            break;
        }
        let beta = (rho_new / rho) * (alpha / omega);
        rho = rho_new;
        p.par_chunks_mut(CHUNK)
            .zip(r.par_chunks(CHUNK).zip(v.par_chunks(CHUNK)))
            .for_each(|(p, (r, v))| {
                for i in 0..p.len() {
                    p[i] = r[i] + beta * (p[i] - omega * v[i]);
                }
            });
        pc.apply(&p, &mut phat);
        op.apply(&phat, &mut v);
        let r0v = dot(&r0, &v);
        if r0v == 0.0 || !r0v.is_finite() {
            broke_down = true;
            break;
        }
        alpha = rho / r0v;
        let [ss] = sum_parts(
            s.par_chunks_mut(CHUNK)
                .zip(r.par_chunks(CHUNK).zip(v.par_chunks(CHUNK)))
                .map(|(s, (r, v))| {
                    let mut ss = 0.0;
                    for i in 0..s.len() {
                        s[i] = r[i] - alpha * v[i];
                        ss += s[i] * s[i];
                    }
                    [ss]
                })
                .collect(),
        );
        it += 1;
        let snorm = ss.sqrt() / bnorm;
        if snorm <= tol {
            x.par_iter_mut()
                .zip(phat.par_iter())
                .for_each(|(x, ph)| *x += alpha * ph);
            r.copy_from_slice(&s);
            rel = snorm;
            break;
        }
        pc.apply(&s, &mut shat);
        op.apply(&shat, &mut t);
        let [tt, ts] = sum_parts(
            t.par_chunks(CHUNK)
                .zip(s.par_chunks(CHUNK))
                .map(|(t, s)| {
                    let (mut tt, mut ts) = (0.0, 0.0);
                    for i in 0..t.len() {
                        tt += t[i] * t[i];
                        ts += t[i] * s[i];
                    }
                    [tt, ts]
                })
                .collect(),
        );
        omega = if tt > 0.0 { ts / tt } else { 0.0 };
        // The update, the residual norm and the next `r0 . r` in one pass.
        let [rr, r0r_new] = sum_parts(
            x.par_chunks_mut(CHUNK)
                .zip(r.par_chunks_mut(CHUNK))
                .zip(phat.par_chunks(CHUNK).zip(shat.par_chunks(CHUNK)))
                .zip(s.par_chunks(CHUNK).zip(t.par_chunks(CHUNK)))
                .zip(r0.par_chunks(CHUNK))
                .map(|((((x, r), (ph, sh)), (s, t)), r0)| {
                    let (mut rr, mut r0r) = (0.0, 0.0);
                    for i in 0..x.len() {
                        x[i] += alpha * ph[i] + omega * sh[i];
                        r[i] = s[i] - omega * t[i];
                        rr += r[i] * r[i];
                        r0r += r0[i] * r[i];
                    }
                    [rr, r0r]
                })
                .collect(),
        );
        r0r = r0r_new;
        rel = rr.sqrt() / bnorm;
        if omega == 0.0 {
            broke_down = true;
            break;
        }
    }
    (
        SolveStats {
            iterations: it,
            rel_residual: rel,
        },
        broke_down,
    )
}
