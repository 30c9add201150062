//! The built-in thermal simulator: a reduced-order 3-D model of a data hall on a
//! structured grid.
//!
//! * **Air** follows Darcy / potential flow: `div(g grad p) = sources` with conservative
//!   face fluxes. Tiles (or CRAC front faces) inject the CRAC flow (fan speed x rated
//!   flow; tiles share it by area x open fraction); ceiling returns are fixed-pressure
//!   outlets (without returns, CRAC tops take each CRAC's flow back); each server takes
//!   `Q = alpha * P * 4.71947e-4` m3/s from the cells at its intake face and releases it
//!   at its exhaust face. Racks, CRACs and containment panels are walls. Recirculation and
//!   bypass follow from mass balance.
//! * **Heat** is steady first-order upwind advection-diffusion on those fluxes with an
//!   effective turbulent diffusivity; supply enters at setpoint (+ effect offsets); each
//!   server's exhaust is its flow-weighted mean intake plus `P / (rho cp Q)`, coupled
//!   inside the linear operator. Sensors read trilinear interpolation of cell centres,
//!   leaving out solid cells and those across a containment panel from the sensor.
//! * The grid topology is built once in [`Simulator::new`]; each [`Simulator::solve`]
//!   assembles sources and coefficients and runs CG (pressure) and BiCGSTAB (temperature),
//!   matrix-free, preconditioned by geometric multigrid ([`Preconditioner`]), bit-identical
//!   at any thread count. The pressure hierarchy depends on the topology only and is built
//!   once too (again per run only when effects open containment panels).
//!
//! Effects ([`crate::effects::Effect`]) change a run through [`SimMods`].

mod advection;
mod config;
mod dense;
mod flow;
mod grid;
mod heat;
mod heat_sources;
mod influence;
mod inlets;
pub mod jets;
mod linalg;
mod mods;
mod multigrid;
mod panel;
mod placement;
mod run;
mod snapping;
mod solution;
mod supply;
mod topology;
mod vtk;

pub use advection::AdvectionStats;
pub use config::{Advection, FrontSupply, Preconditioner, SimConfig, DEFAULT_CONTAINMENT_PANEL_M};
pub use grid::Grid;
pub use heat_sources::{
    rack_heat, sensor_warming, write_rack_heat, RackHeat, SensorWarming, MIN_WARMING_K,
};
pub use influence::SensorInfluence;
pub use inlets::{
    coldest_under_read, inlet_check, intake_error, server_air, setpoint_headroom_c,
    write_server_air, InletCheck, IntakeError, ServerAir, RECOMMENDED_MAX_INLET_C,
};
pub use linalg::SolveStats;
pub use mods::{AirLink, RackRecirculation, SimMods, SupplyOpening, WallOpening, WallSide};
pub use snapping::{
    containment_side_on_cell_centre, grid_placing_all, off_grid_edges, SnappedEdge,
};
pub use solution::Solution;
pub use supply::tile_flows_m3_s;
/// The face a `front` CRAC blows through: the OpenFOAM case puts its supply there too.
pub(crate) use topology::front_side;

pub use topology::{cells_beyond_cap, MAX_CELLS};
pub use vtk::{vtk_file_name, write_vtk};

use crate::effects::Effect;
use crate::hall::Hall;
use crate::snapshots::OperatingState;
use crate::Result;

/// One cfm in m3/s.
pub const M3_S_PER_CFM: f64 = 4.71947e-4;

/// The simulator for one hall and grid: topology built once, solved per operating state.
#[derive(Debug, Clone)]
pub struct Simulator {
    hall: Hall,
    config: SimConfig,
    topo: topology::Topology,
    /// Multigrid of the pressure operator without wall openings (it depends on the
    /// topology only), built once.
    pressure_mg: Option<multigrid::Multigrid>,
}

impl Simulator {
    /// Builds the grid topology of `hall` (checks the configuration and the hall first:
    /// a hall built in code rather than read from a file gets the file's checks, named
    /// ``hall `NAME` `` for the hall named NAME).
    pub fn new(hall: &Hall, config: SimConfig) -> Result<Self> {
        config.check()?;
        hall.validate(&format!("hall `{}`", hall.name))?;
        let topo = topology::Topology::build(hall, &config)?;
        let pressure_mg = (config.preconditioner == Preconditioner::Multigrid).then(|| {
            let g = [
                topo.g[0].as_slice(),
                topo.g[1].as_slice(),
                topo.g[2].as_slice(),
            ];
            run::pressure_multigrid(&topo.grid, g, &topo.g_outlet, &topo.solid)
        });
        Ok(Simulator {
            hall: hall.clone(),
            config,
            topo,
            pressure_mg,
        })
    }

    /// The hall.
    pub fn hall(&self) -> &Hall {
        &self.hall
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The grid.
    pub fn grid(&self) -> &Grid {
        &self.topo.grid
    }

    /// Solid (rack, CRAC, enclosed) flag per cell.
    pub fn solid(&self) -> &[bool] {
        &self.topo.solid
    }

    /// The sensors (hall order) within half a cell of a containment panel: each reads the
    /// air on its own side of the panel (the cell centres across it are left out of its
    /// interpolation).
    pub fn sensors_beside_panels(&self) -> &[usize] {
        &self.topo.sensors_beside_panels
    }

    /// Number of fluid (active) cells.
    pub fn fluid_cells(&self) -> usize {
        self.topo.solid.iter().filter(|s| !**s).count()
    }

    /// Solves one operating state with per-server alpha (cfm/W, hall order) and effects
    /// with their parameter values.
    pub fn solve(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        effects: &[(&dyn Effect, &[f64])],
    ) -> Result<Solution> {
        let mods = self.effect_mods(effects)?;
        self.solve_with_mods(state, alpha_per_server, &mods)
    }

    /// The modifications `effects` at their parameter values ask of a run (what
    /// [`Self::solve`] passes to [`Self::solve_with_mods`]).
    pub fn effect_mods(&self, effects: &[(&dyn Effect, &[f64])]) -> Result<SimMods> {
        let mut mods = SimMods::new(self.hall.cracs.len());
        for (e, values) in effects {
            e.modify(values, &self.hall, &mut mods)?;
        }
        Ok(mods)
    }

    /// Solves with explicit modifications (what [`Self::solve`] builds from effects).
    pub fn solve_with_mods(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        mods: &SimMods,
    ) -> Result<Solution> {
        run::solve(self, state, alpha_per_server, mods)
    }

    pub(crate) fn topo(&self) -> &topology::Topology {
        &self.topo
    }

    pub(crate) fn pressure_mg(&self) -> Option<&multigrid::Multigrid> {
        self.pressure_mg.as_ref()
    }
}
