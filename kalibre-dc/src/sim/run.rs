//! One run: sources and couplings from the operating state, alpha and modifications
//! (the numeric part), then the pressure and temperature solves.

use std::borrow::Cow;

use super::advection::{solve_deferred, AdvectionStats, Faces};
use super::config::{Advection, Preconditioner};
use super::flow::{face_fluxes, pressure_spec, PressureOp};
use super::grid::Grid;
use super::heat::{heat_spec, stencil_value, HeatOp, Transfer};
use super::linalg::{bicgstab, pcg, Jacobi, Operator, SolveStats};
use super::mods::{SimMods, WallSide};
use super::multigrid::Multigrid;
use super::panel::panel_face_g;
use super::solution::Solution;
use super::supply::{crac_flows_m3_s, floor_flow_m3_s, split_over_tiles};
use super::topology::{open_face_g, Stencil};
use super::{Simulator, M3_S_PER_CFM};
use crate::hall::{SupplyKind, MAX_ALPHA_CFM_PER_W};
use crate::snapshots::{number, OperatingState, MAX_POWER_W};
use crate::PLAUSIBLE_SENSOR_C;
use crate::{Error, Result};

/// Air entering at a fixed temperature.
struct Inflow {
    cell: usize,
    flow_m3_s: f64,
    temp_c: f64,
}

/// The largest supply temperature offset a run takes (C): beyond it the CRAC would not
/// be the one in the hall file.
const MAX_SUPPLY_OFFSET_C: f64 = 100.0;

fn check_inputs(
    sim: &Simulator,
    state: &OperatingState,
    alpha: &[f64],
    mods: &SimMods,
) -> Result<()> {
    let hall = sim.hall();
    let nc = hall.cracs.len();
    let ns = hall.server_count();
    let len = |what: &str, got: usize, want: usize| {
        if got != want {
            Err(Error::Mismatch(format!(
                "{what}: {got} values for {want} {}",
                if what == "alpha" || what == "power_w" {
                    "servers"
                } else {
                    "CRACs"
                }
            )))
        } else {
            Ok(())
        }
    };
    len("setpoint_c", state.setpoint_c.len(), nc)?;
    len("fan_speed", state.fan_speed.len(), nc)?;
    len("power_w", state.power_w.len(), ns)?;
    len("alpha", alpha.len(), ns)?;
    if !mods.supply_offset_c.is_empty() {
        len("supply offsets", mods.supply_offset_c.len(), nc)?;
    }
    for (k, c) in hall.cracs.iter().enumerate() {
        if !PLAUSIBLE_SENSOR_C.contains(&state.setpoint_c[k]) {
            return Err(Error::Mismatch(format!(
                "CRAC `{}`: setpoint {} C is outside [{}, {}] C",
                c.id,
                number(state.setpoint_c[k]),
                PLAUSIBLE_SENSOR_C.start(),
                PLAUSIBLE_SENSOR_C.end()
            )));
        }
        let offset = mods.supply_offset_c.get(k).copied().unwrap_or(0.0);
        if !(-MAX_SUPPLY_OFFSET_C..=MAX_SUPPLY_OFFSET_C).contains(&offset) {
            return Err(Error::Mismatch(format!(
                "CRAC `{}`: supply offset {} C is outside [-{MAX_SUPPLY_OFFSET_C}, \
                 {MAX_SUPPLY_OFFSET_C}] C",
                c.id,
                number(offset)
            )));
        }
        if !(0.0..=1.0).contains(&state.fan_speed[k]) {
            return Err(Error::Mismatch(format!(
                "CRAC `{}`: fan speed {} outside [0, 1]",
                c.id, state.fan_speed[k]
            )));
        }
    }
    for (s, (p, a)) in hall.servers().zip(state.power_w.iter().zip(alpha)) {
        if !(*p >= 0.0 && *p <= MAX_POWER_W) {
            return Err(Error::Mismatch(format!(
                "server `{}`: power {} W is outside [0, {MAX_POWER_W:e}] W",
                s.server.id,
                number(*p)
            )));
        }
        if !(*a > 0.0 && *a <= MAX_ALPHA_CFM_PER_W) {
            return Err(Error::Mismatch(format!(
                "server `{}`: alpha {} cfm/W is outside (0, {MAX_ALPHA_CFM_PER_W}] cfm/W",
                s.server.id,
                number(*a)
            )));
        }
    }
    for rr in &mods.rack_recirculation {
        if !(0.0..=1.0).contains(&rr.fraction) {
            return Err(Error::Mismatch(format!(
                "rack recirculation at rack index {}: fraction {} is outside [0, 1]",
                rr.rack,
                number(rr.fraction)
            )));
        }
    }
    Ok(())
}

/// Gauss-Seidel sweeps before and after each coarse correction.
const PRESSURE_SWEEPS: usize = 1;
pub(super) const HEAT_SWEEPS: usize = 1;

/// The pressure multigrid for face conductances `g`.
pub(super) fn pressure_multigrid(
    grid: &Grid,
    g: [&[f64]; 3],
    g_outlet: &[f64],
    solid: &[bool],
) -> Multigrid {
    Multigrid::build(
        pressure_spec(grid, g, g_outlet, solid),
        true,
        PRESSURE_SWEEPS,
    )
}

pub(super) fn solve(
    sim: &Simulator,
    state: &OperatingState,
    alpha: &[f64],
    mods: &SimMods,
) -> Result<Solution> {
    solve_keeping(sim, state, alpha, mods, false).map(|(sol, _)| sol)
}

/// What the heat operator of a run was built from, besides the solution's fluxes: kept
/// for the adjoint (`influence.rs`), which must see the same operator, effects included.
pub(super) struct HeatParts {
    /// Face conductances with this run's opened panels.
    pub g: [Vec<f64>; 3],
    /// Flow leaving each cell other than through faces and outlets (m3/s).
    pub sink: Vec<f64>,
    /// Servers, in-rack recirculation and forced links.
    pub transfers: Vec<Transfer>,
    /// Each server's index in `transfers` (`usize::MAX`: no flow).
    pub server_transfer: Vec<usize>,
}

/// [`solve`], also returning the heat operator's parts when `keep` is set.
pub(super) fn solve_keeping(
    sim: &Simulator,
    state: &OperatingState,
    alpha: &[f64],
    mods: &SimMods,
    keep: bool,
) -> Result<(Solution, Option<HeatParts>)> {
    check_inputs(sim, state, alpha, mods)?;
    let hall = sim.hall();
    let topo = sim.topo();
    let cfg = sim.config();
    let grid = &topo.grid;
    let n = grid.len();
    let rho_cp = cfg.rho_cp();

    // CRAC flows and supply temperatures.
    let crac_q = crac_flows_m3_s(hall, state);
    let crac_t: Vec<f64> = (0..hall.cracs.len())
        .map(|k| state.setpoint_c[k] + mods.supply_offset_c.get(k).copied().unwrap_or(0.0))
        .collect();
    let open_share = mods.supply_opening_share();
    if !(0.0..1.0).contains(&open_share)
        || mods
            .supply_openings
            .iter()
            .any(|o| o.share.is_nan() || o.share < 0.0)
    {
        return Err(Error::Simulation(format!(
            "supply openings take a share {open_share} of the supply; must be in [0, 1)"
        )));
    }

    let mut inflows: Vec<Inflow> = Vec::new();
    let push_stencil = |inflows: &mut Vec<Inflow>, st: &Stencil, q: f64, t: f64| {
        for &(c, w) in st {
            inflows.push(Inflow {
                cell: c,
                flow_m3_s: w * q,
                temp_c: t,
            });
        }
    };
    let floor_q = floor_flow_m3_s(hall, &crac_q);
    if floor_q > 0.0 {
        if topo.tiles.is_empty() {
            return Err(Error::Simulation("floor-supply CRACs but no tiles".into()));
        }
        // The plenum mixes the floor CRACs' supply.
        let plenum_t = hall
            .cracs
            .iter()
            .zip(crac_q.iter().zip(&crac_t))
            .filter(|(c, _)| c.supply == SupplyKind::Floor)
            .map(|(_, (q, t))| q * t)
            .sum::<f64>()
            / floor_q;
        for (st, q) in topo
            .tiles
            .iter()
            .zip(split_over_tiles(hall, floor_q, open_share))
        {
            push_stencil(&mut inflows, st, q, plenum_t);
        }
    }
    for (k, c) in hall.cracs.iter().enumerate() {
        if c.supply == SupplyKind::Front && crac_q[k] > 0.0 {
            push_stencil(
                &mut inflows,
                &topo.crac_front[k],
                (1.0 - open_share) * crac_q[k],
                crac_t[k],
            );
        }
    }
    for (j, o) in mods.supply_openings.iter().enumerate() {
        let st = topo.box_stencil(&o.region).ok_or_else(|| {
            Error::Simulation(format!("supply opening {j}: no open cell in its box"))
        })?;
        for k in 0..hall.cracs.len() {
            if crac_q[k] > 0.0 {
                push_stencil(&mut inflows, &st, o.share * crac_q[k], crac_t[k]);
            }
        }
    }

    // Fixed sinks: CRAC tops when there are no returns.
    let mut fixed_sink = vec![0.0; n];
    if !topo.has_returns {
        for (k, st) in topo.crac_top.iter().enumerate() {
            for &(c, w) in st {
                fixed_sink[c] += w * crac_q[k];
            }
        }
    }

    // Transfers: servers, in-rack recirculation, forced links.
    let mut transfers: Vec<Transfer> = Vec::with_capacity(alpha.len());
    let mut server_flow = vec![0.0; alpha.len()];
    let mut rack_flow = vec![0.0; hall.racks.len()];
    let mut server_transfer = vec![usize::MAX; alpha.len()];
    for s in hall.servers() {
        let i = s.index;
        let q = alpha[i] * state.power_w[i] * M3_S_PER_CFM;
        server_flow[i] = q;
        rack_flow[s.rack_index] += q;
        if q > 0.0 {
            server_transfer[i] = transfers.len();
            transfers.push(Transfer {
                from: topo.server_intake[i].clone(),
                to: topo.server_exhaust[i].clone(),
                flow_m3_s: q,
                rise_c: state.power_w[i] / (rho_cp * q),
            });
        }
    }
    for rr in &mods.rack_recirculation {
        let r = hall.racks.get(rr.rack).ok_or_else(|| {
            Error::Simulation(format!("rack recirculation: no rack index {}", rr.rack))
        })?;
        let q = rr.fraction * rack_flow[rr.rack];
        if q <= 0.0 {
            continue;
        }
        let none = || Error::Simulation(format!("rack `{}`: no open cell for recirculation", r.id));
        let from = topo
            .rack_face(hall, rr.rack, r.inlet.opposite(), rr.z_m)
            .ok_or_else(none)?;
        let to = topo
            .rack_face(hall, rr.rack, r.inlet, rr.z_m)
            .ok_or_else(none)?;
        transfers.push(Transfer {
            from,
            to,
            flow_m3_s: q,
            rise_c: 0.0,
        });
    }
    for (j, l) in mods.air_links.iter().enumerate() {
        if !(l.flow_m3_s >= 0.0 && l.flow_m3_s.is_finite()) {
            return Err(Error::Simulation(format!(
                "air link {j}: flow {} is not >= 0",
                l.flow_m3_s
            )));
        }
        let none = |what: &str| {
            Error::Simulation(format!("air link {j}: no open cell in its `{what}` box"))
        };
        let from = topo.box_stencil(&l.from).ok_or_else(|| none("from"))?;
        let to = topo.box_stencil(&l.to).ok_or_else(|| none("to"))?;
        transfers.push(Transfer {
            from,
            to,
            flow_m3_s: l.flow_m3_s,
            rise_c: 0.0,
        });
    }

    // Net volume source per cell.
    let mut source = vec![0.0; n];
    let mut sink = fixed_sink.clone();
    for f in &inflows {
        source[f.cell] += f.flow_m3_s;
    }
    for c in 0..n {
        source[c] -= fixed_sink[c];
    }
    for t in &transfers {
        for &(c, w) in &t.from {
            source[c] -= w * t.flow_m3_s;
            sink[c] += w * t.flow_m3_s;
        }
        for &(c, w) in &t.to {
            source[c] += w * t.flow_m3_s;
        }
    }

    let supply_q: f64 = inflows.iter().map(|f| f.flow_m3_s).sum();
    let power_w: f64 = state.power_w.iter().sum();
    if supply_q <= 0.0 && power_w > 0.0 {
        return Err(Error::Simulation(
            "no supply air (all fans off) while servers dissipate heat: no steady state".into(),
        ));
    }

    // Face conductances, with opened containment panels for this run.
    let g: Cow<[Vec<f64>; 3]> = if mods.wall_openings.is_empty() {
        Cow::Borrowed(&topo.g)
    } else {
        let mut g = topo.g.clone();
        let leak = cfg.containment_leak_fraction;
        for o in &mods.wall_openings {
            let walls = topo.walls.get(o.containment).ok_or_else(|| {
                Error::Simulation(format!(
                    "wall opening: no containment index {}",
                    o.containment
                ))
            })?;
            if !(0.0..=1.0).contains(&o.open_fraction) {
                return Err(Error::Simulation(format!(
                    "wall opening: open fraction {} outside [0, 1]",
                    o.open_fraction
                )));
            }
            for side in &o.sides {
                let si = WallSide::ALL.iter().position(|w| w == side).unwrap_or(0);
                for f in &walls[si] {
                    let open = leak + (1.0 - leak) * o.open_fraction;
                    g[f.axis][f.low] = match cfg.containment_panel_m {
                        None => open_face_g(grid, f.axis) * open,
                        panel_m => panel_face_g(grid, f.axis, open, panel_m),
                    };
                }
            }
        }
        Cow::Owned(g)
    };
    let gref = [g[0].as_slice(), g[1].as_slice(), g[2].as_slice()];

    // Pressure.
    let mut p = vec![0.0; n];
    let (ptol, pmax) = (cfg.pressure_tol, cfg.max_iterations);
    let pstats = match (cfg.preconditioner, sim.pressure_mg()) {
        (Preconditioner::Multigrid, Some(mg)) => {
            let owned;
            let mg = if mods.wall_openings.is_empty() {
                mg
            } else {
                owned = pressure_multigrid(grid, gref, &topo.g_outlet, &topo.solid);
                &owned
            };
            pcg(mg, &mut mg.workspace(), &source, &mut p, ptol, pmax)
        }
        _ => {
            let pop = PressureOp::new(grid, gref, &topo.g_outlet, &topo.solid);
            pcg(
                &pop,
                &mut Jacobi(pop.inv_diag()),
                &source,
                &mut p,
                ptol,
                pmax,
            )
        }
    };
    if pstats.rel_residual.is_nan() || pstats.rel_residual > cfg.pressure_tol {
        return Err(Error::Simulation(format!(
            "pressure solve did not converge: relative residual {:.3e} after {} iterations",
            pstats.rel_residual, pstats.iterations
        )));
    }
    let flux = face_fluxes(grid, gref, &p);
    let outlet_flux: Vec<f64> = (0..n).map(|c| topo.g_outlet[c] * p[c]).collect();

    // Temperature.
    let mut rhs = vec![0.0; n];
    for f in &inflows {
        rhs[f.cell] += f.flow_m3_s * f.temp_c;
    }
    for t in &transfers {
        for &(c, w) in &t.to {
            rhs[c] += w * t.flow_m3_s * t.rise_c;
        }
    }
    let mut sink_all = sink;
    // Outlet flux is folded in by the operator; the fixed sinks are already in `sink_all`.
    for v in sink_all.iter_mut() {
        if *v < 0.0 {
            *v = 0.0;
        }
    }
    let t_supply_mean = if supply_q > 0.0 {
        inflows.iter().map(|f| f.flow_m3_s * f.temp_c).sum::<f64>() / supply_q
    } else {
        crac_t.iter().sum::<f64>() / crac_t.len().max(1) as f64
    };
    let mut temp: Vec<f64> = topo
        .solid
        .iter()
        .map(|s| if *s { 0.0 } else { t_supply_mean })
        .collect();
    let faces = Faces {
        grid,
        g: gref,
        full_g: std::array::from_fn(|a| open_face_g(grid, a)),
        flux: &flux,
    };
    let (hstats, advection_stats) = heat_solve(
        cfg.preconditioner,
        HeatInputs {
            grid,
            solid: &topo.solid,
            flux: &flux,
            g: gref,
            diffusivity: cfg.diffusivity_m2_s,
            outlet_flux: &outlet_flux,
            sink: &sink_all,
            transfers: &transfers,
        },
        &rhs,
        &mut temp,
        (cfg.heat_tol, cfg.max_iterations),
        (
            &faces,
            cfg.advection,
            (cfg.advection_max_outer, cfg.advection_tol_c),
        ),
    );
    if hstats.rel_residual.is_nan() || hstats.rel_residual > cfg.heat_tol {
        return Err(Error::Simulation(format!(
            "temperature solve did not converge: relative residual {:.3e} after {} iterations",
            hstats.rel_residual, hstats.iterations
        )));
    }
    for (t, s) in temp.iter_mut().zip(&topo.solid) {
        if *s {
            *t = f64::NAN;
        }
    }

    // Post-processing.
    let sensor_c: Vec<f64> = topo
        .sensors
        .iter()
        .map(|st| stencil_value(st, &temp))
        .collect();
    let mut out_q = 0.0;
    let mut out_qt = 0.0;
    for c in 0..n {
        let q = outlet_flux[c] + fixed_sink[c];
        if q != 0.0 {
            out_q += q;
            out_qt += q * temp[c];
        }
    }
    let in_qt: f64 = inflows.iter().map(|f| f.flow_m3_s * f.temp_c).sum();
    let heat_removed_w = rho_cp * (out_qt - in_qt);
    let server_intake_c: Vec<f64> = topo
        .server_intake
        .iter()
        .map(|st| stencil_value(st, &temp))
        .collect();
    let server_exhaust_c: Vec<f64> = (0..alpha.len())
        .map(|i| {
            if server_transfer[i] == usize::MAX {
                server_intake_c[i]
            } else {
                server_intake_c[i] + transfers[server_transfer[i]].rise_c
            }
        })
        .collect();
    let parts = keep.then(|| HeatParts {
        g: g.clone().into_owned(),
        sink: sink_all.clone(),
        transfers: transfers.clone(),
        server_transfer: server_transfer.clone(),
    });
    let solution = Solution {
        label: state.label.clone(),
        pressure: p,
        face_flux_m3_s: flux,
        outlet_flux_m3_s: outlet_flux,
        fixed_sink_m3_s: fixed_sink,
        source_m3_s: source,
        temperature_c: temp,
        sensor_c,
        return_c: if out_q > 0.0 {
            out_qt / out_q
        } else {
            f64::NAN
        },
        supply_c: t_supply_mean,
        supply_flow_m3_s: supply_q,
        return_flow_m3_s: out_q,
        server_flow_m3_s: server_flow,
        server_intake_c,
        server_exhaust_c,
        power_w,
        heat_removed_w,
        pressure_stats: pstats,
        heat_stats: hstats,
        advection_stats,
    };
    Ok((solution, parts))
}

/// What the heat operator is built from.
struct HeatInputs<'a> {
    grid: &'a Grid,
    solid: &'a [bool],
    flux: &'a [Vec<f64>; 3],
    g: [&'a [f64]; 3],
    diffusivity: f64,
    outlet_flux: &'a [f64],
    sink: &'a [f64],
    transfers: &'a [Transfer],
}

/// The temperature solve with the chosen preconditioner and advection scheme (the
/// operator is built once; TVD schemes re-solve it with corrected right-hand sides).
fn heat_solve(
    pc: Preconditioner,
    h: HeatInputs,
    rhs: &[f64],
    temp: &mut [f64],
    (tol, max_iter): (f64, usize),
    (faces, scheme, passes): (&Faces, Advection, (usize, f64)),
) -> (SolveStats, AdvectionStats) {
    let deferred =
        |rhs: &[f64], temp: &mut [f64], solve: &mut dyn FnMut(&[f64], &mut [f64]) -> SolveStats| {
            solve_deferred(faces, scheme, passes, tol, rhs, temp, solve)
        };
    match pc {
        Preconditioner::Multigrid => {
            let spec = heat_spec(
                h.grid,
                h.solid,
                h.flux,
                h.g,
                h.diffusivity,
                h.outlet_flux,
                h.sink,
                h.transfers,
            );
            let mg = Multigrid::build(spec, false, HEAT_SWEEPS);
            deferred(rhs, temp, &mut |b, x| {
                bicgstab(&mg, &mut mg.workspace(), b, x, tol, max_iter)
            })
        }
        Preconditioner::Jacobi => {
            let hop = HeatOp::new(
                h.grid,
                h.solid,
                h.flux,
                h.g,
                h.diffusivity,
                h.outlet_flux,
                h.sink,
                h.transfers,
            );
            deferred(rhs, temp, &mut |b, x| {
                bicgstab(&hop, &mut Jacobi(hop.inv_diag()), b, x, tol, max_iter)
            })
        }
    }
}
