//! Geometric multigrid for the 7-point cell-centred operators of the simulator, used as a
//! preconditioner (symmetric V-cycle for CG on the pressure, the same cycle for BiCGSTAB on
//! the temperature).
//!
//! Coarsening merges 2 cells per axis (an axis of one cell is not coarsened). Coarse
//! operators are built from the fine face coefficients: advective parts (upwind outflow
//! `max(F, 0)` and `max(-F, 0)`) are summed over the fine faces of a coarse face, which is
//! the Galerkin product with piecewise-constant transfer and conserves mass; diffusive
//! conductances (area over distance) are summed and divided by the coarsening ratio of
//! the face's axis, which is the rediscretised operator (plain Galerkin aggregation would
//! overweight them by that ratio and slow the cycle). Walls and solids need no special
//! case: a closed face has zero coefficients at every level. Non-local links (servers)
//! are carried to every level by merging their cell stencils.
//!
//! Smoothing is lexicographic Gauss-Seidel (forward before the coarse correction,
//! backward after, so the cycle is symmetric for a symmetric operator); links are lagged
//! within a sweep. The coarsest level (at most [`COARSE_MAX`] cells) is solved by a
//! dense LU factorisation. Everything is sequential or chunked in fixed order, so the
//! result does not depend on the thread count.

use rayon::prelude::*;

mod coarsen;

use super::dense::DenseLu;
use super::linalg::{Operator, Precond, CHUNK};
use coarsen::{coarsen, Axes};

/// Largest grid solved directly.
const COARSE_MAX: usize = 400;

/// Smallest level whose sweeps run in two parallel halves.
const PARALLEL_MIN: usize = 20_000;

/// A non-local link: `flow` leaves the `from` cells (weights sum to one) and enters the
/// `to` cells at the mixed value; row `c` in `to` gets `- w_to flow sum w_from x`.
#[derive(Debug, Clone)]
pub(crate) struct Link {
    pub from: Vec<(usize, f64)>,
    pub to: Vec<(usize, f64)>,
    pub flow: f64,
}

/// Coefficients of a 7-point operator on an `n[0] x n[1] x n[2]` grid (x fastest), the
/// input of a level. Per face between `c` and `c + stride(a)` (zero when closed or on the
/// grid boundary): `fp`/`fm` the flow towards `+a`/`-a` (empty vectors mean zero, e.g.
/// for the pressure), `dif` the diffusive conductance. Per cell: `sink_adv` outflow to
/// fixed outlets, `sink_dif` conductance to a fixed (zero) value.
#[derive(Debug, Clone)]
pub(crate) struct StencilSpec {
    pub n: [usize; 3],
    pub fp: [Vec<f64>; 3],
    pub fm: [Vec<f64>; 3],
    pub dif: [Vec<f64>; 3],
    pub sink_adv: Vec<f64>,
    pub sink_dif: Vec<f64>,
    /// Rows that take part; the others are identities.
    pub active: Vec<bool>,
    pub links: Vec<Link>,
}

pub(super) fn at(v: &[f64], c: usize) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v[c]
    }
}

pub(super) fn strides(n: [usize; 3]) -> [usize; 3] {
    [1, n[0], n[0] * n[1]]
}

/// One level: the operator in coefficient form and the map to the next coarser level.
#[derive(Debug, Clone)]
struct Level {
    n: [usize; 3],
    /// Coefficient of `x[c + s_a]` in row `c` (entered with a minus sign).
    cu: [Vec<f64>; 3],
    /// Coefficient of `x[c]` in row `c + s_a`; `None` when equal to `cu` (symmetric).
    cl: Option<[Vec<f64>; 3]>,
    diag: Vec<f64>,
    inv_diag: Vec<f64>,
    active: Vec<bool>,
    links: Vec<Link>,
    /// Coarse cell of each cell (empty on the coarsest level).
    parent: Vec<u32>,
}

impl Level {
    fn new(spec: &StencilSpec, symmetric: bool) -> Self {
        let n = spec.n;
        let len = n[0] * n[1] * n[2];
        let s = strides(n);
        let mut diag: Vec<f64> = (0..len)
            .map(|c| at(&spec.sink_adv, c) + at(&spec.sink_dif, c))
            .collect();
        let mut cu: [Vec<f64>; 3] = [vec![0.0; len], vec![0.0; len], vec![0.0; len]];
        let mut cl: [Vec<f64>; 3] = if symmetric {
            Default::default()
        } else {
            [vec![0.0; len], vec![0.0; len], vec![0.0; len]]
        };
        for a in 0..3 {
            for c in 0..len.saturating_sub(s[a]) {
                let (fp, fm, d) = (at(&spec.fp[a], c), at(&spec.fm[a], c), at(&spec.dif[a], c));
                if fp == 0.0 && fm == 0.0 && d == 0.0 {
                    continue;
                }
                diag[c] += fp + d;
                diag[c + s[a]] += fm + d;
                cu[a][c] = fm + d;
                if !symmetric {
                    cl[a][c] = fp + d;
                }
            }
        }
        let active: Vec<bool> = (0..len).map(|c| spec.active[c] && diag[c] > 0.0).collect();
        for c in 0..len {
            if !active[c] {
                diag[c] = 1.0;
            }
        }
        let inv_diag = diag.iter().map(|d| 1.0 / d).collect();
        Level {
            n,
            cu,
            cl: if symmetric { None } else { Some(cl) },
            diag,
            inv_diag,
            active,
            links: spec.links.clone(),
            parent: Vec::new(),
        }
    }

    /// The level's operator as a dense row-major matrix.
    fn dense(&self) -> Vec<f64> {
        let m = self.len();
        let mut a = vec![0.0; m * m];
        let s = strides(self.n);
        let cl = self.lower();
        for c in 0..m {
            a[c * m + c] = self.diag[c];
            if !self.active[c] {
                continue;
            }
            for ax in 0..3 {
                if c + s[ax] < m {
                    a[c * m + c + s[ax]] -= self.cu[ax][c];
                }
                if c >= s[ax] {
                    a[c * m + c - s[ax]] -= cl[ax][c - s[ax]];
                }
            }
        }
        for l in &self.links {
            for &(ct, wt) in &l.to {
                if self.active[ct] {
                    for &(cf, wf) in &l.from {
                        a[ct * m + cf] -= wt * l.flow * wf;
                    }
                }
            }
        }
        a
    }

    fn len(&self) -> usize {
        self.diag.len()
    }

    fn lower(&self) -> &[Vec<f64>; 3] {
        self.cl.as_ref().unwrap_or(&self.cu)
    }

    /// Sum of the off-diagonal stencil terms of row `c` (signs folded in: `+ coef x`).
    #[inline(always)]
    fn neighbours(&self, x: &[f64], c: usize, s: &[usize; 3], cl: &[Vec<f64>; 3]) -> f64 {
        let n = x.len();
        let mut acc = 0.0;
        for a in 0..3 {
            if c + s[a] < n {
                acc += self.cu[a][c] * x[c + s[a]];
            }
            if c >= s[a] {
                acc += cl[a][c - s[a]] * x[c - s[a]];
            }
        }
        acc
    }

    /// `t = (links) x`: what the links add to each row's right-hand side.
    fn link_values(&self, x: &[f64], t: &mut [f64]) {
        for l in &self.links {
            let mean: f64 = l.from.iter().map(|&(c, w)| w * x[c]).sum();
            for &(c, w) in &l.to {
                t[c] += w * l.flow * mean;
            }
        }
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let s = strides(self.n);
        let n = self.len();
        let cl = self.lower();
        let (lo, hi) = if n > 2 * s[2] {
            (s[2], n - s[2])
        } else {
            (n, n)
        };
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, yc)| {
            let base = ci * CHUNK;
            for (o, yv) in yc.iter_mut().enumerate() {
                let c = base + o;
                *yv = if !self.active[c] {
                    x[c]
                } else if c >= lo && c < hi {
                    self.diag[c] * x[c]
                        - (self.cu[0][c] * x[c + 1]
                            + cl[0][c - 1] * x[c - 1]
                            + self.cu[1][c] * x[c + s[1]]
                            + cl[1][c - s[1]] * x[c - s[1]]
                            + self.cu[2][c] * x[c + s[2]]
                            + cl[2][c - s[2]] * x[c - s[2]])
                } else {
                    self.diag[c] * x[c] - self.neighbours(x, c, &s, cl)
                };
            }
        });
        // Links are sparse next to the stencil: applied serially, in order.
        for l in &self.links {
            let mean: f64 = l.from.iter().map(|&(c, w)| w * x[c]).sum();
            for &(c, w) in &l.to {
                if self.active[c] {
                    y[c] -= w * l.flow * mean;
                }
            }
        }
    }

    /// One Gauss-Seidel sweep on `A x = b`, links lagged; `t` and `halo` are scratch.
    /// Large levels sweep their lower and upper halves of z planes at the same time,
    /// each reading the other's border plane as it was before the sweep (a fixed split,
    /// so the result does not depend on the thread count; for a symmetric operator the
    /// backward sweep is still the adjoint of the forward one).
    fn sweep(&self, b: &[f64], x: &mut [f64], t: &mut [f64], halo: &mut [f64], fwd: bool) {
        let n = self.len();
        let rhs: &[f64] = if self.links.is_empty() {
            b
        } else {
            t.copy_from_slice(b);
            self.link_values(x, t);
            t
        };
        let s2 = strides(self.n)[2];
        if n < PARALLEL_MIN || self.n[2] < 4 {
            self.sweep_block(rhs, x, 0, &[], &[], fwd);
            return;
        }
        let split = (self.n[2] / 2) * s2;
        let (below, above) = halo.split_at_mut(s2);
        below.copy_from_slice(&x[split - s2..split]);
        above.copy_from_slice(&x[split..split + s2]);
        let (x0, x1) = x.split_at_mut(split);
        rayon::join(
            || self.sweep_block(rhs, x0, 0, &[], above, fwd),
            || self.sweep_block(rhs, x1, split, below, &[], fwd),
        );
    }

    /// Gauss-Seidel over the whole planes in `xb` (cells `off..off + xb.len()`), reading
    /// the plane below from `below` and the plane above from `above` (empty at the grid's
    /// own bottom and top).
    fn sweep_block(
        &self,
        rhs: &[f64],
        xb: &mut [f64],
        off: usize,
        below: &[f64],
        above: &[f64],
        forward: bool,
    ) {
        let s = strides(self.n);
        let n = self.len();
        let end = off + xb.len();
        let cl = self.lower();
        let (active, inv_diag) = (&self.active[..], &self.inv_diag[..]);
        let (s1, s2) = (s[1], s[2]);
        let edge = |c: usize, xb: &mut [f64]| {
            let get = |xb: &[f64], g: usize| {
                if g < off {
                    below[g + s2 - off]
                } else if g >= end {
                    above[g - end]
                } else {
                    xb[g - off]
                }
            };
            xb[c - off] = if active[c] {
                let mut acc = rhs[c];
                for a in 0..3 {
                    if c + s[a] < n {
                        acc += self.cu[a][c] * get(xb, c + s[a]);
                    }
                    if c >= s[a] {
                        acc += cl[a][c - s[a]] * get(xb, c - s[a]);
                    }
                }
                acc * inv_diag[c]
            } else {
                rhs[c]
            };
        };
        // Cells off the block's first and last planes have all six neighbours in `xb`.
        let (u0, u1, u2) = (&self.cu[0][..], &self.cu[1][..], &self.cu[2][..]);
        let (l0, l1, l2) = (&cl[0][..], &cl[1][..], &cl[2][..]);
        // The neighbour just updated enters last: the sweep's serial dependency is then
        // one multiply-add per cell instead of a chain of six.
        let inner = |c: usize, xb: &mut [f64], forward: bool| {
            let i = c - off;
            xb[i] = if active[c] {
                let far = rhs[c]
                    + u1[c] * xb[i + s1]
                    + l1[c - s1] * xb[i - s1]
                    + u2[c] * xb[i + s2]
                    + l2[c - s2] * xb[i - s2];
                let v = if forward {
                    far + u0[c] * xb[i + 1] + l0[c - 1] * xb[i - 1]
                } else {
                    far + l0[c - 1] * xb[i - 1] + u0[c] * xb[i + 1]
                };
                v * inv_diag[c]
            } else {
                rhs[c]
            };
        };
        let (lo, hi) = if end - off > 2 * s2 {
            (off + s2, end - s2)
        } else {
            (end, end)
        };
        if forward {
            (off..lo).for_each(|c| edge(c, xb));
            (lo..hi).for_each(|c| inner(c, xb, true));
            (hi.max(lo)..end).for_each(|c| edge(c, xb));
        } else {
            (hi.max(lo)..end).rev().for_each(|c| edge(c, xb));
            (lo..hi).rev().for_each(|c| inner(c, xb, false));
            (off..lo).rev().for_each(|c| edge(c, xb));
        }
    }
}

/// A multigrid hierarchy; also the fine-level operator for the Krylov solver.
#[derive(Debug, Clone)]
pub(crate) struct Multigrid {
    levels: Vec<Level>,
    coarse: DenseLu,
    sweeps: usize,
}

impl Multigrid {
    /// Builds the hierarchy of `spec`; `symmetric` when `fp`/`fm` are empty and there
    /// are no links; `sweeps` Gauss-Seidel sweeps before and after each coarse correction.
    pub fn build(spec: StencilSpec, symmetric: bool, sweeps: usize) -> Self {
        let mut levels = Vec::new();
        let mut axes = Axes::finest(&spec);
        let mut spec = spec;
        loop {
            let mut level = Level::new(&spec, symmetric);
            let len = level.len();
            if len <= COARSE_MAX || spec.n.iter().all(|&n| n == 1) {
                let coarse = DenseLu::new(level.len(), level.dense());
                levels.push(level);
                return Multigrid {
                    levels,
                    coarse,
                    sweeps,
                };
            }
            let (next, next_axes, parent) = coarsen(&spec, &axes);
            level.parent = parent;
            levels.push(level);
            spec = next;
            axes = next_axes;
        }
    }

    /// Number of levels.
    #[cfg(test)]
    pub fn depth(&self) -> usize {
        self.levels.len()
    }

    /// Scratch for applying the cycle.
    pub fn workspace(&self) -> MgWork<'_> {
        let scratch = self
            .levels
            .iter()
            .enumerate()
            .map(|(l, lev)| {
                let next = self.levels.get(l + 1).map_or(0, Level::len);
                Scratch {
                    r: vec![0.0; lev.len()],
                    t: vec![0.0; lev.len()],
                    halo: vec![0.0; 2 * strides(lev.n)[2]],
                    cb: vec![0.0; next],
                    cx: vec![0.0; next],
                }
            })
            .collect();
        MgWork { mg: self, scratch }
    }

    fn cycle(&self, l: usize, scratch: &mut [Scratch], b: &[f64], x: &mut [f64]) {
        if l + 1 == self.levels.len() {
            x.copy_from_slice(b);
            self.coarse.solve(x);
            return;
        }
        let lev = &self.levels[l];
        let (head, tail) = scratch.split_at_mut(1);
        let sc = &mut head[0];
        x.fill(0.0);
        for _ in 0..self.sweeps {
            lev.sweep(b, x, &mut sc.t, &mut sc.halo, true);
        }
        lev.apply(x, &mut sc.r);
        // Restriction sums the residuals of a coarse cell's children; prolongation
        // copies the coarse correction back (both skip identity rows).
        sc.cb.fill(0.0);
        for (((&p, &on), bv), rv) in lev.parent.iter().zip(&lev.active).zip(b).zip(&sc.r) {
            if on {
                sc.cb[p as usize] += bv - rv;
            }
        }
        self.cycle(l + 1, tail, &sc.cb, &mut sc.cx);
        for ((&p, &on), xv) in lev.parent.iter().zip(&lev.active).zip(x.iter_mut()) {
            if on {
                *xv += sc.cx[p as usize];
            }
        }
        for _ in 0..self.sweeps {
            lev.sweep(b, x, &mut sc.t, &mut sc.halo, false);
        }
    }
}

impl Operator for Multigrid {
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.levels[0].apply(x, y);
    }

    fn inv_diag(&self) -> &[f64] {
        &self.levels[0].inv_diag
    }
}

struct Scratch {
    r: Vec<f64>,
    t: Vec<f64>,
    halo: Vec<f64>,
    cb: Vec<f64>,
    cx: Vec<f64>,
}

/// One V-cycle per preconditioner application.
pub(crate) struct MgWork<'a> {
    mg: &'a Multigrid,
    scratch: Vec<Scratch>,
}

impl Precond for MgWork<'_> {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        self.mg.cycle(0, &mut self.scratch, r, z);
    }
}

#[cfg(test)]
mod tests;
