//! Which edges of a hall's equipment fall between the built-in simulator's cells.
//!
//! The simulator lays racks, CRACs, tiles and containment on its grid by the
//! cells whose centres they cover, so an edge between two cell faces moves to the nearer
//! face. A rack 0.05 m off the 0.2 m grid moves a whole aisle's air and reads degrees
//! differently at its sensors; the user should hear of it, with a grid that would place
//! the hall as written.

use super::Grid;
use crate::hall::Hall;

/// Below this share of a cell an edge counts as on a face: rounding in an export, not a
/// position.
const ON_FACE_SHARE: f64 = 0.01;

/// One edge the grid moves.
#[derive(Debug, Clone, PartialEq)]
pub struct SnappedEdge {
    /// The entry's JSON pointer and field (`/racks/3/position_m`).
    pub pointer: String,
    /// The axis, 0 for x, 1 for y, 2 for z.
    pub axis: usize,
    /// Where the hall puts the edge (m).
    pub given_m: f64,
    /// The cell face the simulator puts it on (m).
    pub placed_m: f64,
}

/// Every edge of the racks, CRACs, tiles and containment of `hall` that the grid of
/// `cell_m` moves to a cell face by more than 1 % of a cell, in file order. Sensors are
/// not moved (they read between cell centres). Return grilles are not counted: the
/// presets' own sit half a cell off the 0.2 m grid, and a cell's shift of the `demo`
/// hall's grille moves its readings by 0.05-0.08 C on average (at most 0.44 C), where
/// equipment shifted by a quarter cell moved another hall's by 0.44 C on average.
///
/// ```
/// use kalibre_dc::sim::off_grid_edges;
/// use kalibre_dc::synth::{generate_hall, Preset, SynthOptions};
/// let mut hall = generate_hall(&SynthOptions::new(Preset::Demo, 1)).unwrap();
/// assert!(off_grid_edges(&hall, 0.2).is_empty());
/// hall.racks[0].position_m[0] += 0.05;
/// let moved = off_grid_edges(&hall, 0.2);
/// assert_eq!(moved[0].pointer, "/racks/0/position_m");
/// assert!((moved[0].given_m - moved[0].placed_m).abs() > 0.04);
/// ```
pub fn off_grid_edges(hall: &Hall, cell_m: f64) -> Vec<SnappedEdge> {
    let grid = Grid::new(hall.room.size_m, cell_m);
    let mut out = Vec::new();
    let mut check = |pointer: String, axis: usize, edges: [f64; 2]| {
        let d = grid.d[axis];
        // Where the cells the simulator puts in the box end ([`Grid::range_in`]): a tie
        // on a cell centre goes outward at either end.
        let inside = grid.range_in(axis, edges[0], edges[1]);
        let placed = [inside.start as f64 * d, inside.end as f64 * d];
        for (given_m, placed_m) in edges.into_iter().zip(placed) {
            if (given_m - placed_m).abs() > ON_FACE_SHARE * d {
                out.push(SnappedEdge {
                    pointer: pointer.clone(),
                    axis,
                    given_m,
                    placed_m,
                });
            }
        }
    };
    let span = |p: f64, s: f64| [p, p + s];
    for (i, r) in hall.racks.iter().enumerate() {
        for a in 0..3 {
            let edges = span(r.position_m[a], r.size_m[a]);
            check(format!("/racks/{i}/position_m"), a, edges);
        }
    }
    for (i, c) in hall.cracs.iter().enumerate() {
        for a in 0..3 {
            let edges = span(c.position_m[a], c.size_m[a]);
            check(format!("/cracs/{i}/position_m"), a, edges);
        }
    }
    for (i, t) in hall.tiles.iter().enumerate() {
        for a in 0..2 {
            let edges = span(t.position_m[a], t.size_m[a]);
            check(format!("/tiles/{i}/position_m"), a, edges);
        }
    }
    for (i, c) in hall.containment.iter().enumerate() {
        for a in 0..3 {
            check(
                format!("/containment/{i}/min_m"),
                a,
                [c.min_m[a], c.max_m[a]],
            );
        }
    }
    out
}

/// Whether `grid` puts a side of a containment box of `hall` on another face than the
/// nearest one, which it took before session 59: a side on a cell centre (a half-cell
/// tie) now goes outward, as a rack's cells do ([`Grid::box_side_faces`]).
pub fn containment_side_on_cell_centre(hall: &Hall, grid: &Grid) -> bool {
    hall.containment.iter().any(|c| {
        (0..3).any(|a| {
            let inside = grid.range_in(a, c.min_m[a], c.max_m[a]);
            let nearest = |x: f64| (x / grid.d[a]).round() as usize;
            inside.start != nearest(c.min_m[a]) || inside.end != nearest(c.max_m[a])
        })
    })
}

/// The coarsest cell of `cell_m / k` (k = 2..=8) whose grid moves no edge of `hall`, if
/// one does: a grid that places the hall as written.
pub fn grid_placing_all(hall: &Hall, cell_m: f64) -> Option<f64> {
    (2..=8)
        .map(|k| cell_m / k as f64)
        .find(|&c| off_grid_edges(hall, c).is_empty())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rack shifted by a quarter cell is found at both its x edges and no other, with
    /// the face it moves to; halving the cell places it.
    #[test]
    fn a_shifted_rack_is_found_at_its_moved_edges() {
        let options = crate::synth::SynthOptions::new(crate::synth::Preset::Demo, 1);
        let mut hall = crate::synth::generate_hall(&options).unwrap();
        assert_eq!(off_grid_edges(&hall, 0.2), vec![]);
        let x = hall.racks[1].position_m[0];
        hall.racks[1].position_m[0] = x + 0.05;
        let moved = off_grid_edges(&hall, 0.2);
        assert_eq!(moved.len(), 2, "{moved:?}");
        assert!(moved
            .iter()
            .all(|e| e.pointer == "/racks/1/position_m" && e.axis == 0));
        assert!((moved[0].given_m - (x + 0.05)).abs() < 1e-12);
        assert!((moved[0].placed_m - x).abs() < 1e-9, "{moved:?}");
        assert_eq!(grid_placing_all(&hall, 0.2), Some(0.05));
    }
}
