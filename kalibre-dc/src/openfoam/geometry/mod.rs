//! The hall on the OpenFOAM grid: which cells are solid, which boundary faces form each
//! patch (server intakes and exhausts, tiles, bypass openings, returns), the containment
//! panels, the heated cell layers and the probe points, all checked in Rust before any
//! OpenFOAM program runs.
//!
//! Patch names are built from indices (`srv7-in`, `tile2`, `byp0`, `ret0`) because hall ids may
//! hold characters OpenFOAM does not accept in a word; the order is the hall's.

use crate::hall::{Aabb, Hall, SupplyKind};

use super::OpenFoamError;

mod panels;
mod patches;

use panels::grid_index;
pub use panels::{PanelPlane, PanelZone, PANEL_LAYER_CELLS};

/// Relative tolerance for "on the grid".
const GRID_TOL: f64 = 1e-6;

/// An axis-aligned index box of cells `[lo, hi)` per axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellRange {
    /// Lowest cell index per axis.
    pub lo: [usize; 3],
    /// One past the highest cell index per axis.
    pub hi: [usize; 3],
}

impl CellRange {
    fn count(&self) -> usize {
        (0..3).map(|a| self.hi[a] - self.lo[a]).product()
    }
}

/// A set of boundary faces on one plane: normal `axis`, at grid line `plane`, over the
/// tangential cell range of `cells` (its extent along `axis` is ignored).
#[derive(Debug, Clone, PartialEq)]
pub struct FacePatch {
    /// OpenFOAM patch name.
    pub name: String,
    /// Normal axis (0 x, 1 y, 2 z).
    pub axis: usize,
    /// Grid line index of the plane along `axis`.
    pub plane: usize,
    /// Tangential extent (cell indices).
    pub cells: CellRange,
    /// Number of faces (checked against the mesh OpenFOAM builds).
    pub faces: usize,
}

/// One server on the grid.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerPatches {
    /// Intake (air leaves the room here).
    pub intake: FacePatch,
    /// Exhaust (air re-enters the room here).
    pub exhaust: FacePatch,
    /// The fluid cell layer in front of the exhaust that receives the server's heat.
    pub heat_cells: CellRange,
}

/// What effects add to the mesh: bypass openings and recirculation gaps.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CaseExtras {
    /// Extra floor openings (`z` 0 boxes, as the `bypass` effect gives them).
    pub openings: Vec<Aabb>,
    /// Recirculation gaps through racks (the `rack_recirculation` effect).
    pub gaps: Vec<RackGap>,
}

/// A gap through a rack: `z_m` its height band; when `None` (a gap over the whole
/// height), one face row near the rack's middle, see [`CaseGeometry::with_extras`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RackGap {
    /// Index of the rack in `hall.racks`.
    pub rack: usize,
    /// Height band (m).
    pub z_m: Option<[f64; 2]>,
}

/// A gap's two patches: air leaves the room at the rack's exhaust side and re-enters at
/// its intake side, at the temperature it left with.
#[derive(Debug, Clone, PartialEq)]
pub struct GapPatches {
    /// The gap.
    pub gap: RackGap,
    /// Exhaust side (outflow).
    pub rear: FacePatch,
    /// Intake side (inflow).
    pub front: FacePatch,
}

/// A face of a CRAC that air passes: its front (a `front` CRAC's supply) or its top
/// (its return when the hall has no grilles).
#[derive(Debug, Clone, PartialEq)]
pub struct CracPatch {
    /// Index of the CRAC in `hall.cracs`.
    pub crac: usize,
    /// The face.
    pub patch: FacePatch,
}

/// The hall on the grid.
#[derive(Debug, Clone)]
pub struct CaseGeometry {
    /// Cell size (m).
    pub h: f64,
    /// Cells per axis.
    pub n: [usize; 3],
    /// Room size (m).
    pub size_m: [f64; 3],
    /// Solid boxes (racks, CRACs) as cell ranges.
    pub solids: Vec<CellRange>,
    /// Per server, hall order.
    pub servers: Vec<ServerPatches>,
    /// Per tile, hall order.
    pub tiles: Vec<FacePatch>,
    /// Extra floor openings that deliver part of the supply (the `bypass` effect), in the
    /// order given.
    pub openings: Vec<FacePatch>,
    /// Recirculation gaps through racks, in the order given.
    pub gaps: Vec<GapPatches>,
    /// Per return grille, hall order.
    pub returns: Vec<FacePatch>,
    /// The fronts of the `front` CRACs, where their supply enters (`sup<c>`, `c` the
    /// CRAC's index in the hall), hall order.
    pub crac_supplies: Vec<CracPatch>,
    /// With no return grilles, every CRAC's top, where it draws its own flow back in
    /// (`crt<c>`), hall order; empty otherwise.
    pub crac_returns: Vec<CracPatch>,
    /// Containment panel planes, per containment and side.
    pub panels: Vec<PanelPlane>,
    /// The panels' porous cell zones (disjoint).
    pub panel_zones: Vec<PanelZone>,
    /// Probe points (sensor positions), hall order.
    pub probes: Vec<[f64; 3]>,
    /// Fluid cells after cutting the solids.
    pub fluid_cells: usize,
    solid: Vec<bool>,
}

fn geo(field: impl Into<String>, message: impl Into<String>) -> OpenFoamError {
    OpenFoamError::Geometry {
        field: field.into(),
        message: message.into(),
    }
}

impl CaseGeometry {
    /// Everything the mesh is built from, as text (for the case directory's key): the
    /// geometry without its per-cell solid map, which the solid boxes give. (Every field
    /// is named, so that a field added later must be placed here or left out on
    /// purpose.)
    pub fn mesh_description(&self) -> String {
        let CaseGeometry {
            h,
            n,
            size_m,
            solids,
            servers,
            tiles,
            openings,
            gaps,
            returns,
            crac_supplies,
            crac_returns,
            panels,
            panel_zones,
            probes,
            fluid_cells,
            solid: _,
        } = self;
        let mut text = format!(
            "{h:?} {n:?} {size_m:?} {solids:?} {servers:?} {tiles:?} {openings:?} {gaps:?} \
             {returns:?} {panels:?} {panel_zones:?} {probes:?} {fluid_cells:?}"
        );
        // Only when there are any: a hall of floor CRACs and grilles keeps the key (and
        // the meshed case) it had before CRAC faces could be patches.
        if !crac_supplies.is_empty() || !crac_returns.is_empty() {
            text += &format!(" {crac_supplies:?} {crac_returns:?}");
        }
        text
    }

    /// Places `hall` on a grid of cell size `h` (m). Every box edge must lie on a grid line.
    pub fn new(hall: &Hall, h: f64) -> Result<Self, OpenFoamError> {
        Self::with_extras(hall, h, &CaseExtras::default())
    }

    /// As [`CaseGeometry::new`], with what effects add:
    /// - floor openings become inflow patches `byp0`, `byp1`, ... in order; each must lie
    ///   on the grid, on fluid floor, clear of the tiles and of the other openings (a face
    ///   belongs to one patch only);
    /// - each gap takes its rack's face rows over its band on both sides as patches
    ///   `rec<r>-out` and `rec<r>-in`, and the rack's servers draw through the rest of
    ///   their faces; a gap must not split a server's span nor cover it, and a rack has
    ///   at most one gap. Without a band (a gap over the whole height) it takes one row:
    ///   the one above the boundary between two servers nearest the rack's middle (the
    ///   centre of an even release), or the top row when one server fills the rack.
    pub fn with_extras(hall: &Hall, h: f64, extras: &CaseExtras) -> Result<Self, OpenFoamError> {
        let openings = &extras.openings;
        if !(h.is_finite() && h > 0.0) {
            return Err(OpenFoamError::Setting {
                name: "grid_m".into(),
                reason: format!("{h} is not a positive cell size"),
            });
        }
        let snap = |x: f64, field: &str| grid_index(x, h, field);
        let size = hall.room.size_m;
        let mut n = [0usize; 3];
        for a in 0..3 {
            n[a] = snap(size[a], &format!("/room/size_m/{a}"))?;
            if n[a] == 0 {
                return Err(geo(format!("/room/size_m/{a}"), "smaller than one cell"));
            }
        }
        let boxr = |pos: [f64; 3], sz: [f64; 3], field: &str| -> Result<CellRange, OpenFoamError> {
            let mut lo = [0; 3];
            let mut hi = [0; 3];
            for a in 0..3 {
                lo[a] = snap(pos[a], &format!("{field}/position_m/{a}"))?;
                hi[a] = snap(pos[a] + sz[a], &format!("{field}/size_m/{a}"))?;
                if hi[a] <= lo[a] || hi[a] > n[a] {
                    return Err(geo(field, "box is empty or outside the room on the grid"));
                }
            }
            Ok(CellRange { lo, hi })
        };
        let mut solids = Vec::new();
        for (i, c) in hall.cracs.iter().enumerate() {
            solids.push(boxr(c.position_m, c.size_m, &format!("/cracs/{i}"))?);
        }
        let crac_ranges: Vec<CellRange> = solids.clone();
        let rack_ranges: Vec<CellRange> = hall
            .racks
            .iter()
            .enumerate()
            .map(|(i, r)| boxr(r.position_m, r.size_m, &format!("/racks/{i}")))
            .collect::<Result<_, _>>()?;
        solids.extend(rack_ranges.iter().copied());
        let mut solid = vec![false; n[0] * n[1] * n[2]];
        let idx = |i: usize, j: usize, k: usize| i + n[0] * (j + n[1] * k);
        for s in &solids {
            for k in s.lo[2]..s.hi[2] {
                for j in s.lo[1]..s.hi[1] {
                    for i in s.lo[0]..s.hi[0] {
                        solid[idx(i, j, k)] = true;
                    }
                }
            }
        }
        let fluid_cells = solid.iter().filter(|s| !**s).count();
        let mut g = CaseGeometry {
            h,
            n,
            size_m: size,
            solids,
            servers: Vec::new(),
            tiles: Vec::new(),
            openings: Vec::new(),
            gaps: Vec::new(),
            returns: Vec::new(),
            crac_supplies: Vec::new(),
            crac_returns: Vec::new(),
            panels: Vec::new(),
            panel_zones: Vec::new(),
            probes: Vec::new(),
            fluid_cells,
            solid,
        };
        g.panels = g.containment_panels(hall)?;
        g.panel_zones = g.panel_zones();

        // Face rows [lo, hi) of each gap, per rack.
        let mut gap_rows: Vec<Option<(usize, usize)>> = vec![None; hall.racks.len()];
        for (r, gap) in extras.gaps.iter().enumerate() {
            let field = format!("recirculation gap {r}");
            let rr = *rack_ranges
                .get(gap.rack)
                .ok_or_else(|| geo(&field, format!("no rack {}", gap.rack)))?;
            let rows = match gap.z_m {
                // One face row stands for a gap over the whole height: the row above the
                // boundary between two of the rack's servers nearest the rack's middle
                // (the centre of an even release; a row cannot split a server), or the
                // top row when one server fills the rack.
                None => {
                    let mid2 = rr.lo[2] + rr.hi[2];
                    let boundary = hall
                        .servers()
                        .filter(|s| s.rack_index == gap.rack)
                        .map(|s| face_row(server_span_m(&s)[0], h))
                        .filter(|k| *k > rr.lo[2] && *k < rr.hi[2])
                        .min_by_key(|k| (2 * k).abs_diff(mid2));
                    match boundary {
                        Some(k) => (k, k + 1),
                        None => (rr.hi[2] - 1, rr.hi[2]),
                    }
                }
                Some([z0, z1]) => {
                    let lo = face_row(z0, h).max(rr.lo[2]);
                    let hi = face_row(z1, h).min(rr.hi[2]);
                    if hi <= lo {
                        return Err(geo(
                            &field,
                            format!("z {z0}-{z1} m holds no {h} m face row of its rack"),
                        ));
                    }
                    (lo, hi)
                }
            };
            if gap_rows[gap.rack].replace(rows).is_some() {
                return Err(geo(&field, "a second gap in the same rack"));
            }
        }

        for s in hall.servers() {
            let rack = s.rack;
            let rr = rack_ranges[s.rack_index];
            let [z0, z1] = server_span_m(&s);
            let k_lo = face_row(z0, h);
            let k_hi = face_row(z1, h).min(rr.hi[2]);
            let field = format!("server `{}`", s.server.id);
            if k_hi <= k_lo {
                return Err(geo(
                    &field,
                    format!("spans z {z0:.3}-{z1:.3} m, less than one {h} m cell face"),
                ));
            }
            let (mut k_lo, mut k_hi) = (k_lo, k_hi);
            if let Some((g_lo, g_hi)) = gap_rows[s.rack_index] {
                if g_lo < k_hi && k_lo < g_hi {
                    if g_lo <= k_lo && g_hi >= k_hi {
                        return Err(geo(&field, "lies entirely in its rack's recirculation gap"));
                    } else if g_lo <= k_lo {
                        k_lo = g_hi;
                    } else if g_hi >= k_hi {
                        k_hi = g_lo;
                    } else {
                        return Err(geo(
                            &field,
                            "its rack's recirculation gap splits the server's span (the OpenFOAM \
                             case needs the gap at a server's edge)",
                        ));
                    }
                }
            }
            let mut span = rr;
            span.lo[2] = k_lo;
            span.hi[2] = k_hi;
            let intake = g.side_patch(&span, rack.inlet, format!("srv{}-in", s.index), &field)?;
            let exhaust = g.side_patch(
                &span,
                rack.inlet.opposite(),
                format!("srv{}-out", s.index),
                &field,
            )?;
            let (axis, sign) = rack.inlet.opposite().axis_sign();
            let mut heat = span;
            if sign > 0.0 {
                heat.lo[axis] = span.hi[axis];
                heat.hi[axis] = span.hi[axis] + 1;
            } else {
                heat.lo[axis] = span.lo[axis] - 1;
                heat.hi[axis] = span.lo[axis];
            }
            g.servers.push(ServerPatches {
                intake,
                exhaust,
                heat_cells: heat,
            });
        }
        for (t, tile) in hall.tiles.iter().enumerate() {
            let p = g.plane_patch(
                tile.position_m,
                tile.size_m,
                0,
                format!("tile{t}"),
                &format!("/tiles/{t}"),
                &snap,
            )?;
            g.tiles.push(p);
        }
        for (b, o) in openings.iter().enumerate() {
            let field = format!("bypass opening {b}");
            if o.min[2].abs() > GRID_TOL || o.max[2].abs() > GRID_TOL {
                return Err(geo(
                    &field,
                    "not on the floor (the case has floor openings only)",
                ));
            }
            let p = g.plane_patch(
                [o.min[0], o.min[1]],
                [o.max[0] - o.min[0], o.max[1] - o.min[1]],
                0,
                format!("byp{b}"),
                &field,
                &snap,
            )?;
            let clash = g
                .tiles
                .iter()
                .map(|t| (t, "a tile"))
                .chain(g.openings.iter().map(|t| (t, "another opening")))
                .find(|(t, _)| overlap(&t.cells, &p.cells));
            if let Some((t, what)) = clash {
                return Err(geo(
                    &field,
                    format!("overlaps {what} (`{}`) on the grid", t.name),
                ));
            }
            g.openings.push(p);
        }
        for (r, gap) in extras.gaps.iter().enumerate() {
            let field = format!("recirculation gap {r}");
            let (lo, hi) = gap_rows[gap.rack].expect("rows of every gap");
            let rack = &hall.racks[gap.rack];
            let mut span = rack_ranges[gap.rack];
            span.lo[2] = lo;
            span.hi[2] = hi;
            let rear = g.side_patch(&span, rack.inlet.opposite(), format!("rec{r}-out"), &field)?;
            let front = g.side_patch(&span, rack.inlet, format!("rec{r}-in"), &field)?;
            g.gaps.push(GapPatches {
                gap: *gap,
                rear,
                front,
            });
        }
        for (r, ret) in hall.returns.iter().enumerate() {
            let p = g.plane_patch(
                ret.position_m,
                ret.size_m,
                n[2],
                format!("ret{r}"),
                &format!("/returns/{r}"),
                &snap,
            )?;
            g.returns.push(p);
        }
        for (c, crac) in hall.cracs.iter().enumerate() {
            let field = format!("/cracs/{c}");
            if crac.supply == SupplyKind::Front {
                // The face the built-in simulator blows through, over the CRAC's height.
                let side = crate::sim::front_side(
                    hall,
                    &Aabb::from_position_size(crac.position_m, crac.size_m),
                );
                let patch = g.side_patch(&crac_ranges[c], side, format!("sup{c}"), &field)?;
                g.crac_supplies.push(CracPatch { crac: c, patch });
            }
            if hall.returns.is_empty() {
                let patch = g.top_patch(&crac_ranges[c], format!("crt{c}"), &field)?;
                g.crac_returns.push(CracPatch { crac: c, patch });
            }
        }
        for (i, s) in hall.sensors.iter().enumerate() {
            let p = s.position_m;
            let mut c = [0usize; 3];
            for a in 0..3 {
                if !(p[a] > 0.0 && p[a] < size[a]) {
                    return Err(geo(format!("/sensors/{i}/position_m"), "outside the room"));
                }
                c[a] = ((p[a] / h).floor() as usize).min(n[a] - 1);
            }
            if g.solid[idx(c[0], c[1], c[2])] {
                return Err(geo(
                    format!("/sensors/{i}"),
                    format!("sensor `{}` is inside a rack or CRAC on the grid", s.id),
                ));
            }
            g.probes.push(p);
        }
        Ok(g)
    }

    /// A box (m) that holds exactly the face centres of `p`.
    pub fn face_box(&self, p: &FacePatch) -> ([f64; 3], [f64; 3]) {
        let h = self.h;
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for a in 0..3 {
            if a == p.axis {
                lo[a] = p.plane as f64 * h - 0.25 * h;
                hi[a] = p.plane as f64 * h + 0.25 * h;
            } else {
                lo[a] = p.cells.lo[a] as f64 * h + 0.25 * h;
                hi[a] = p.cells.hi[a] as f64 * h - 0.25 * h;
            }
        }
        (lo, hi)
    }

    /// A box (m) that holds exactly the cell centres of `r`.
    pub fn cell_box(&self, r: &CellRange) -> ([f64; 3], [f64; 3]) {
        let h = self.h;
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for a in 0..3 {
            lo[a] = r.lo[a] as f64 * h + 0.25 * h;
            hi[a] = r.hi[a] as f64 * h - 0.25 * h;
        }
        (lo, hi)
    }

    /// The patches through which air enters or leaves the room (tiles, openings,
    /// grilles, CRAC faces and tops), not those it passes through a rack by: what the
    /// energy balance is taken over.
    pub fn room_openings(&self) -> impl Iterator<Item = &FacePatch> {
        self.tiles
            .iter()
            .chain(&self.openings)
            .chain(&self.returns)
            .chain(self.crac_supplies.iter().map(|c| &c.patch))
            .chain(self.crac_returns.iter().map(|c| &c.patch))
    }

    /// Every patch other than the walls, in the order they are created.
    pub fn patches(&self) -> impl Iterator<Item = &FacePatch> {
        self.servers
            .iter()
            .flat_map(|s| [&s.intake, &s.exhaust])
            .chain(&self.tiles)
            .chain(&self.openings)
            .chain(self.gaps.iter().flat_map(|g| [&g.rear, &g.front]))
            .chain(&self.returns)
            .chain(self.crac_supplies.iter().map(|c| &c.patch))
            .chain(self.crac_returns.iter().map(|c| &c.patch))
    }
}

/// A server's height span `[z0, z1]` (m) from its rack's units.
fn server_span_m(s: &crate::hall::ServerRef<'_>) -> [f64; 2] {
    let rack = s.rack;
    let units = rack.units.max(1) as f64;
    let z0 = rack.position_m[2] + (s.server.u as f64 - 1.0) / units * rack.size_m[2];
    [z0, z0 + s.server.height_u as f64 / units * rack.size_m[2]]
}

/// The first face row whose centre lies at or above `z` (m): a span `[z0, z1)` covers
/// rows `face_row(z0)..face_row(z1)`, so servers off the grid still get the faces
/// nearest their span.
fn face_row(z: f64, h: f64) -> usize {
    ((z / h) - 0.5).ceil().max(0.0) as usize
}

/// Whether two cell ranges share a cell.
fn overlap(a: &CellRange, b: &CellRange) -> bool {
    (0..3).all(|k| a.lo[k] < b.hi[k] && b.lo[k] < a.hi[k])
}

#[cfg(test)]
mod tests;
