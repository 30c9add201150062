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

use super::linalg::{Operator, Precond, CHUNK};

/// Largest grid solved directly.
const COARSE_MAX: usize = 400;

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

fn at(v: &[f64], c: usize) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v[c]
    }
}

fn strides(n: [usize; 3]) -> [usize; 3] {
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
        let cl = self.lower();
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, yc)| {
            let base = ci * CHUNK;
            for (o, yv) in yc.iter_mut().enumerate() {
                let c = base + o;
                *yv = if self.active[c] {
                    self.diag[c] * x[c] - self.neighbours(x, c, &s, cl)
                } else {
                    x[c]
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

    /// One Gauss-Seidel sweep on `A x = b`, links lagged; `t` is scratch.
    fn sweep(&self, b: &[f64], x: &mut [f64], t: &mut [f64], forward: bool) {
        let s = strides(self.n);
        let cl = self.lower();
        let has_links = !self.links.is_empty();
        if has_links {
            t.fill(0.0);
            self.link_values(x, t);
        }
        let row = |c: usize, x: &mut [f64]| {
            if self.active[c] {
                let extra = if has_links { t[c] } else { 0.0 };
                x[c] = (b[c] + extra + self.neighbours(x, c, &s, cl)) * self.inv_diag[c];
            } else {
                x[c] = b[c];
            }
        };
        if forward {
            for c in 0..self.len() {
                row(c, x);
            }
        } else {
            for c in (0..self.len()).rev() {
                row(c, x);
            }
        }
    }
}

/// Per axis: cell widths (in finest cells) and protected face planes (`protect[f]`: the
/// plane between cells `f - 1` and `f` carries weak walls and is kept at coarser levels).
#[derive(Debug, Clone)]
struct Axes {
    widths: [Vec<f64>; 3],
    protect: [Vec<bool>; 3],
}

impl Axes {
    /// Finest level: unit widths; a plane is protected when some face on it between two
    /// active cells conducts less than half the axis's largest conductance (containment
    /// panels). Aggregating across such a wall would average two nearly independent
    /// regions and leave their relative level to the Krylov solver.
    fn finest(spec: &StencilSpec) -> Self {
        let n = spec.n;
        let s = strides(n);
        let widths = std::array::from_fn(|a| vec![1.0; n[a]]);
        let protect = std::array::from_fn(|a| {
            let mut p = vec![false; n[a] + 1];
            let gmax = spec.dif[a].iter().fold(0.0f64, |m, v| m.max(*v));
            if gmax <= 0.0 {
                return p;
            }
            let mut c = 0;
            for k in 0..n[2] {
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let ijk = [i, j, k];
                        if ijk[a] + 1 < n[a]
                            && spec.active[c]
                            && spec.active[c + s[a]]
                            && spec.dif[a][c] < 0.5 * gmax
                        {
                            p[ijk[a] + 1] = true;
                        }
                        c += 1;
                    }
                }
            }
            p
        });
        Axes { widths, protect }
    }
}

/// Groups of one or two cells along one axis, never across a protected plane (unless
/// that would leave the axis uncoarsened); returns the group of each cell and the count.
fn pair_cells(n: usize, protect: &[bool]) -> (Vec<usize>, usize) {
    let group = |use_protect: bool| {
        let mut map = vec![0; n];
        let (mut i, mut g) = (0, 0);
        while i < n {
            map[i] = g;
            if i + 1 < n && !(use_protect && protect[i + 1]) {
                map[i + 1] = g;
                i += 2;
            } else {
                i += 1;
            }
            g += 1;
        }
        (map, g)
    };
    let (map, g) = group(true);
    if g == n && n > 1 {
        group(false)
    } else {
        (map, g)
    }
}

/// The coarse-level input of `spec`, its axes, and the fine-to-coarse cell map.
fn coarsen(spec: &StencilSpec, axes: &Axes) -> (StencilSpec, Axes, Vec<u32>) {
    let n = spec.n;
    let s = strides(n);
    let pairs: [(Vec<usize>, usize); 3] =
        std::array::from_fn(|a| pair_cells(n[a], &axes.protect[a]));
    let nc: [usize; 3] = std::array::from_fn(|a| pairs[a].1);
    let sc = strides(nc);
    let len_c = nc[0] * nc[1] * nc[2];
    let mut cw: [Vec<f64>; 3] = std::array::from_fn(|a| vec![0.0; nc[a]]);
    let mut cp: [Vec<bool>; 3] = std::array::from_fn(|a| vec![false; nc[a] + 1]);
    for a in 0..3 {
        let map = &pairs[a].0;
        for i in 0..n[a] {
            cw[a][map[i]] += axes.widths[a][i];
            if i > 0 && map[i] != map[i - 1] {
                cp[a][map[i]] = axes.protect[a][i];
            }
        }
    }
    let mut parent = Vec::with_capacity(n[0] * n[1] * n[2]);
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                parent.push((pairs[0].0[i] + sc[1] * pairs[1].0[j] + sc[2] * pairs[2].0[k]) as u32);
            }
        }
    }
    let has_adv = !spec.fp[0].is_empty();
    let zeros = || -> [Vec<f64>; 3] {
        if has_adv {
            [vec![0.0; len_c], vec![0.0; len_c], vec![0.0; len_c]]
        } else {
            Default::default()
        }
    };
    let (mut fp, mut fm) = (zeros(), zeros());
    let mut dif: [Vec<f64>; 3] = [vec![0.0; len_c], vec![0.0; len_c], vec![0.0; len_c]];
    for a in 0..3 {
        let (map, w, cwa) = (&pairs[a].0, &axes.widths[a], &cw[a]);
        let mut c = 0;
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let ijk = [i, j, k];
                    if ijk[a] + 1 < n[a] {
                        let (p, q) = (parent[c] as usize, parent[c + s[a]] as usize);
                        if p != q {
                            // Rediscretised: same area, centre distance of the coarse cells.
                            let (gi, gj) = (map[ijk[a]], map[ijk[a] + 1]);
                            let ratio = (w[ijk[a]] + w[ijk[a] + 1]) / (cwa[gi] + cwa[gj]);
                            dif[a][p] += at(&spec.dif[a], c) * ratio;
                            if has_adv {
                                fp[a][p] += spec.fp[a][c];
                                fm[a][p] += spec.fm[a][c];
                            }
                        }
                    }
                    c += 1;
                }
            }
        }
    }
    let mut sink_adv = vec![0.0; len_c];
    let mut sink_dif = vec![0.0; len_c];
    let mut active = vec![false; len_c];
    for (c, &p) in parent.iter().enumerate() {
        let p = p as usize;
        let k = c / s[2];
        sink_adv[p] += at(&spec.sink_adv, c);
        // A fixed value half a cell away: the distance grows with the cell height.
        sink_dif[p] += at(&spec.sink_dif, c) * axes.widths[2][k] / cw[2][pairs[2].0[k]];
        active[p] |= spec.active[c];
    }
    let merge = |st: &[(usize, f64)]| -> Vec<(usize, f64)> {
        let mut v: Vec<(usize, f64)> = st.iter().map(|&(c, w)| (parent[c] as usize, w)).collect();
        v.sort_by_key(|e| e.0);
        let mut out: Vec<(usize, f64)> = Vec::with_capacity(v.len());
        for (c, w) in v {
            match out.last_mut() {
                Some(last) if last.0 == c => last.1 += w,
                _ => out.push((c, w)),
            }
        }
        out
    };
    let links = spec
        .links
        .iter()
        .map(|l| Link {
            from: merge(&l.from),
            to: merge(&l.to),
            flow: l.flow,
        })
        .collect();
    let coarse = StencilSpec {
        n: nc,
        fp,
        fm,
        dif,
        sink_adv,
        sink_dif,
        active,
        links,
    };
    (
        coarse,
        Axes {
            widths: cw,
            protect: cp,
        },
        parent,
    )
}

/// Dense LU with partial pivoting of the coarsest operator.
#[derive(Debug, Clone)]
struct DenseLu {
    m: usize,
    lu: Vec<f64>,
    piv: Vec<usize>,
}

impl DenseLu {
    fn new(level: &Level) -> Self {
        let m = level.len();
        let mut a = vec![0.0; m * m];
        let s = strides(level.n);
        let cl = level.lower();
        for c in 0..m {
            a[c * m + c] = level.diag[c];
            if !level.active[c] {
                continue;
            }
            for ax in 0..3 {
                if c + s[ax] < m {
                    a[c * m + c + s[ax]] -= level.cu[ax][c];
                }
                if c >= s[ax] {
                    a[c * m + c - s[ax]] -= cl[ax][c - s[ax]];
                }
            }
        }
        for l in &level.links {
            for &(ct, wt) in &l.to {
                if level.active[ct] {
                    for &(cf, wf) in &l.from {
                        a[ct * m + cf] -= wt * l.flow * wf;
                    }
                }
            }
        }
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
    fn solve(&self, x: &mut [f64]) {
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
                let coarse = DenseLu::new(&level);
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
            lev.sweep(b, x, &mut sc.t, true);
        }
        lev.apply(x, &mut sc.r);
        sc.cb.fill(0.0);
        for c in 0..lev.len() {
            if lev.active[c] {
                sc.cb[lev.parent[c] as usize] += b[c] - sc.r[c];
            }
        }
        self.cycle(l + 1, tail, &sc.cb, &mut sc.cx);
        for c in 0..lev.len() {
            if lev.active[c] {
                x[c] += sc.cx[lev.parent[c] as usize];
            }
        }
        for _ in 0..self.sweeps {
            lev.sweep(b, x, &mut sc.t, false);
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
