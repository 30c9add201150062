//! Air flow: the Darcy / potential-flow pressure equation `div(g grad p) = sources` with
//! conservative face fluxes, as a matrix-free 7-point operator.

use rayon::prelude::*;

use super::grid::Grid;
use super::linalg::{Operator, CHUNK};
use super::multigrid::StencilSpec;

/// The symmetric pressure operator: `(A p)_c = sum_f g_f (p_c - p_nb) + g_out,c p_c`.
pub(crate) struct PressureOp<'a> {
    pub grid: &'a Grid,
    pub g: [&'a [f64]; 3],
    pub solid: &'a [bool],
    pub diag: Vec<f64>,
    pub inv_diag: Vec<f64>,
}

impl<'a> PressureOp<'a> {
    pub fn new(grid: &'a Grid, g: [&'a [f64]; 3], g_outlet: &'a [f64], solid: &'a [bool]) -> Self {
        let n = grid.len();
        let s = [grid.stride(0), grid.stride(1), grid.stride(2)];
        let diag: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|c| {
                if solid[c] {
                    return 1.0;
                }
                let mut d = g_outlet[c];
                for a in 0..3 {
                    d += g[a][c];
                    if c >= s[a] {
                        d += g[a][c - s[a]];
                    }
                }
                // A fluid cell with no open face carries no flow: keep the row regular.
                if d > 0.0 {
                    d
                } else {
                    1.0
                }
            })
            .collect();
        let inv_diag = diag.iter().map(|d| 1.0 / d).collect();
        PressureOp {
            grid,
            g,
            solid,
            diag,
            inv_diag,
        }
    }
}

impl Operator for PressureOp<'_> {
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let n = x.len();
        let s = [
            self.grid.stride(0),
            self.grid.stride(1),
            self.grid.stride(2),
        ];
        let [gx, gy, gz] = self.g;
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, yc)| {
            let base = ci * CHUNK;
            for (o, yv) in yc.iter_mut().enumerate() {
                let c = base + o;
                if self.solid[c] {
                    *yv = x[c];
                    continue;
                }
                let mut acc = self.diag[c] * x[c];
                if c + s[0] < n {
                    acc -= gx[c] * x[c + s[0]];
                }
                if c >= s[0] {
                    acc -= gx[c - s[0]] * x[c - s[0]];
                }
                if c + s[1] < n {
                    acc -= gy[c] * x[c + s[1]];
                }
                if c >= s[1] {
                    acc -= gy[c - s[1]] * x[c - s[1]];
                }
                if c + s[2] < n {
                    acc -= gz[c] * x[c + s[2]];
                }
                if c >= s[2] {
                    acc -= gz[c - s[2]] * x[c - s[2]];
                }
                *yv = acc;
            }
        });
    }

    fn inv_diag(&self) -> &[f64] {
        &self.inv_diag
    }
}

/// Face fluxes (m3/s, positive towards `+axis`) from the pressure: `F = g (p_c - p_nb)`.
pub(crate) fn face_fluxes(grid: &Grid, g: [&[f64]; 3], p: &[f64]) -> [Vec<f64>; 3] {
    let n = grid.len();
    let flux = |a: usize| -> Vec<f64> {
        let s = grid.stride(a);
        (0..n)
            .into_par_iter()
            .map(|c| {
                if g[a][c] > 0.0 && c + s < n {
                    g[a][c] * (p[c] - p[c + s])
                } else {
                    0.0
                }
            })
            .collect()
    };
    [flux(0), flux(1), flux(2)]
}

/// Net outflow of each cell through its faces and outlet, minus its sources: zero when
/// mass balances.
pub(crate) fn mass_imbalance(
    grid: &Grid,
    flux: &[Vec<f64>; 3],
    outlet_flux: &[f64],
    source: &[f64],
) -> Vec<f64> {
    let n = grid.len();
    (0..n)
        .into_par_iter()
        .map(|c| {
            let mut out = outlet_flux[c] - source[c];
            for (a, f) in flux.iter().enumerate() {
                let s = grid.stride(a);
                out += f[c];
                if c >= s {
                    out -= f[c - s];
                }
            }
            out
        })
        .collect()
}

/// The pressure operator as multigrid input (the same rows as [`PressureOp`]).
pub(crate) fn pressure_spec(
    grid: &Grid,
    g: [&[f64]; 3],
    g_outlet: &[f64],
    solid: &[bool],
) -> StencilSpec {
    StencilSpec {
        n: grid.n,
        fp: Default::default(),
        fm: Default::default(),
        dif: [g[0].to_vec(), g[1].to_vec(), g[2].to_vec()],
        sink_adv: Vec::new(),
        sink_dif: g_outlet.to_vec(),
        active: solid.iter().map(|s| !s).collect(),
        links: Vec::new(),
    }
}
