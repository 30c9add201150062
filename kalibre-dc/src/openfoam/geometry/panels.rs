//! Containment panels on the grid. Each side of a containment box that is not on a room
//! wall, floor or ceiling is a plane of panels and doors. Air crosses it through the
//! faces between two fluid cells there (the faces a rack covers are walls or server
//! patches already), and in the built-in simulator those faces are the panels.
//!
//! In the OpenFOAM case a panel is the two layers of cells on either side of the plane,
//! made a porous zone that resists flow along the plane's normal only (Forchheimer: the
//! pressure drop of a sharp-edged orifice of the panels' open fraction, see
//! [`crate::openfoam::OpenFoamSettings::containment_leak_fraction`]). A porous zone is
//! implicit in the momentum equation; a baffle with an explicit pressure jump of that size
//! made SIMPLE diverge within 10 iterations. Two layers, because on a collocated grid the
//! flux through a face between a porous and a free cell sees half the free cell's
//! conductance: a one-cell zone let air through the panel plane almost freely (0.7 m/s
//! into a closed door's foot). The plane itself lies between two porous cells.

use crate::hall::Hall;
use crate::sim::WallSide;

use super::{geo, CaseGeometry, CellRange, OpenFoamError, GRID_TOL};

/// The sides of a containment box that can carry panels (the floor cannot): the side,
/// its name in zone names, its normal axis and whether it is the box's maximum there.
const SIDES: [(WallSide, &str, usize, bool); 5] = [
    (WallSide::MinusX, "xmin", 0, false),
    (WallSide::PlusX, "xmax", 0, true),
    (WallSide::MinusY, "ymin", 1, false),
    (WallSide::PlusY, "ymax", 1, true),
    (WallSide::Top, "top", 2, true),
];

/// Cells across a panel plane in its porous zone.
pub const PANEL_LAYER_CELLS: usize = 2;

/// One plane of containment panels.
#[derive(Debug, Clone, PartialEq)]
pub struct PanelPlane {
    /// Name of its porous cell zone (`cont0-xmin`).
    pub name: String,
    /// Index of the containment in `hall.containment`.
    pub containment: usize,
    /// Which side of the box (as the `containment_leakage` effect names them).
    pub side: WallSide,
    /// Normal axis (0 x, 1 y, 2 z).
    pub axis: usize,
    /// Grid line index of the plane along `axis`.
    pub plane: usize,
    /// Tangential extent (cell indices; the extent along `axis` is ignored).
    pub cells: CellRange,
    /// Faces between two fluid cells on the plane (where air can cross it).
    pub faces: usize,
    /// The porous zone: the two cell layers on either side of the plane (see the module
    /// docs), `PANEL_LAYER_CELLS` thick along `axis`.
    pub layer: CellRange,
}

/// A porous cell zone of the panels: cells that resist flow along each axis by the same
/// panel planes. Where two planes meet (a door and the roof, a door and the panel above
/// the racks) a cell lies in both planes' layers, and OpenFOAM gives a cell one zone
/// only, so such cells get a zone of their own that resists along both normals: with
/// one plane's zone alone, air went round the corner through them.
#[derive(Debug, Clone, PartialEq)]
pub struct PanelZone {
    /// Cell zone name (`panels0`, `panels1`, ...).
    pub name: String,
    /// Per axis, the index in [`CaseGeometry::panels`] of the plane whose resistance
    /// applies along it.
    pub axes: [Option<usize>; 3],
    /// The zone's fluid cells, as runs along x.
    pub runs: Vec<CellRange>,
}

/// The grid line index of `x` (m), which must lie on the `h` grid.
pub(super) fn grid_index(x: f64, h: f64, field: &str) -> Result<usize, OpenFoamError> {
    let r = x / h;
    if (r - r.round()).abs() > GRID_TOL * r.abs().max(1.0) || r < -GRID_TOL {
        return Err(geo(
            field,
            format!("{x} m is not on the {h} m grid (the OpenFOAM case needs edges on grid lines)"),
        ));
    }
    Ok(r.round() as usize)
}

impl CaseGeometry {
    /// The panel planes of every containment box of `hall`, in the hall's order and the
    /// order of [`SIDES`]; planes with no face between two fluid cells are left out.
    pub(super) fn containment_panels(&self, hall: &Hall) -> Result<Vec<PanelPlane>, OpenFoamError> {
        let mut out = Vec::new();
        for (c, cb) in hall.containment.iter().enumerate() {
            let mut range = CellRange {
                lo: [0; 3],
                hi: [0; 3],
            };
            for a in 0..3 {
                range.lo[a] =
                    grid_index(cb.min_m[a], self.h, &format!("/containment/{c}/min_m/{a}"))?;
                range.hi[a] =
                    grid_index(cb.max_m[a], self.h, &format!("/containment/{c}/max_m/{a}"))?;
                if range.hi[a] <= range.lo[a] || range.hi[a] > self.n[a] {
                    return Err(geo(
                        format!("/containment/{c}"),
                        "box is empty or outside the room on the grid",
                    ));
                }
            }
            for (side, side_name, axis, at_max) in SIDES {
                let plane = if at_max {
                    range.hi[axis]
                } else {
                    range.lo[axis]
                };
                if plane == 0 || plane == self.n[axis] {
                    continue; // on a room wall or the ceiling
                }
                let faces = self.fluid_faces_on(axis, plane, &range);
                if faces > 0 {
                    let mut layer = range;
                    // Half the zone on each side: the plane lies between porous cells.
                    layer.lo[axis] = plane.saturating_sub(PANEL_LAYER_CELLS / 2);
                    layer.hi[axis] = (plane + PANEL_LAYER_CELLS / 2).min(self.n[axis]);
                    out.push(PanelPlane {
                        name: format!("cont{c}-{side_name}"),
                        containment: c,
                        side,
                        axis,
                        plane,
                        cells: range,
                        faces,
                        layer,
                    });
                }
            }
        }
        Ok(out)
    }

    /// The panels' porous zones (see [`PanelZone`]), in a fixed order.
    pub(super) fn panel_zones(&self) -> Vec<PanelZone> {
        let mut by_cell: std::collections::BTreeMap<[usize; 3], [Option<usize>; 3]> =
            Default::default();
        for (k, p) in self.panels.iter().enumerate() {
            let r = &p.layer;
            for z in r.lo[2]..r.hi[2] {
                for y in r.lo[1]..r.hi[1] {
                    for x in r.lo[0]..r.hi[0] {
                        if self.is_solid([x, y, z]) {
                            continue;
                        }
                        // Keyed (z, y, x) so that runs along x come out in order.
                        by_cell.entry([z, y, x]).or_default()[p.axis].get_or_insert(k);
                    }
                }
            }
        }
        let mut zones: std::collections::BTreeMap<[Option<usize>; 3], Vec<CellRange>> =
            Default::default();
        for ([z, y, x], axes) in by_cell {
            let runs = zones.entry(axes).or_default();
            match runs.last_mut() {
                Some(run) if run.lo[1] == y && run.lo[2] == z && run.hi[0] == x => run.hi[0] += 1,
                _ => runs.push(CellRange {
                    lo: [x, y, z],
                    hi: [x + 1, y + 1, z + 1],
                }),
            }
        }
        zones
            .into_iter()
            .enumerate()
            .map(|(i, (axes, runs))| PanelZone {
                name: format!("panels{i}"),
                axes,
                runs,
            })
            .collect()
    }

    /// Faces on grid line `plane` of `axis`, over `range`'s tangential extent, with fluid
    /// on both sides.
    fn fluid_faces_on(&self, axis: usize, plane: usize, range: &CellRange) -> usize {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut count = 0;
        for i in range.lo[u]..range.hi[u] {
            for j in range.lo[v]..range.hi[v] {
                let mut below = [0; 3];
                below[axis] = plane - 1;
                below[u] = i;
                below[v] = j;
                let mut above = below;
                above[axis] = plane;
                if !self.is_solid(below) && !self.is_solid(above) {
                    count += 1;
                }
            }
        }
        count
    }
}
