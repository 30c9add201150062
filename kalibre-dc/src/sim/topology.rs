//! The symbolic part of the simulator, built once per hall and grid: solid cells, open
//! faces and their conductances, containment walls, supply and return cells, server
//! intake and exhaust cells with weights, and sensor interpolation stencils.

use std::collections::HashSet;

use super::grid::{metres_text, Grid, GEOM_EPS};
use super::mods::WallSide;
use super::panel::panel_face_g;
use super::{FrontSupply, SimConfig};
use crate::hall::{Aabb, Hall, Side, SupplyKind};
use crate::snapshots::number;
use crate::{Error, Result};

/// Cells with weights summing to one.
pub(crate) type Stencil = Vec<(usize, f64)>;

/// One containment face crossing: axis and the cell on its low side.
#[derive(Debug, Clone, Copy)]
pub(crate) struct WallFace {
    pub axis: usize,
    pub low: usize,
}

/// The grid topology of a hall.
#[derive(Debug, Clone)]
pub(crate) struct Topology {
    pub grid: Grid,
    /// Solid (rack, CRAC) or inactive (enclosed, no flow) cells.
    pub solid: Vec<bool>,
    /// Conductance (m) of the face between `c` and `c + stride(a)`; 0 when closed.
    pub g: [Vec<f64>; 3],
    /// Conductance (m) from a cell to a fixed-pressure outlet (ceiling returns, or the
    /// gauge cell when there are none).
    pub g_outlet: Vec<f64>,
    /// True when the hall has ceiling returns (else air returns into CRAC tops).
    pub has_returns: bool,
    /// Cells of each tile with weights (each tile's flow: [`super::supply::split_over_tiles`]).
    pub tiles: Vec<Stencil>,
    /// Per CRAC: the cells its supply enters (front face cells for `front` CRACs; empty
    /// for `floor` CRACs).
    pub crac_front: Vec<Stencil>,
    /// Per CRAC: cells above its top face that take its return flow (no returns only).
    pub crac_top: Vec<Stencil>,
    /// Per server (hall order): intake and exhaust cells with weights.
    pub server_intake: Vec<Stencil>,
    /// Exhaust cells per server.
    pub server_exhaust: Vec<Stencil>,
    /// Sensor trilinear stencils (hall order).
    pub sensors: Vec<Stencil>,
    /// Per containment, per side (`WallSide::ALL` order): the wall faces between fluid cells.
    pub walls: Vec<[Vec<WallFace>; 5]>,
    /// The sensors (hall order) within half a cell of a containment panel, whose
    /// stencils leave out the cell centres across it.
    pub sensors_beside_panels: Vec<usize>,
}

/// Full (open) conductance of a face normal to axis `a`: area over centre distance.
fn full_g(grid: &Grid, a: usize) -> f64 {
    grid.face_area(a) / grid.d[a]
}

/// The most cells the built-in simulator builds. A solve holds about 300 bytes per cell
/// (the `demo` hall at 0.1 m: 302,400 cells, 100 MB resident), so this is about 9 GB.
pub const MAX_CELLS: usize = 30_000_000;

/// How many cells a room of `size_m` needs at `cell_m`, when that is more than the
/// built-in simulator builds ([`MAX_CELLS`]); counted before any grid is, so that a room
/// of 1e308 m cannot overflow `usize`.
pub fn cells_beyond_cap(size_m: [f64; 3], cell_m: f64) -> Option<f64> {
    let cells = Grid::cell_count(size_m, cell_m);
    (cells.is_nan() || cells > MAX_CELLS as f64).then_some(cells)
}

impl Topology {
    pub fn build(hall: &Hall, config: &SimConfig) -> Result<Self> {
        if let Some(cells) = cells_beyond_cap(hall.room.size_m, config.cell_m) {
            let [x, y, z] = hall.room.size_m.map(crate::snapshots::number);
            return Err(Error::Geometry(format!(
                "the room ({x} x {y} x {z} m) at cells of {} m needs {cells:.3e} cells; \
                 the built-in simulator takes at most {MAX_CELLS}: use coarser cells \
                 (`--grid-m`) or check the room size",
                config.cell_m
            )));
        }
        let grid = Grid::new(hall.room.size_m, config.cell_m);
        let n = grid.len();
        let mut solid = vec![false; n];
        for r in &hall.racks {
            for c in grid.cells_in_box(&Aabb::from_position_size(r.position_m, r.size_m)) {
                solid[c] = true;
            }
        }
        for cr in &hall.cracs {
            for c in grid.cells_in_box(&Aabb::from_position_size(cr.position_m, cr.size_m)) {
                solid[c] = true;
            }
        }
        let mut g: [Vec<f64>; 3] = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        for (a, ga) in g.iter_mut().enumerate() {
            let s = grid.stride(a);
            let gf = full_g(&grid, a);
            for (c, v) in ga.iter_mut().enumerate() {
                let ijk = grid.ijk(c);
                if ijk[a] + 1 < grid.n[a] && !solid[c] && !solid[c + s] {
                    *v = gf;
                }
            }
        }
        let walls = containment_walls(
            hall,
            &grid,
            &solid,
            &mut g,
            config.containment_leak_fraction,
            config.containment_panel_m,
        );

        // Returns: ceiling cells under each grille, Dirichlet p = 0 half a cell away.
        let mut g_outlet = vec![0.0; n];
        let top = grid.n[2] - 1;
        let g_half = grid.face_area(2) / (0.5 * grid.d[2]);
        for (ri, r) in hall.returns.iter().enumerate() {
            let b = Aabb {
                min: [r.position_m[0], r.position_m[1], hall.room.size_m[2]],
                max: [
                    r.position_m[0] + r.size_m[0],
                    r.position_m[1] + r.size_m[1],
                    hall.room.size_m[2],
                ],
            };
            let cells = layer_cells(&grid, &b, top);
            let open: Vec<usize> = cells.into_iter().filter(|&c| !solid[c]).collect();
            if open.is_empty() {
                return Err(Error::Geometry(format!(
                    "return {ri} lies over solid cells only on cells of {} x {} m (the {} m \
                     asked for, fitted to the room): use finer cells (`--grid-m`)",
                    metres_text(grid.d[0]),
                    metres_text(grid.d[1]),
                    number(config.cell_m)
                )));
            }
            for c in open {
                g_outlet[c] = g_half;
            }
        }
        let has_returns = !hall.returns.is_empty();

        let mut tiles = Vec::with_capacity(hall.tiles.len());
        for (ti, t) in hall.tiles.iter().enumerate() {
            let b = Aabb {
                min: [t.position_m[0], t.position_m[1], 0.0],
                max: [
                    t.position_m[0] + t.size_m[0],
                    t.position_m[1] + t.size_m[1],
                    0.0,
                ],
            };
            // The hall keeps tiles clear of racks (hall validation); on a grid their edges
            // do not fall on, a tile's snapped footprint can still reach a cell of the
            // rack it abuts. That cell is the rack's, and the tile blows through the rest
            // with its whole share, as a return grille over solid cells does.
            let cells: Vec<usize> = layer_cells(&grid, &b, 0)
                .into_iter()
                .filter(|&c| !solid[c])
                .collect();
            if cells.is_empty() {
                return Err(Error::Geometry(format!(
                    "tile {ti} at {:?} lies over solid cells only on cells of {} x {} m (the {} \
                     m asked for, fitted to the room): use finer cells (`--grid-m`)",
                    t.position_m,
                    metres_text(grid.d[0]),
                    metres_text(grid.d[1]),
                    number(config.cell_m)
                )));
            }
            let w = 1.0 / cells.len() as f64;
            tiles.push(cells.into_iter().map(|c| (c, w)).collect());
        }

        let mut crac_front = Vec::with_capacity(hall.cracs.len());
        let mut crac_top = Vec::with_capacity(hall.cracs.len());
        for (i, cr) in hall.cracs.iter().enumerate() {
            let b = Aabb::from_position_size(cr.position_m, cr.size_m);
            crac_front.push(match cr.supply {
                SupplyKind::Floor => Vec::new(),
                SupplyKind::Front => {
                    let side = front_side(hall, &b);
                    match config.front_supply {
                        FrontSupply::Jet => jet_stencil(&grid, &solid, &b, side),
                        FrontSupply::Face => {
                            face_stencil(&grid, &solid, &b, side, [b.min[2], b.max[2]])
                        }
                    }
                    .ok_or_else(|| {
                        Error::Geometry(format!(
                            "/cracs/{i}: CRAC `{}` supplies through its front, the {} face \
                                 (opposite the wall it stands against), and no air cell lies \
                                 in front of it; expected room in front of a `front` CRAC \
                                 (or `supply` `floor`)",
                            cr.id,
                            side.as_str()
                        ))
                    })?
                }
            });
            crac_top.push(if has_returns {
                Vec::new()
            } else {
                top_stencil(&grid, &solid, &b).ok_or_else(|| {
                    Error::Geometry(format!(
                        "/cracs/{i}: CRAC `{}` reaches the ceiling and the hall has no \
                         `returns`, so its air has no way back (without returns it returns \
                         into each CRAC's top); expected a CRAC lower than the room, or \
                         `returns`",
                        cr.id
                    ))
                })?
            });
        }
        // Without returns, one CRAC-top cell fixes the pressure level; the fluxes balance,
        // so no flow passes through it.
        if !has_returns {
            if let Some(&(c, _)) = crac_top.first().and_then(|s| s.first()) {
                g_outlet[c] = g_half;
            }
        }

        let mut server_intake = Vec::new();
        let mut server_exhaust = Vec::new();
        for s in hall.servers() {
            let b = s.bounds();
            let z = [b.min[2], b.max[2]];
            let rb = Aabb::from_position_size(s.rack.position_m, s.rack.size_m);
            // The JSON pointer first, so the CLI can name the hall file's field.
            let blocked = |face: &str| {
                let rack = hall.racks.iter().position(|r| r.id == s.rack.id);
                Error::Geometry(format!(
                    "/racks/{}/inlet: server `{}` of rack `{}`: no open cell at its {face}{}",
                    rack.unwrap_or_default(),
                    s.server.id,
                    s.rack.id,
                    face_hint(&grid, s.rack.size_m)
                ))
            };
            let inl = face_stencil(&grid, &solid, &rb, s.rack.inlet, z)
                .ok_or_else(|| blocked("intake"))?;
            let exh = face_stencil(&grid, &solid, &rb, s.rack.inlet.opposite(), z)
                .ok_or_else(|| blocked("exhaust"))?;
            server_intake.push(inl);
            server_exhaust.push(exh);
        }

        let mut topo = Topology {
            grid,
            solid,
            g,
            g_outlet,
            has_returns,
            tiles,
            crac_front,
            crac_top,
            server_intake,
            server_exhaust,
            sensors: Vec::new(),
            walls,
            sensors_beside_panels: Vec::new(),
        };
        topo.deactivate_enclosed(hall)?;
        let panels: HashSet<(usize, usize)> = (topo.walls.iter().flatten().flatten())
            .map(|f| (f.axis, f.low))
            .collect();
        for (i, s) in hall.sensors.iter().enumerate() {
            let (st, beside_panel) =
                topo.sensor_stencil(s.position_m, &panels).ok_or_else(|| {
                    Error::Geometry(format!("sensor `{}`: no open cell around it", s.id))
                })?;
            topo.sensors.push(st);
            if beside_panel {
                topo.sensors_beside_panels.push(i);
            }
        }
        Ok(topo)
    }

    /// Marks fluid regions without any outlet as inactive; refuses one that has inflow,
    /// servers or supply (its mass balance would have no solution).
    fn deactivate_enclosed(&mut self, hall: &Hall) -> Result<()> {
        let n = self.grid.len();
        let mut comp = vec![usize::MAX; n];
        let mut anchored = Vec::new();
        let mut stack = Vec::new();
        for start in 0..n {
            if self.solid[start] || comp[start] != usize::MAX {
                continue;
            }
            let id = anchored.len();
            let mut has_outlet = false;
            comp[start] = id;
            stack.push(start);
            while let Some(c) = stack.pop() {
                has_outlet |= self.g_outlet[c] > 0.0;
                for a in 0..3 {
                    let s = self.grid.stride(a);
                    if self.g[a][c] > 0.0 && comp[c + s] == usize::MAX {
                        comp[c + s] = id;
                        stack.push(c + s);
                    }
                    if c >= s && self.g[a][c - s] > 0.0 && comp[c - s] == usize::MAX {
                        comp[c - s] = id;
                        stack.push(c - s);
                    }
                }
            }
            anchored.push(has_outlet);
        }
        let lost = |st: &Stencil| st.iter().any(|&(c, _)| !anchored[comp[c]]);
        for (s, (i, e)) in hall
            .servers()
            .zip(self.server_intake.iter().zip(&self.server_exhaust))
        {
            if lost(i) || lost(e) {
                return Err(Error::Geometry(format!(
                    "server `{}` draws or exhausts into an enclosed region with no return path \
                     (add a return, or containment leakage)",
                    s.server.id
                )));
            }
        }
        if self.tiles.iter().any(lost) || self.crac_front.iter().chain(&self.crac_top).any(lost) {
            return Err(Error::Geometry(
                "a tile or CRAC opens into an enclosed region with no return path".into(),
            ));
        }
        for c in 0..n {
            if !self.solid[c] && !anchored[comp[c]] {
                self.solid[c] = true;
                for a in 0..3 {
                    let s = self.grid.stride(a);
                    self.g[a][c] = 0.0;
                    if c >= s {
                        self.g[a][c - s] = 0.0;
                    }
                }
            }
        }
        Ok(())
    }

    /// Trilinear weights of the eight cell centres around `p`, solid ones and those
    /// across a containment panel (a face of `panels`, `(axis, low cell)`) from the cell
    /// holding `p` dropped and the rest renormalised; `None` when all eight are solid. The
    /// flag says whether a panel dropped any: a sensor beside a panel reads its own side's
    /// air, not a blend with the other side's, degrees apart.
    pub fn sensor_stencil(
        &self,
        p: [f64; 3],
        panels: &HashSet<(usize, usize)>,
    ) -> Option<(Stencil, bool)> {
        let g = &self.grid;
        let own = [0, 1, 2].map(|a| g.cell_of(a, p[a]));
        // Across a panel: a step on some axis from the sensor's cell to the corner's slab
        // goes through a panel face, at the sensor's or at the corner's place.
        let across = |c: usize| {
            let ijk = g.ijk(c);
            (0..3).any(|a| {
                if ijk[a] == own[a] {
                    return false;
                }
                let low_slab = ijk[a].min(own[a]);
                [own, ijk].iter().any(|at| {
                    let mut face = *at;
                    face[a] = low_slab;
                    panels.contains(&(a, g.idx(face[0], face[1], face[2])))
                })
            })
        };
        let all = g.trilinear_corners(p);
        let (corners, dropped): (Stencil, Stencil) =
            all.into_iter().partition(|&(c, _)| !across(c));
        let beside_panel = dropped.iter().any(|&(_, w)| w > 1e-12);
        let corners = if corners.is_empty() {
            all.to_vec()
        } else {
            corners
        };
        let st: Vec<(usize, f64)> = corners
            .iter()
            .copied()
            .filter(|&(c, w)| w > 1e-12 && !self.solid[c])
            .collect();
        let total: f64 = st.iter().map(|(_, w)| w).sum();
        if total <= 1e-12 {
            // Point within a cell of a solid: the nearest fluid corner.
            let mut best: Option<(usize, f64)> = None;
            for &(c, _) in &corners {
                if !self.solid[c] {
                    let d = super::super::hall::distance(g.cell_centre(c), p);
                    if best.is_none_or(|(_, bd)| d < bd) {
                        best = Some((c, d));
                    }
                }
            }
            return best.map(|(c, _)| (vec![(c, 1.0)], beside_panel));
        }
        Some((
            st.into_iter().map(|(c, w)| (c, w / total)).collect(),
            beside_panel,
        ))
    }

    /// Intake or exhaust cells of a rack (whole face, or a height band), for effects.
    pub fn rack_face(
        &self,
        hall: &Hall,
        rack: usize,
        side: Side,
        z: Option<[f64; 2]>,
    ) -> Option<Stencil> {
        let r = &hall.racks[rack];
        let b = Aabb::from_position_size(r.position_m, r.size_m);
        let z = z.unwrap_or([b.min[2], b.max[2]]);
        face_stencil(&self.grid, &self.solid, &b, side, z)
    }

    /// Open cells whose centres lie in a box, evenly weighted (`None` when none is open).
    pub fn box_stencil(&self, b: &Aabb) -> Option<Stencil> {
        let cells: Vec<usize> = self
            .grid
            .cells_in_box(b)
            .into_iter()
            .filter(|&c| !self.solid[c])
            .collect();
        if cells.is_empty() {
            return None;
        }
        let w = 1.0 / cells.len() as f64;
        Some(cells.into_iter().map(|c| (c, w)).collect())
    }
}

/// Why a rack face may have no open cell: the rack thinner than a cell on some axis, or
/// its face against a wall, a CRAC or another rack.
fn face_hint(grid: &Grid, size_m: [f64; 3]) -> String {
    let thin = (0..3).find(|&a| size_m[a] < grid.d[a]);
    match thin {
        Some(a) => format!(
            " (its rack is {} m across in {}, less than a cell of {} m: the grid cannot \
             hold it; check its `size_m` or use finer cells, `--grid-m`)",
            number(size_m[a]),
            ["x", "y", "z"][a],
            metres_text(grid.d[a])
        ),
        None => " (the face may stand against a wall, a CRAC or another rack)".into(),
    }
}

/// Cells of layer `k` under the xy extent of `b`.
fn layer_cells(grid: &Grid, b: &Aabb, k: usize) -> Vec<usize> {
    let mut bb = *b;
    bb.min[2] = grid.centre(2, k);
    bb.max[2] = bb.min[2];
    grid.cells_in_box(&bb)
}

/// The side of a CRAC box that blows into the room (its front): the face opposite the
/// wall it stands against, so that where it stands along that wall does not turn it;
/// in a corner, or standing free, of the sides whose backs are nearest a wall, the one
/// facing the most open room.
pub(crate) fn front_side(hall: &Hall, b: &Aabb) -> Side {
    let room = hall.room.size_m;
    let room_space = |s: Side| match s {
        Side::PlusX => room[0] - b.max[0],
        Side::MinusX => b.min[0],
        Side::PlusY => room[1] - b.max[1],
        Side::MinusY => b.min[1],
    };
    let sides = [Side::PlusX, Side::MinusX, Side::PlusY, Side::MinusY];
    let nearest_wall = sides
        .iter()
        .map(|&s| room_space(s.opposite()))
        .fold(f64::INFINITY, f64::min);
    sides
        .into_iter()
        .filter(|&s| room_space(s.opposite()) <= nearest_wall + GEOM_EPS)
        .fold(None, |best: Option<Side>, s| match best {
            Some(b) if room_space(s) <= room_space(b) + GEOM_EPS => Some(b),
            _ => Some(s),
        })
        .unwrap_or(Side::PlusX)
}

/// The first open cells outside face `side` of box `b`, over the box's tangential extent
/// and the height band `z`, weighted by overlap area; `None` when none is open.
pub(crate) fn face_stencil(
    grid: &Grid,
    solid: &[bool],
    b: &Aabb,
    side: Side,
    z: [f64; 2],
) -> Option<Stencil> {
    let (a, sign) = side.axis_sign();
    let t = 1 - a;
    // First cell whose centre lies outside the box on that side.
    let out = if sign > 0.0 {
        let i = (b.max[a] / grid.d[a] - 0.5 + GEOM_EPS).floor() + 1.0;
        if i >= grid.n[a] as f64 {
            return None;
        }
        i.max(0.0) as usize
    } else {
        let i = (b.min[a] / grid.d[a] - 0.5 - GEOM_EPS).ceil() - 1.0;
        if i < 0.0 {
            return None;
        }
        i as usize
    };
    let mut st = Vec::new();
    for k in grid.overlapping(2, z[0], z[1]) {
        let wz = grid.overlap(2, k, z[0], z[1]);
        for it in grid.overlapping(t, b.min[t], b.max[t]) {
            let wt = grid.overlap(t, it, b.min[t], b.max[t]);
            let mut ijk = [0; 3];
            ijk[a] = out;
            ijk[t] = it;
            ijk[2] = k;
            let c = grid.idx(ijk[0], ijk[1], ijk[2]);
            if !solid[c] && wz * wt > 0.0 {
                st.push((c, wz * wt));
            }
        }
    }
    let total: f64 = st.iter().map(|(_, w)| w).sum();
    if total <= 0.0 {
        return None;
    }
    Some(st.into_iter().map(|(c, w)| (c, w / total)).collect())
}

/// Where a `front` CRAC's supply enters: along its jet. The cells just outside face
/// `side` of `b` ([`face_stencil`]), each marched on along the jet until a solid or the
/// room's wall, with the face cell's weight spread evenly along that path.
///
/// The simulator's air has no momentum, so supply entering at the face alone goes to the
/// nearest sinks: around the CRAC's edge into its own top when the hall has no grilles,
/// up the grilles over the aisle it blows into. A jet carries it across the room. Spread
/// along its path (no throw length is fitted: the path ends where the jet would strike),
/// the built-in model came from 12.4-49.4 C to 2.5-11.3 C off OpenFOAM on no-grille
/// halls, from 6.9 to 3.4 C blowing at the back of a row, and from 1.3 to 1.1 C blowing
/// down a cold aisle; on four halls held out of that comparison (half the fan speed, a
/// single row facing its CRAC), from 2.7-19.6 to 2.7-8.8 C (docs/models.md,
/// "Front-supply CRACs and halls without grilles").
fn jet_stencil(grid: &Grid, solid: &[bool], b: &Aabb, side: Side) -> Option<Stencil> {
    let face = face_stencil(grid, solid, b, side, [b.min[2], b.max[2]])?;
    let (a, sign) = side.axis_sign();
    let mut st = Vec::new();
    for (c, w) in face {
        let mut ijk = grid.ijk(c);
        let mut path = Vec::new();
        loop {
            let cell = grid.idx(ijk[0], ijk[1], ijk[2]);
            if solid[cell] {
                break;
            }
            path.push(cell);
            if sign > 0.0 {
                if ijk[a] + 1 >= grid.n[a] {
                    break;
                }
                ijk[a] += 1;
            } else {
                if ijk[a] == 0 {
                    break;
                }
                ijk[a] -= 1;
            }
        }
        let n = path.len() as f64;
        st.extend(path.into_iter().map(|p| (p, w / n)));
    }
    Some(st)
}

/// Open cells just above the top face of box `b`, evenly weighted.
fn top_stencil(grid: &Grid, solid: &[bool], b: &Aabb) -> Option<Stencil> {
    let k = (b.max[2] / grid.d[2] - 0.5 + GEOM_EPS).floor() + 1.0;
    if k >= grid.n[2] as f64 {
        return None;
    }
    let cells: Vec<usize> = layer_cells(grid, b, k.max(0.0) as usize)
        .into_iter()
        .filter(|&c| !solid[c])
        .collect();
    if cells.is_empty() {
        return None;
    }
    let w = 1.0 / cells.len() as f64;
    Some(cells.into_iter().map(|c| (c, w)).collect())
}

/// Closes the faces on each containment box's planes (scaled by the leak fraction) and
/// lists them per side.
fn containment_walls(
    hall: &Hall,
    grid: &Grid,
    solid: &[bool],
    g: &mut [Vec<f64>; 3],
    leak: f64,
    panel_m: Option<f64>,
) -> Vec<[Vec<WallFace>; 5]> {
    let room = hall.room.size_m;
    let mut out = Vec::with_capacity(hall.containment.len());
    for cb in &hall.containment {
        let mut sides: [Vec<WallFace>; 5] = Default::default();
        for (si, side) in WallSide::ALL.into_iter().enumerate() {
            let (a, at_max) = match side {
                WallSide::MinusX => (0, false),
                WallSide::PlusX => (0, true),
                WallSide::MinusY => (1, false),
                WallSide::PlusY => (1, true),
                WallSide::Top => (2, true),
            };
            let x = if at_max { cb.max_m[a] } else { cb.min_m[a] };
            if x <= GEOM_EPS || x >= room[a] - GEOM_EPS {
                continue; // on a room wall, floor or ceiling
            }
            for low in grid.box_side_faces(a, at_max, cb.min_m, cb.max_m) {
                let high = low + grid.stride(a);
                if solid[low] || solid[high] {
                    continue;
                }
                g[a][low] = panel_face_g(grid, a, leak, panel_m);
                sides[si].push(WallFace { axis: a, low });
            }
        }
        out.push(sides);
    }
    out
}

/// Full conductance of an open face on axis `a` (for opened walls).
pub(crate) fn open_face_g(grid: &Grid, a: usize) -> f64 {
    full_g(grid, a)
}
