//! How much each server's exhaust reaches each sensor, from the simulator's own air flow:
//! the sensitivity of every sensor to every server's temperature rise at fixed flows.
//!
//! At fixed flows the temperature is linear in the supply temperatures and the server
//! rises, `A T = b`, and server `j` puts `q_j * rise_j` into `b` at its exhaust cells. So
//! `dT_k / d rise_j = q_j * sum_{c in exhaust_j} w_c * lambda_k[c]` with the adjoint
//! `A^T lambda_k = s_k` (`s_k` the sensor's interpolation stencil): one solve per sensor
//! gives its row for every server, where a forward difference would need one per server.
//! The coupling of exhaust to intake is in `A`, so a server whose exhaust is drawn into
//! another server's intake reaches the sensors that server's exhaust reaches too.

use rayon::prelude::*;

use super::config::Preconditioner;
use super::heat::{heat_spec, HeatOp};
use super::linalg::{bicgstab, Jacobi, Operator, Precond};
use super::multigrid::{Multigrid, StencilSpec};
use super::run::{solve_keeping, HEAT_SWEEPS};
use super::{SimMods, Simulator, Solution};
use crate::effects::Effect;
use crate::snapshots::OperatingState;
use crate::{Error, Result};

/// The transposed heat operator (the adjoint of upwind advection-diffusion with the
/// server coupling).
struct Transposed<'a> {
    op: HeatOp<'a>,
}

impl Operator for Transposed<'_> {
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let op = &self.op;
        let n = x.len();
        let s = [op.grid.stride(0), op.grid.stride(1), op.grid.stride(2)];
        // Row c of A^T is column c of A: A[c - s][c] = -up[c - s], A[c + s][c] = -down[c + s].
        y.par_iter_mut().enumerate().for_each(|(c, yv)| {
            if op.solid[c] {
                *yv = x[c];
                return;
            }
            let mut acc = op.diag[c] * x[c];
            for a in 0..3 {
                if c >= s[a] && !op.solid[c - s[a]] {
                    acc -= op.up[a][c - s[a]] * x[c - s[a]];
                }
                if c + s[a] < n && !op.solid[c + s[a]] {
                    acc -= op.down[a][c + s[a]] * x[c + s[a]];
                }
            }
            *yv = acc;
        });
        for t in op.transfers {
            let mean: f64 = t.to.iter().map(|&(c, w)| w * x[c]).sum();
            for &(c, w) in &t.from {
                y[c] -= w * t.flow_m3_s * mean;
            }
        }
    }

    fn inv_diag(&self) -> &[f64] {
        &self.op.inv_diag
    }
}

/// Every sensor's sensitivity to every server's temperature rise, at fixed flows.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorInfluence {
    /// `per_sensor[k][j]`: K at sensor `k` per K of server `j`'s rise (hall order).
    pub per_sensor: Vec<Vec<f64>>,
    /// Largest relative residual of the adjoint solves.
    pub max_rel_residual: f64,
}

impl Simulator {
    /// The sensitivity of each sensor to each server's rise at `state`, per-server
    /// `alpha` (cfm/W) and effects with their values, with the run it was taken from: one
    /// adjoint solve per sensor on the flow of that run. The heat operator is upwind
    /// whatever the configured scheme (its adjoint is exact; a limited scheme's is not
    /// linear).
    pub fn sensor_influence(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        effects: &[(&dyn Effect, &[f64])],
    ) -> Result<(Solution, SensorInfluence)> {
        let mut mods = SimMods::new(self.hall().cracs.len());
        for (e, values) in effects {
            e.modify(values, self.hall(), &mut mods)?;
        }
        self.sensor_influence_with_mods(state, alpha_per_server, &mods)
    }

    /// [`Self::sensor_influence`] with explicit modifications.
    pub fn sensor_influence_with_mods(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        mods: &SimMods,
    ) -> Result<(Solution, SensorInfluence)> {
        let (sol, parts) = solve_keeping(self, state, alpha_per_server, mods, true)?;
        let parts = parts.ok_or_else(|| {
            Error::Simulation("the run kept no heat operator for the adjoint".into())
        })?;
        let topo = self.topo();
        let cfg = self.config();
        let n = topo.grid.len();
        let g = [
            parts.g[0].as_slice(),
            parts.g[1].as_slice(),
            parts.g[2].as_slice(),
        ];
        let transfers = &parts.transfers;
        let mg = (cfg.preconditioner == Preconditioner::Multigrid).then(|| {
            let spec = heat_spec(
                &topo.grid,
                &topo.solid,
                &sol.face_flux_m3_s,
                g,
                cfg.diffusivity_m2_s,
                &sol.outlet_flux_m3_s,
                &parts.sink,
                transfers,
            );
            Multigrid::build(transposed_spec(spec), false, HEAT_SWEEPS)
        });
        let op = Transposed {
            op: HeatOp::new(
                &topo.grid,
                &topo.solid,
                &sol.face_flux_m3_s,
                g,
                cfg.diffusivity_m2_s,
                &sol.outlet_flux_m3_s,
                &parts.sink,
                transfers,
            ),
        };
        let rows: Vec<(Vec<f64>, f64)> = topo
            .sensors
            .iter()
            .enumerate()
            .map(|(k, st)| {
                let mut b = vec![0.0; n];
                for &(c, w) in st {
                    b[c] += w;
                }
                let mut lambda = vec![0.0; n];
                let mut jacobi = Jacobi(op.inv_diag());
                let mut work;
                let pc: &mut dyn Precond = match &mg {
                    Some(mg) => {
                        work = mg.workspace();
                        &mut work
                    }
                    None => &mut jacobi,
                };
                let stats = bicgstab(&op, pc, &b, &mut lambda, cfg.heat_tol, cfg.max_iterations);
                if stats.rel_residual.is_nan() || stats.rel_residual > cfg.heat_tol {
                    return Err(Error::Simulation(format!(
                        "sensor `{}`: adjoint solve did not converge: relative residual \
                         {:.3e} after {} iterations",
                        self.hall().sensors[k].id,
                        stats.rel_residual,
                        stats.iterations
                    )));
                }
                let row = parts
                    .server_transfer
                    .iter()
                    .map(|&t| match transfers.get(t) {
                        Some(tr) => {
                            tr.flow_m3_s * tr.to.iter().map(|&(c, w)| w * lambda[c]).sum::<f64>()
                        }
                        None => 0.0,
                    })
                    .collect();
                Ok((row, stats.rel_residual))
            })
            .collect::<Result<_>>()?;
        let max_rel_residual = rows.iter().map(|r| r.1).fold(0.0, f64::max);
        let influence = SensorInfluence {
            per_sensor: rows.into_iter().map(|r| r.0).collect(),
            max_rel_residual,
        };
        Ok((sol, influence))
    }
}

/// The multigrid input of the transposed heat operator. Swapping the two upwind parts of
/// every face swaps the coefficients above and below the diagonal, which is the transpose
/// of the stencil; the diagonal must stay the original one (a face's outflow), so each
/// cell's sink takes the difference, its net face outflow (its volume source, so never
/// negative but for solver round-off); and the links run backwards.
fn transposed_spec(mut spec: StencilSpec) -> StencilSpec {
    let s = [1, spec.n[0], spec.n[0] * spec.n[1]];
    let len = spec.active.len();
    let mut net_out = vec![0.0; len];
    for a in 0..3 {
        for c in 0..len.saturating_sub(s[a]) {
            let (fp, fm) = (spec.fp[a][c], spec.fm[a][c]);
            net_out[c] += fp - fm;
            net_out[c + s[a]] += fm - fp;
        }
    }
    for (sink, d) in spec.sink_adv.iter_mut().zip(&net_out) {
        *sink = (*sink + d).max(0.0);
    }
    std::mem::swap(&mut spec.fp, &mut spec.fm);
    for l in &mut spec.links {
        std::mem::swap(&mut l.from, &mut l.to);
    }
    spec
}
