//! Simulator settings.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// Settings of the built-in simulator.
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `cell_m` | 0.2 | target cell size (m); each axis gets `round(L / cell_m)` cells | (0, 5] |
/// | `diffusivity_m2_s` | 0.01 | effective turbulent diffusivity of heat (m2/s) | [0, 10] |
/// | `containment_leak_fraction` | 0.02 | open fraction of containment panels (real panels leak; a sealed contained region with unbalanced flow has no steady state) | [0, 1] |
/// | `pressure_tol` | 1e-9 | relative residual of the pressure solve | (0, 1e-3] |
/// | `heat_tol` | 1e-9 | relative residual of the temperature solve | (0, 1e-3] |
/// | `max_iterations` | 20000 | Krylov iteration limit per solve | >= 10 |
/// | `preconditioner` | `multigrid` | Krylov preconditioner of both solves | `multigrid`, `jacobi` |
/// | `air_density_kg_m3` | 1.2 | rho | > 0 |
/// | `air_cp_j_kg_k` | 1005 | cp | > 0 |
/// | `advection` | `upwind` | advection scheme of the temperature equation | `upwind`, `van_leer`, `minmod` |
/// | `advection_max_outer` | 10 | deferred-correction passes after the upwind solve (TVD schemes only) | [1, 100] |
/// | `advection_tol_c` | 1e-3 | stop the passes when no cell temperature moves more than this (C) | (0, 1] |
/// | `front_supply` | `jet` | where a `front` CRAC's supply enters: along its jet to the first solid or wall, or at its face only (before session 58; kept for studies and tests that want a point-like inflow) | `jet`, `face` |
/// | `containment_panel_m` | 0.2 | thickness (m) of a containment panel, so that its resistance (and leakage) does not depend on the grid; `null`: one cell thick, whose resistance halves with the cell size (kalibre before 0.2 m panels; the maximum 0.2 -> 0.1 m change on the demo was 3.4 C with it, 0.34 C without) | (0, 5] |
///
/// Fields after `preconditioner` are optional in files (missing: the default) and are
/// written only when not at their default, so older files parse and the serialized form
/// of a default configuration (a model fingerprint) is unchanged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Target cell size (m).
    pub cell_m: f64,
    /// Effective turbulent diffusivity (m2/s).
    pub diffusivity_m2_s: f64,
    /// Open fraction of containment panels.
    pub containment_leak_fraction: f64,
    /// Relative residual of the pressure solve.
    pub pressure_tol: f64,
    /// Relative residual of the temperature solve.
    pub heat_tol: f64,
    /// Krylov iteration limit per solve.
    pub max_iterations: usize,
    /// Preconditioner of the pressure and temperature solves (missing in older files:
    /// multigrid).
    #[serde(default)]
    pub preconditioner: Preconditioner,
    /// Air density (kg/m3).
    pub air_density_kg_m3: f64,
    /// Air heat capacity (J/(kg K)).
    pub air_cp_j_kg_k: f64,
    /// Advection scheme of the temperature equation (missing in older files: upwind).
    #[serde(default, skip_serializing_if = "Advection::is_upwind")]
    pub advection: Advection,
    /// Deferred-correction passes after the first (upwind) solve, TVD schemes only.
    #[serde(
        default = "default_max_outer",
        skip_serializing_if = "is_default_max_outer"
    )]
    pub advection_max_outer: usize,
    /// Largest cell temperature change (C) of a pass below which the passes stop.
    #[serde(default = "default_tol_c", skip_serializing_if = "is_default_tol_c")]
    pub advection_tol_c: f64,
    /// Containment panels as a layer of this thickness (m) in series with free air, so
    /// that their leakage does not change with the grid (missing: 0.2 m; `null`: one cell
    /// thick, whose resistance halves with the cell size). At `cell_m` equal to it, both
    /// agree.
    #[serde(
        default = "default_panel_m",
        skip_serializing_if = "is_default_panel_m"
    )]
    pub containment_panel_m: Option<f64>,
    /// Where a `front` CRAC's supply enters (missing: along the jet).
    #[serde(default, skip_serializing_if = "FrontSupply::is_jet")]
    pub front_supply: FrontSupply,
}

/// Where the supply of a `front` CRAC enters the room.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrontSupply {
    /// Along the jet: each cell beyond the face marched on to the first solid or the
    /// room's wall, its share spread evenly along the way (docs/models.md, "Front-supply
    /// CRACs and halls without grilles").
    #[default]
    Jet,
    /// In the cells just beyond the face only.
    Face,
}

impl FrontSupply {
    fn is_jet(&self) -> bool {
        *self == FrontSupply::Jet
    }
}

const DEFAULT_MAX_OUTER: usize = 10;
/// The default containment panel thickness (m): the default cell, so that at the default
/// grid panels leak as they did when they were one cell thick.
pub const DEFAULT_CONTAINMENT_PANEL_M: f64 = 0.2;

fn default_panel_m() -> Option<f64> {
    Some(DEFAULT_CONTAINMENT_PANEL_M)
}

fn is_default_panel_m(v: &Option<f64>) -> bool {
    *v == default_panel_m()
}
const DEFAULT_TOL_C: f64 = 1e-3;

fn default_max_outer() -> usize {
    DEFAULT_MAX_OUTER
}

fn is_default_max_outer(v: &usize) -> bool {
    *v == DEFAULT_MAX_OUTER
}

fn default_tol_c() -> f64 {
    DEFAULT_TOL_C
}

fn is_default_tol_c(v: &f64) -> bool {
    *v == DEFAULT_TOL_C
}

/// Advection scheme of the temperature equation.
///
/// The TVD schemes keep the upwind matrix (and so the multigrid-preconditioned BiCGSTAB
/// solve) and add the difference between the limited second-order face value and the
/// upwind one as an explicit source, updated in a few deferred-correction passes. Their
/// limiters stay in Sweby's second-order TVD region, so no new extrema appear.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Advection {
    /// First-order upwind (numerical diffusion about `|U| dx / 2`).
    #[default]
    Upwind,
    /// TVD with the van Leer limiter `psi(r) = (r + |r|) / (1 + |r|)`.
    VanLeer,
    /// TVD with the minmod limiter `psi(r) = max(0, min(1, r))` (the most diffusive TVD).
    Minmod,
}

impl Advection {
    /// True for first-order upwind.
    pub fn is_upwind(&self) -> bool {
        *self == Advection::Upwind
    }
}

/// Preconditioner of the simulator's Krylov solves. Both give the same answers to solver
/// tolerance; Jacobi is the slow reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preconditioner {
    /// Geometric multigrid V-cycle (iteration counts nearly independent of the grid).
    #[default]
    Multigrid,
    /// Diagonal scaling (iteration counts grow with the grid extent).
    Jacobi,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            cell_m: 0.2,
            diffusivity_m2_s: 0.01,
            containment_leak_fraction: 0.02,
            pressure_tol: 1e-9,
            heat_tol: 1e-9,
            max_iterations: 20000,
            preconditioner: Preconditioner::Multigrid,
            air_density_kg_m3: 1.2,
            air_cp_j_kg_k: 1005.0,
            advection: Advection::Upwind,
            advection_max_outer: DEFAULT_MAX_OUTER,
            advection_tol_c: DEFAULT_TOL_C,
            containment_panel_m: default_panel_m(),
            front_supply: FrontSupply::Jet,
        }
    }
}

impl SimConfig {
    /// Sets the cell size (m).
    pub fn with_cell_m(mut self, cell_m: f64) -> Self {
        self.cell_m = cell_m;
        self
    }

    /// Sets the effective diffusivity (m2/s).
    pub fn with_diffusivity_m2_s(mut self, d: f64) -> Self {
        self.diffusivity_m2_s = d;
        self
    }

    /// Sets the containment panel leak fraction.
    pub fn with_containment_leak_fraction(mut self, f: f64) -> Self {
        self.containment_leak_fraction = f;
        self
    }

    /// Sets both solver tolerances.
    pub fn with_tolerances(mut self, pressure_tol: f64, heat_tol: f64) -> Self {
        self.pressure_tol = pressure_tol;
        self.heat_tol = heat_tol;
        self
    }

    /// Sets the preconditioner of both solves.
    pub fn with_preconditioner(mut self, p: Preconditioner) -> Self {
        self.preconditioner = p;
        self
    }

    /// Sets the iteration limit.
    pub fn with_max_iterations(mut self, n: usize) -> Self {
        self.max_iterations = n;
        self
    }

    /// Sets the advection scheme of the temperature equation.
    pub fn with_advection(mut self, advection: Advection) -> Self {
        self.advection = advection;
        self
    }

    /// Sets where a `front` CRAC's supply enters.
    pub fn with_front_supply(mut self, front_supply: FrontSupply) -> Self {
        self.front_supply = front_supply;
        self
    }

    /// Sets the deferred-correction passes (TVD schemes): at most `max_outer`, stopping
    /// when no cell temperature changes by more than `tol_c` (C).
    pub fn with_advection_outer(mut self, max_outer: usize, tol_c: f64) -> Self {
        self.advection_max_outer = max_outer;
        self.advection_tol_c = tol_c;
        self
    }

    /// Models containment panels as a layer `panel_m` thick (grid-independent leakage; the
    /// default is [`DEFAULT_CONTAINMENT_PANEL_M`]), or one cell thick with `None`.
    pub fn with_containment_panel_m(mut self, panel_m: Option<f64>) -> Self {
        self.containment_panel_m = panel_m;
        self
    }

    /// `rho * cp` (J/(m3 K)).
    pub fn rho_cp(&self) -> f64 {
        self.air_density_kg_m3 * self.air_cp_j_kg_k
    }

    /// Checks every setting against its range, naming the first offender.
    pub fn check(&self) -> Result<()> {
        let bad = |field: &str, v: String, range: &str| {
            Err(Error::Geometry(format!(
                "config `{field}` = {v} is outside {range}"
            )))
        };
        let in_range = |v: f64, lo: f64, hi: f64, lo_open: bool| {
            v.is_finite() && (if lo_open { v > lo } else { v >= lo }) && v <= hi
        };
        if !in_range(self.cell_m, 0.0, 5.0, true) {
            return bad("cell_m", crate::snapshots::number(self.cell_m), "(0, 5]");
        }
        if !in_range(self.diffusivity_m2_s, 0.0, 10.0, false) {
            return bad(
                "diffusivity_m2_s",
                crate::snapshots::number(self.diffusivity_m2_s),
                "[0, 10]",
            );
        }
        if !in_range(self.containment_leak_fraction, 0.0, 1.0, false) {
            return bad(
                "containment_leak_fraction",
                crate::snapshots::number(self.containment_leak_fraction),
                "[0, 1]",
            );
        }
        if !in_range(self.pressure_tol, 0.0, 1e-3, true) {
            return bad(
                "pressure_tol",
                crate::snapshots::number(self.pressure_tol),
                "(0, 1e-3]",
            );
        }
        if !in_range(self.heat_tol, 0.0, 1e-3, true) {
            return bad(
                "heat_tol",
                crate::snapshots::number(self.heat_tol),
                "(0, 1e-3]",
            );
        }
        if self.max_iterations < 10 {
            return bad("max_iterations", self.max_iterations.to_string(), ">= 10");
        }
        if !in_range(self.air_density_kg_m3, 0.0, f64::MAX, true) {
            return bad(
                "air_density_kg_m3",
                crate::snapshots::number(self.air_density_kg_m3),
                "> 0",
            );
        }
        if !in_range(self.air_cp_j_kg_k, 0.0, f64::MAX, true) {
            return bad(
                "air_cp_j_kg_k",
                crate::snapshots::number(self.air_cp_j_kg_k),
                "> 0",
            );
        }
        if !(1..=100).contains(&self.advection_max_outer) {
            return bad(
                "advection_max_outer",
                self.advection_max_outer.to_string(),
                "[1, 100]",
            );
        }
        if !in_range(self.advection_tol_c, 0.0, 1.0, true) {
            return bad(
                "advection_tol_c",
                crate::snapshots::number(self.advection_tol_c),
                "(0, 1]",
            );
        }
        if let Some(t) = self.containment_panel_m {
            if !in_range(t, 0.0, 5.0, true) {
                return bad("containment_panel_m", crate::snapshots::number(t), "(0, 5]");
            }
        }
        Ok(())
    }
}
