//! Coarsening of a 7-point operator: which cells merge (pairs per axis, never across a
//! weak wall) and the coarse coefficients.

use super::{at, strides, Link, StencilSpec};

/// Per axis: cell widths (in finest cells) and protected face planes (`protect[f]`: the
/// plane between cells `f - 1` and `f` carries weak walls and is kept at coarser levels).
#[derive(Debug, Clone)]
pub(super) struct Axes {
    pub widths: [Vec<f64>; 3],
    pub protect: [Vec<bool>; 3],
}

impl Axes {
    /// Finest level: unit widths; a plane is protected when some face on it between two
    /// active cells conducts less than half the axis's largest conductance (containment
    /// panels). Aggregating across such a wall would average two nearly independent
    /// regions and leave their relative level to the Krylov solver.
    pub fn finest(spec: &StencilSpec) -> Self {
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
pub(super) fn coarsen(spec: &StencilSpec, axes: &Axes) -> (StencilSpec, Axes, Vec<u32>) {
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
