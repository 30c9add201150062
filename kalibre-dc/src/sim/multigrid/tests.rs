//! Multigrid-preconditioned CG on a Poisson problem with a leaky internal wall: the same
//! answer as Jacobi-CG, in few iterations that barely grow with the grid.

use super::coarsen::{coarsen, Axes};
use super::*;
use crate::sim::linalg::{pcg, Jacobi};

/// A box with outlets on a ceiling patch and a wall at `x = nx / 2 + 1` (odd on purpose:
/// it must survive coarsening) conducting 2 % except for a gap.
fn leaky_box(m: usize) -> (StencilSpec, Vec<f64>) {
    let n = [4 * m, 3 * m, 2 * m];
    let len = n[0] * n[1] * n[2];
    let s = strides(n);
    let wall = n[0] / 2 + 1;
    let mut dif: [Vec<f64>; 3] = std::array::from_fn(|_| vec![0.0; len]);
    let mut sink_dif = vec![0.0; len];
    let mut b = vec![0.0; len];
    for c in 0..len {
        let ijk = [c % n[0], (c / n[0]) % n[1], c / s[2]];
        for a in 0..3 {
            if ijk[a] + 1 < n[a] {
                let leak = a == 0 && ijk[0] + 1 == wall && ijk[1] > n[1] / 4;
                dif[a][c] = if leak { 0.02 } else { 1.0 };
            }
        }
        if ijk[2] + 1 == n[2] && ijk[0] < n[0] / 4 {
            sink_dif[c] = 2.0;
        }
        b[c] = (0.37 * c as f64).sin() + if ijk[0] > wall { 0.5 } else { 0.0 };
    }
    let spec = StencilSpec {
        n,
        fp: Default::default(),
        fm: Default::default(),
        dif,
        sink_adv: Vec::new(),
        sink_dif,
        active: vec![true; len],
        links: Vec::new(),
    };
    (spec, b)
}

#[test]
fn multigrid_cg_matches_jacobi_cg_in_few_iterations() {
    let mut iters = Vec::new();
    for m in [6, 12] {
        let (spec, b) = leaky_box(m);
        let mg = Multigrid::build(spec, true, 1);
        assert!(mg.depth() >= 3, "only {} levels", mg.depth());
        let mut x = vec![0.0; b.len()];
        let st = pcg(&mg, &mut mg.workspace(), &b, &mut x, 1e-10, 10_000);
        assert!(st.rel_residual <= 1e-10, "{st:?}");
        let mut xj = vec![0.0; b.len()];
        let sj = pcg(&mg, &mut Jacobi(mg.inv_diag()), &b, &mut xj, 1e-12, 100_000);
        assert!(sj.rel_residual <= 1e-12, "{sj:?}");
        let scale = xj.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let d = x
            .iter()
            .zip(&xj)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
        assert!(
            d < 1e-7 * scale,
            "m = {m}: differs by {d:e} (scale {scale:e})"
        );
        assert!(
            st.iterations * 5 < sj.iterations,
            "m = {m}: multigrid {} vs Jacobi {} iterations",
            st.iterations,
            sj.iterations
        );
        iters.push(st.iterations);
    }
    // Eight times the cells: at most a few more iterations.
    assert!(iters[0] <= 25 && iters[1] <= iters[0] + 5, "{iters:?}");
}

#[test]
fn coarsening_keeps_weak_walls_as_cell_faces() {
    let (spec, _) = leaky_box(8);
    let axes = Axes::finest(&spec);
    let wall = spec.n[0] / 2 + 1;
    assert!(axes.protect[0][wall]);
    assert_eq!(axes.protect[0].iter().filter(|p| **p).count(), 1);
    let (coarse, caxes, parent) = coarsen(&spec, &axes);
    // The cells on both sides of the wall have different parents, at every level.
    let s = strides(spec.n);
    let c = wall - 1 + s[1] * (spec.n[1] - 1);
    assert_ne!(parent[c], parent[c + 1]);
    let (_, _, parent2) = coarsen(&coarse, &caxes);
    assert_ne!(parent2[parent[c] as usize], parent2[parent[c + 1] as usize]);
    // The widths still cover the box.
    assert_eq!(caxes.widths[0].iter().sum::<f64>(), spec.n[0] as f64);
}
