//! The faces of a box that air passes through, as patches: a rack's or CRAC's side, a
//! CRAC's top, a floor or ceiling rectangle, each checked to open onto fluid.

use crate::hall::Side;

use super::{geo, CaseGeometry, CellRange, FacePatch, OpenFoamError};

impl CaseGeometry {
    pub(super) fn is_solid(&self, c: [usize; 3]) -> bool {
        self.solid[c[0] + self.n[0] * (c[1] + self.n[1] * c[2])]
    }

    /// The first solid cell of `cells` (k, then j, then i), if any: a patch's faces must
    /// all open onto fluid.
    fn first_solid(&self, cells: &CellRange) -> Option<[usize; 3]> {
        (cells.lo[2]..cells.hi[2])
            .flat_map(|k| (cells.lo[1]..cells.hi[1]).map(move |j| (j, k)))
            .flat_map(|(j, k)| (cells.lo[0]..cells.hi[0]).map(move |i| [i, j, k]))
            .find(|&c| self.is_solid(c))
    }

    /// Boundary faces of a rack's side over a server's span; every face must open onto
    /// fluid (a rack pressed against another rack or a wall has no intake there).
    pub(super) fn side_patch(
        &self,
        span: &CellRange,
        side: Side,
        name: String,
        field: &str,
    ) -> Result<FacePatch, OpenFoamError> {
        let (axis, sign) = side.axis_sign();
        let plane = if sign > 0.0 {
            span.hi[axis]
        } else {
            span.lo[axis]
        };
        let outside = if sign > 0.0 {
            Some(plane)
        } else {
            plane.checked_sub(1)
        };
        let outside = outside.filter(|&o| o < self.n[axis]).ok_or_else(|| {
            geo(
                field,
                format!("side {side:?} lies on a room wall: no air can pass"),
            )
        })?;
        let mut cells = *span;
        cells.lo[axis] = outside;
        cells.hi[axis] = outside + 1;
        if let Some([i, j, k]) = self.first_solid(&cells) {
            return Err(geo(
                field,
                format!(
                    "side {side:?} is blocked by a solid at cell ({i}, {j}, {k}) (racks back \
                     to back or against a CRAC)"
                ),
            ));
        }
        Ok(FacePatch {
            name,
            axis,
            plane,
            faces: cells.count(),
            cells,
        })
    }

    /// The top of a box `r` (a CRAC's, where it draws its return air with no grilles):
    /// every face must open onto fluid, so a box reaching the ceiling has none.
    pub(super) fn top_patch(
        &self,
        r: &CellRange,
        name: String,
        field: &str,
    ) -> Result<FacePatch, OpenFoamError> {
        let plane = r.hi[2];
        if plane >= self.n[2] {
            return Err(geo(
                field,
                "reaches the ceiling, so no air can return into its top; give the hall \
                 `returns` (ceiling grilles)",
            ));
        }
        let mut cells = *r;
        cells.lo[2] = plane;
        cells.hi[2] = plane + 1;
        self.horizontal_patch(cells, plane, name, field, "its top is covered")
    }

    /// A floor (`plane` 0) or ceiling (`plane` nz) rectangle.
    pub(super) fn plane_patch(
        &self,
        pos: [f64; 2],
        size: [f64; 2],
        plane: usize,
        name: String,
        field: &str,
        snap: &dyn Fn(f64, &str) -> Result<usize, OpenFoamError>,
    ) -> Result<FacePatch, OpenFoamError> {
        let mut lo = [0; 3];
        let mut hi = [0; 3];
        for a in 0..2 {
            lo[a] = snap(pos[a], &format!("{field}/position_m/{a}"))?;
            hi[a] = snap(pos[a] + size[a], &format!("{field}/size_m/{a}"))?;
            if hi[a] <= lo[a] || hi[a] > self.n[a] {
                return Err(geo(field, "empty or outside the room on the grid"));
            }
        }
        let k = if plane == 0 { 0 } else { self.n[2] - 1 };
        lo[2] = k;
        hi[2] = k + 1;
        self.horizontal_patch(CellRange { lo, hi }, plane, name, field, "covered")
    }

    /// The horizontal faces at grid line `plane` over the one cell layer `cells`, all of
    /// which must be fluid (else: `what` by the solid, naming its cell).
    fn horizontal_patch(
        &self,
        cells: CellRange,
        plane: usize,
        name: String,
        field: &str,
        what: &str,
    ) -> Result<FacePatch, OpenFoamError> {
        if let Some([i, j, k]) = self.first_solid(&cells) {
            return Err(geo(
                field,
                format!("{what} by a solid at cell ({i}, {j}, {k})"),
            ));
        }
        Ok(FacePatch {
            name,
            axis: 2,
            plane,
            faces: cells.count(),
            cells,
        })
    }
}
