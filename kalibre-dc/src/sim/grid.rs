//! The structured grid: uniform cells per axis over the room, cell indexing, and the
//! mapping of boxes and points onto cells.

use crate::hall::Aabb;

/// Tolerance (m) for geometric comparisons against cell centres and faces.
pub(crate) const GEOM_EPS: f64 = 1e-6;

/// A uniform structured grid over the room, x fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Cells per axis.
    pub n: [usize; 3],
    /// Cell size per axis (m).
    pub d: [f64; 3],
}

/// Cells along one axis of length `l`: `round(l / cell_m)`, at least 2.
fn cells_along(l: f64, cell_m: f64) -> f64 {
    (l / cell_m).round().max(2.0)
}

impl Grid {
    /// The cell size for messages: `0.2` (m) when the axes agree to a nanometre, else
    /// `0.2 x 0.25 x 0.2`. A room length that is not a whole number of cells leaves
    /// rounding noise (4.8 m / 24 = 0.19999999999999998) that a reader should not see.
    pub fn cell_m_text(&self) -> String {
        let [x, y, z] = self.d.map(metres_text);
        if x == y && y == z {
            x
        } else {
            format!("{x} x {y} x {z}")
        }
    }

    /// The grid with cells of about `cell_m` over a room of `size_m` (each axis gets
    /// `round(L / cell_m)` cells, at least 2, so that cell faces fall on the room walls).
    pub fn new(size_m: [f64; 3], cell_m: f64) -> Self {
        let mut n = [0usize; 3];
        let mut d = [0.0; 3];
        for a in 0..3 {
            n[a] = cells_along(size_m[a], cell_m) as usize;
            d[a] = size_m[a] / n[a] as f64;
        }
        Grid { n, d }
    }

    /// How many cells [`Grid::new`] would make, counted in floating point so that a
    /// room too large for `usize` gives a large (or infinite) count, not an overflow.
    pub fn cell_count(size_m: [f64; 3], cell_m: f64) -> f64 {
        size_m.iter().map(|&l| cells_along(l, cell_m)).product()
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }

    /// True for an empty grid (never, by construction).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Linear index of cell `(i, j, k)`.
    #[inline]
    pub fn idx(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.n[0] * (j + self.n[1] * k)
    }

    /// `(i, j, k)` of a linear index.
    #[inline]
    pub fn ijk(&self, c: usize) -> [usize; 3] {
        let i = c % self.n[0];
        let j = (c / self.n[0]) % self.n[1];
        let k = c / (self.n[0] * self.n[1]);
        [i, j, k]
    }

    /// Stride of the linear index along axis `a`.
    #[inline]
    pub fn stride(&self, a: usize) -> usize {
        match a {
            0 => 1,
            1 => self.n[0],
            _ => self.n[0] * self.n[1],
        }
    }

    /// Centre coordinate of cell index `i` along axis `a`.
    #[inline]
    pub fn centre(&self, a: usize, i: usize) -> f64 {
        (i as f64 + 0.5) * self.d[a]
    }

    /// Centre of a cell.
    pub fn cell_centre(&self, c: usize) -> [f64; 3] {
        let [i, j, k] = self.ijk(c);
        [self.centre(0, i), self.centre(1, j), self.centre(2, k)]
    }

    /// The eight cell centres around `p` and their trilinear weights (which sum to one);
    /// a point outside the hull of the centres is clamped onto it.
    pub fn trilinear_corners(&self, p: [f64; 3]) -> [(usize, f64); 8] {
        let mut i0 = [0usize; 3];
        let mut t = [0.0; 3];
        for a in 0..3 {
            let s = (p[a] / self.d[a] - 0.5).clamp(0.0, (self.n[a] - 1) as f64);
            i0[a] = (s.floor() as usize).min(self.n[a] - 2);
            t[a] = s - i0[a] as f64;
        }
        std::array::from_fn(|corner| {
            let mut w = 1.0;
            let mut ijk = [0usize; 3];
            for a in 0..3 {
                let up = (corner >> a) & 1 == 1;
                ijk[a] = i0[a] + up as usize;
                w *= if up { t[a] } else { 1.0 - t[a] };
            }
            (self.idx(ijk[0], ijk[1], ijk[2]), w)
        })
    }

    /// Face area normal to axis `a`.
    pub fn face_area(&self, a: usize) -> f64 {
        match a {
            0 => self.d[1] * self.d[2],
            1 => self.d[0] * self.d[2],
            _ => self.d[0] * self.d[1],
        }
    }

    /// Volume of one cell.
    pub fn cell_volume(&self) -> f64 {
        self.d[0] * self.d[1] * self.d[2]
    }

    /// Cell indices along axis `a` whose centres lie in `[lo, hi]` (with tolerance). A
    /// centre exactly on a box edge counts as inside at both ends, so that mirrored
    /// geometry maps onto mirrored cells.
    pub fn range_in(&self, a: usize, lo: f64, hi: f64) -> std::ops::Range<usize> {
        let first = ((lo - GEOM_EPS) / self.d[a] - 0.5).ceil().max(0.0) as usize;
        let end = (((hi + GEOM_EPS) / self.d[a] - 0.5).floor() + 1.0).max(0.0) as usize;
        first.min(self.n[a])..end.min(self.n[a]).max(first.min(self.n[a]))
    }

    /// Faces of the side of the box `[min_m, max_m]` normal to axis `a` (its upper side
    /// with `at_max`), each as the index of the cell below it along `a`; none when the
    /// side lies on the domain's boundary. Face index `f` separates cells `f - 1` and `f`.
    /// The side is the face of the cells [`Self::range_in`] puts in the box: a side on a
    /// cell centre (a half-cell tie) goes outward at either end, as a rack's solid cells
    /// do, so that mirrored geometry maps onto mirrored faces.
    pub fn box_side_faces(
        &self,
        a: usize,
        at_max: bool,
        min_m: [f64; 3],
        max_m: [f64; 3],
    ) -> Vec<usize> {
        let inside = self.range_in(a, min_m[a], max_m[a]);
        let f = if at_max { inside.end } else { inside.start };
        if f == 0 || f >= self.n[a] {
            return Vec::new();
        }
        let t: Vec<usize> = (0..3).filter(|&b| b != a).collect();
        let r0 = self.range_in(t[0], min_m[t[0]], max_m[t[0]]);
        let r1 = self.range_in(t[1], min_m[t[1]], max_m[t[1]]);
        let mut faces = Vec::with_capacity(r0.len() * r1.len());
        for i1 in r1 {
            for i0 in r0.clone() {
                let mut ijk = [0usize; 3];
                ijk[a] = f - 1;
                ijk[t[0]] = i0;
                ijk[t[1]] = i1;
                faces.push(self.idx(ijk[0], ijk[1], ijk[2]));
            }
        }
        faces
    }

    /// Index of the cell containing coordinate `x` along axis `a` (clamped into the grid).
    pub fn cell_of(&self, a: usize, x: f64) -> usize {
        ((x / self.d[a]).floor().max(0.0) as usize).min(self.n[a] - 1)
    }

    /// Cells whose centres lie inside the box; along an axis where the box is thinner than
    /// a cell and holds no centre, the cell containing the box's centre on that axis.
    pub fn cells_in_box(&self, b: &Aabb) -> Vec<usize> {
        let c = b.centre();
        let r: Vec<_> = (0..3)
            .map(|a| {
                let r = self.range_in(a, b.min[a], b.max[a]);
                if r.is_empty() {
                    let i = self.cell_of(a, c[a]);
                    i..i + 1
                } else {
                    r
                }
            })
            .collect();
        let mut out = Vec::new();
        for k in r[2].clone() {
            for j in r[1].clone() {
                for i in r[0].clone() {
                    out.push(self.idx(i, j, k));
                }
            }
        }
        out
    }

    /// Overlap length of cell `i` along axis `a` with `[lo, hi]`.
    pub fn overlap(&self, a: usize, i: usize, lo: f64, hi: f64) -> f64 {
        let c0 = i as f64 * self.d[a];
        let c1 = c0 + self.d[a];
        (hi.min(c1) - lo.max(c0)).max(0.0)
    }

    /// Cell indices along axis `a` that overlap `[lo, hi]` by more than the tolerance.
    pub fn overlapping(&self, a: usize, lo: f64, hi: f64) -> std::ops::Range<usize> {
        let first = ((lo + GEOM_EPS) / self.d[a]).floor().max(0.0) as usize;
        let end = ((hi - GEOM_EPS) / self.d[a]).ceil().max(0.0) as usize;
        first.min(self.n[a])..end.min(self.n[a]).max(first.min(self.n[a]))
    }
}

/// A length (m) rounded to the nanometre, for messages.
pub(crate) fn metres_text(x: f64) -> String {
    crate::snapshots::number((x * 1e9).round() / 1e9)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_follow_cell_centres() {
        let g = Grid::new([7.2, 4.8, 3.0], 0.2);
        assert_eq!(g.n, [36, 24, 15]);
        assert_eq!(g.range_in(0, 2.4, 3.0), 12..15);
        assert_eq!(g.range_in(0, 0.0, 0.9), 0..5);
        assert_eq!(g.range_in(0, 6.3, 7.2), 31..36);
        assert_eq!(g.overlapping(2, 0.0, 1.0), 0..5);
        assert_eq!(g.overlapping(2, 0.95, 1.05), 4..6);
        let c = g.idx(3, 4, 5);
        assert_eq!(g.ijk(c), [3, 4, 5]);
    }
}
