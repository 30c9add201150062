//! Heat: steady first-order upwind advection with an effective (turbulent) diffusivity on
//! the face fluxes of the flow solution, plus the non-local server coupling (exhaust =
//! flow-weighted mean intake + rise) inside the operator, so one BiCGSTAB solve gives a
//! consistent field with no outer iteration. The TVD advection option keeps this operator
//! and adds its higher-order part as a deferred correction (`advection.rs`).

use rayon::prelude::*;

use super::grid::Grid;
use super::linalg::{Operator, CHUNK};
use super::multigrid::{Link, StencilSpec};
use super::topology::Stencil;

/// Air moved from one set of cells to another, leaving at the taken air's mixed
/// temperature plus `rise_c` (a server, an in-rack leak, a forced link).
#[derive(Debug, Clone)]
pub(crate) struct Transfer {
    pub from: Stencil,
    pub to: Stencil,
    pub flow_m3_s: f64,
    pub rise_c: f64,
}

/// The heat operator in coefficient form.
pub(crate) struct HeatOp<'a> {
    pub grid: &'a Grid,
    pub solid: &'a [bool],
    pub diag: Vec<f64>,
    /// Coefficient of `T[c + s_a]` in row `c` (entered with a minus sign).
    pub up: [Vec<f64>; 3],
    /// Coefficient of `T[c - s_a]` in row `c` (entered with a minus sign).
    pub down: [Vec<f64>; 3],
    pub transfers: &'a [Transfer],
    pub inv_diag: Vec<f64>,
}

impl<'a> HeatOp<'a> {
    /// Builds the operator from face fluxes, face conductances (diffusion is the
    /// diffusivity times the same area-over-distance conductance), outlet fluxes and
    /// fixed sinks (server intakes, CRAC tops; flow leaving at the cell temperature).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        grid: &'a Grid,
        solid: &'a [bool],
        flux: &[Vec<f64>; 3],
        g: [&[f64]; 3],
        diffusivity: f64,
        outlet_flux: &[f64],
        sink: &[f64],
        transfers: &'a [Transfer],
    ) -> Self {
        let n = grid.len();
        let mut diag = vec![0.0; n];
        let mut up: [Vec<f64>; 3] = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        let mut down: [Vec<f64>; 3] = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        for a in 0..3 {
            let s = grid.stride(a);
            for c in 0..n {
                if g[a][c] <= 0.0 {
                    continue;
                }
                let f = flux[a][c];
                let d = diffusivity * g[a][c];
                diag[c] += f.max(0.0) + d;
                up[a][c] = (-f).max(0.0) + d;
                diag[c + s] += (-f).max(0.0) + d;
                down[a][c + s] = f.max(0.0) + d;
            }
        }
        for c in 0..n {
            // Outlets are zero-gradient: whatever crosses carries the cell temperature.
            diag[c] += outlet_flux[c] + sink[c];
            if solid[c] || diag[c] <= 0.0 {
                diag[c] = 1.0;
            }
        }
        let inv_diag = diag.iter().map(|d| 1.0 / d).collect();
        HeatOp {
            grid,
            solid,
            diag,
            up,
            down,
            transfers,
            inv_diag,
        }
    }
}

impl Operator for HeatOp<'_> {
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let n = x.len();
        let s = [
            self.grid.stride(0),
            self.grid.stride(1),
            self.grid.stride(2),
        ];
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(ci, yc)| {
            let base = ci * CHUNK;
            for (o, yv) in yc.iter_mut().enumerate() {
                let c = base + o;
                if self.solid[c] {
                    *yv = x[c];
                    continue;
                }
                let mut acc = self.diag[c] * x[c];
                for a in 0..3 {
                    if c + s[a] < n {
                        acc -= self.up[a][c] * x[c + s[a]];
                    }
                    if c >= s[a] {
                        acc -= self.down[a][c] * x[c - s[a]];
                    }
                }
                *yv = acc;
            }
        });
        // The coupling is sparse and small next to the stencil: applied serially, in order.
        for t in self.transfers {
            let mean: f64 = t.from.iter().map(|&(c, w)| w * x[c]).sum();
            for &(c, w) in &t.to {
                y[c] -= w * t.flow_m3_s * mean;
            }
        }
    }

    fn inv_diag(&self) -> &[f64] {
        &self.inv_diag
    }
}

/// The stencil-weighted value of a cell field.
pub(crate) fn stencil_value(st: &Stencil, field: &[f64]) -> f64 {
    st.iter().map(|&(c, w)| w * field[c]).sum()
}

/// The heat operator as multigrid input (the same rows as [`HeatOp::new`] builds).
#[allow(clippy::too_many_arguments)]
pub(crate) fn heat_spec(
    grid: &Grid,
    solid: &[bool],
    flux: &[Vec<f64>; 3],
    g: [&[f64]; 3],
    diffusivity: f64,
    outlet_flux: &[f64],
    sink: &[f64],
    transfers: &[Transfer],
) -> StencilSpec {
    let n = grid.len();
    let part = |a: usize, f: fn(f64) -> f64| -> Vec<f64> {
        (0..n)
            .into_par_iter()
            .map(|c| if g[a][c] > 0.0 { f(flux[a][c]) } else { 0.0 })
            .collect()
    };
    let pos = |v: f64| v.max(0.0);
    let neg = |v: f64| (-v).max(0.0);
    StencilSpec {
        n: grid.n,
        fp: [part(0, pos), part(1, pos), part(2, pos)],
        fm: [part(0, neg), part(1, neg), part(2, neg)],
        dif: std::array::from_fn(|a| g[a].iter().map(|v| diffusivity * v.max(0.0)).collect()),
        sink_adv: outlet_flux.iter().zip(sink).map(|(o, s)| o + s).collect(),
        sink_dif: Vec::new(),
        active: solid.iter().map(|s| !s).collect(),
        links: transfers
            .iter()
            .map(|t| Link {
                from: t.from.clone(),
                to: t.to.clone(),
                flow: t.flow_m3_s,
            })
            .collect(),
    }
}
