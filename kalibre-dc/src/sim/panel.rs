//! Conductance of a containment panel face (leaky panel, or a panel with openings).
//!
//! By default a panel is one cell thick: the face between the two cells across it gets
//! `f * A / d` for an open fraction `f`. That makes the panel's resistance proportional to
//! the cell size, so a finer grid leaks more at the same pressure difference (at 0.1 m the
//! demo's containment end door passes about 1.5 times the 0.2 m flow). With a fixed panel
//! thickness `t`, the face is the panel (a layer `t` thick with open fraction `f`) in
//! series with the rest of the centre-to-centre distance as free air:
//! `R = d / A + t (1 / f - 1) / A`. That resistance does not depend on the grid beyond the
//! free air's own `d / A`, and at `d = t` it equals the one-cell panel exactly.

use super::grid::Grid;

/// Conductance (m) of a containment face normal to axis `a` with open fraction
/// `open_fraction` in `[0, 1]`: one cell thick when `panel_m` is `None`, else a panel
/// `panel_m` thick in series with free air.
pub(crate) fn panel_face_g(grid: &Grid, a: usize, open_fraction: f64, panel_m: Option<f64>) -> f64 {
    let area = grid.face_area(a);
    match panel_m {
        // Same operation order as the open-face conductance times the fraction, so that
        // the default stays bit-identical.
        None => open_fraction * (area / grid.d[a]),
        Some(_) if open_fraction <= 0.0 => 0.0,
        Some(t) => area / (grid.d[a] + t * (1.0 / open_fraction - 1.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_panel_matches_one_cell_panel_at_its_thickness_and_is_grid_independent() {
        let coarse = Grid::new([4.0, 4.0, 3.0], 0.2);
        let fine = Grid::new([4.0, 4.0, 3.0], 0.1);
        for f in [0.0, 0.02, 0.3, 1.0] {
            let one_cell = panel_face_g(&coarse, 0, f, None);
            let fixed = panel_face_g(&coarse, 0, f, Some(0.2));
            assert!(
                (one_cell - fixed).abs() <= 1e-12 * one_cell.max(1e-300),
                "f {f}"
            );
        }
        // Per unit area the fine grid's panel passes what the coarse one does, except for
        // the shorter free-air path (0.1 m of 0.2 + 9.8 m equivalent at f = 0.02).
        let per_area = |g: &Grid, p| panel_face_g(g, 0, 0.02, p) / g.face_area(0);
        let fixed_ratio = per_area(&fine, Some(0.2)) / per_area(&coarse, Some(0.2));
        assert!((fixed_ratio - 10.0 / 9.9).abs() < 1e-12, "{fixed_ratio}");
        let cell_ratio = per_area(&fine, None) / per_area(&coarse, None);
        assert!((cell_ratio - 2.0).abs() < 1e-12, "{cell_ratio}");
        // A fully open face is free air at any thickness.
        assert_eq!(
            panel_face_g(&fine, 2, 1.0, Some(0.3)),
            fine.face_area(2) / fine.d[2]
        );
    }
}
