//! Bounded second-order advection for the temperature equation by deferred correction.
//!
//! The implicit operator stays first-order upwind (so the multigrid-preconditioned
//! BiCGSTAB solve is unchanged); a TVD face value `T_f = T_U + psi(r) / 2 (T_D - T_U)`
//! with `r = (T_U - T_UU) / (T_D - T_U)` enters as an explicit source: each open face
//! carries the extra heat `|F| (T_f - T_U)` from its upwind to its downwind cell, with
//! `T` from the previous pass. At convergence the field solves the TVD scheme; every pass
//! is conservative (what one cell loses its neighbour gains), so the energy balance holds
//! after any pass.
//!
//! Faces that are not fully open (containment panels leaking at a fraction of a face) keep
//! upwind: a jet through a gap carries the upwind side's temperature. Where the
//! far-upwind cell `UU` does not exist (a wall, a solid, a partial face), the upwind
//! gradient counts as zero, which the limiters map to upwind.

use rayon::prelude::*;

use super::config::Advection;
use super::grid::Grid;
use super::linalg::{SolveStats, CHUNK};

/// Weight of the new correction against the last one in each pass.
const RELAX: f64 = 0.7;

/// Outcome of the deferred-correction passes of one temperature solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdvectionStats {
    /// Correction passes run after the first (upwind) solve; 0 for upwind.
    pub passes: usize,
    /// Largest cell temperature change (C) of the last pass (0 for upwind).
    pub last_change_c: f64,
}

/// `psi(r) (T_D - T_U)` written without the division, from the upwind difference
/// `du = T_U - T_UU` and the downwind difference `dd = T_D - T_U`. Zero unless both have
/// the same sign (a local extremum stays upwind).
#[inline]
pub(crate) fn limited(scheme: Advection, du: f64, dd: f64) -> f64 {
    if du * dd <= 0.0 {
        return 0.0;
    }
    match scheme {
        Advection::Upwind => 0.0,
        // (r + |r|) / (1 + |r|) * dd = 2 du dd / (du + dd) for r > 0.
        Advection::VanLeer => 2.0 * du * dd / (du + dd),
        // min(r, 1) * dd: the smaller difference in magnitude.
        Advection::Minmod => {
            if du.abs() < dd.abs() {
                du
            } else {
                dd
            }
        }
    }
}

/// Face data of one run: conductances (open when `g >= full`), full conductance per axis,
/// face fluxes.
pub(crate) struct Faces<'a> {
    pub grid: &'a Grid,
    pub g: [&'a [f64]; 3],
    pub full_g: [f64; 3],
    pub flux: &'a [Vec<f64>; 3],
}

impl Faces<'_> {
    /// Face `(c, c + s_a)` is fully open (not a wall, solid or leaking panel).
    #[inline]
    fn open(&self, a: usize, c: usize) -> bool {
        self.g[a][c] >= self.full_g[a] * (1.0 - 1e-9)
    }

    /// Extra heat flow (m3/s x C) through face `(c, c + s_a)` towards `+a`.
    #[inline]
    fn face_correction(&self, scheme: Advection, a: usize, c: usize, t: &[f64]) -> f64 {
        let f = self.flux[a][c];
        if f == 0.0 || !self.open(a, c) {
            return 0.0;
        }
        let s = self.grid.stride(a);
        let ia = self.grid.ijk(c)[a];
        let (u, d) = if f > 0.0 { (c, c + s) } else { (c + s, c) };
        // The far-upwind cell through a fully open face, if any.
        let uu = if f > 0.0 {
            (ia >= 1 && self.open(a, c - s)).then(|| c - s)
        } else {
            (ia + 2 < self.grid.n[a] && self.open(a, c + s)).then(|| c + 2 * s)
        };
        let dd = t[d] - t[u];
        let du = uu.map_or(0.0, |uu| t[u] - t[uu]);
        // Signed towards +a: `f` carries the sign of the direction.
        0.5 * f * limited(scheme, du, dd)
    }

    /// `out = rhs + correction(t)`: the right-hand side of the next pass.
    pub fn corrected_rhs(&self, scheme: Advection, t: &[f64], rhs: &[f64], out: &mut [f64]) {
        let n = t.len();
        let s = [
            self.grid.stride(0),
            self.grid.stride(1),
            self.grid.stride(2),
        ];
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, oc)| {
            let base = ci * CHUNK;
            for (o, ov) in oc.iter_mut().enumerate() {
                let c = base + o;
                let mut acc = rhs[c];
                for (a, &sa) in s.iter().enumerate() {
                    // Out through the high face, in through the low face.
                    if c + sa < n {
                        acc -= self.face_correction(scheme, a, c, t);
                    }
                    if c >= sa {
                        acc += self.face_correction(scheme, a, c - sa, t);
                    }
                }
                *ov = acc;
            }
        });
    }
}

/// The steady temperature with `scheme`: one solve with the upwind right-hand side, then
/// (TVD schemes) up to `max_passes` deferred-correction passes, each warm-started from the
/// last field, until no cell moves more than `tol_c`. `solve(b, x)` solves the upwind
/// system in place. Returns the summed solve figures (iterations of all passes, the last
/// residual) and the pass figures; stops early when a solve fails to converge (the caller
/// checks its residual).
pub(crate) fn solve_deferred(
    faces: &Faces,
    scheme: Advection,
    (max_passes, tol_c): (usize, f64),
    tol: f64,
    rhs: &[f64],
    temp: &mut [f64],
    mut solve: impl FnMut(&[f64], &mut [f64]) -> SolveStats,
) -> (SolveStats, AdvectionStats) {
    let mut stats = solve(rhs, temp);
    let mut adv = AdvectionStats {
        passes: 0,
        last_change_c: 0.0,
    };
    if scheme.is_upwind() {
        return (stats, adv);
    }
    let mut b = vec![0.0; rhs.len()];
    let mut prev = temp.to_vec();
    let mut b_prev = vec![0.0; rhs.len()];
    for _ in 0..max_passes {
        if stats.rel_residual.is_nan() || stats.rel_residual > tol {
            break;
        }
        faces.corrected_rhs(scheme, temp, rhs, &mut b);
        if adv.passes > 0 {
            // Under-relaxed correction: limiter switching otherwise cycles.
            b.par_iter_mut()
                .zip(b_prev.par_iter())
                .for_each(|(b, p)| *b = RELAX * *b + (1.0 - RELAX) * p);
        }
        b_prev.copy_from_slice(&b);
        prev.copy_from_slice(temp);
        let s = solve(&b, temp);
        stats = SolveStats {
            iterations: stats.iterations + s.iterations,
            rel_residual: s.rel_residual,
        };
        adv.passes += 1;
        adv.last_change_c = max_abs_diff(temp, &prev);
        if adv.last_change_c <= tol_c {
            break;
        }
    }
    (stats, adv)
}

/// Largest `|a - b|` (order-independent, so deterministic in parallel).
fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| {
            x.iter()
                .zip(y)
                .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()))
        })
        .reduce(|| 0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limiters_stay_in_the_tvd_region() {
        // Sweby: 0 <= psi(r) <= min(2 r, 2) for r > 0, psi(1) = 1, psi = 0 for r <= 0.
        for scheme in [Advection::VanLeer, Advection::Minmod] {
            for i in -40..=400 {
                let r = i as f64 * 0.05;
                let dd = 0.7;
                let psi = limited(scheme, r * dd, dd) / dd;
                if r <= 0.0 {
                    assert_eq!(psi, 0.0);
                } else {
                    assert!(psi >= 0.0 && psi <= (2.0 * r).min(2.0) + 1e-12, "{r} {psi}");
                }
            }
            assert!((limited(scheme, 0.3, 0.3) - 0.3).abs() < 1e-15);
            // Symmetric in the sense of psi(r)/r = psi(1/r) (same under dd <-> du).
            assert!((limited(scheme, 0.2, 0.9) - limited(scheme, 0.9, 0.2)).abs() < 1e-15);
            // Sign follows the differences.
            assert!((limited(scheme, -0.2, -0.9) + limited(scheme, 0.2, 0.9)).abs() < 1e-15);
        }
    }
}
