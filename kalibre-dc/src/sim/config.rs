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

    /// `rho * cp` (J/(m3 K)).
    pub fn rho_cp(&self) -> f64 {
        self.air_density_kg_m3 * self.air_cp_j_kg_k
    }

    /// Checks every setting against its range, naming the first offender.
    pub fn check(&self) -> Result<()> {
        let bad = |field: &str, v: String, range: &str| {
            Err(Error::Simulation(format!(
                "config `{field}` = {v} is outside {range}"
            )))
        };
        let in_range = |v: f64, lo: f64, hi: f64, lo_open: bool| {
            v.is_finite() && (if lo_open { v > lo } else { v >= lo }) && v <= hi
        };
        if !in_range(self.cell_m, 0.0, 5.0, true) {
            return bad("cell_m", self.cell_m.to_string(), "(0, 5]");
        }
        if !in_range(self.diffusivity_m2_s, 0.0, 10.0, false) {
            return bad(
                "diffusivity_m2_s",
                self.diffusivity_m2_s.to_string(),
                "[0, 10]",
            );
        }
        if !in_range(self.containment_leak_fraction, 0.0, 1.0, false) {
            return bad(
                "containment_leak_fraction",
                self.containment_leak_fraction.to_string(),
                "[0, 1]",
            );
        }
        if !in_range(self.pressure_tol, 0.0, 1e-3, true) {
            return bad("pressure_tol", self.pressure_tol.to_string(), "(0, 1e-3]");
        }
        if !in_range(self.heat_tol, 0.0, 1e-3, true) {
            return bad("heat_tol", self.heat_tol.to_string(), "(0, 1e-3]");
        }
        if self.max_iterations < 10 {
            return bad("max_iterations", self.max_iterations.to_string(), ">= 10");
        }
        if !in_range(self.air_density_kg_m3, 0.0, f64::MAX, true) {
            return bad(
                "air_density_kg_m3",
                self.air_density_kg_m3.to_string(),
                "> 0",
            );
        }
        if !in_range(self.air_cp_j_kg_k, 0.0, f64::MAX, true) {
            return bad("air_cp_j_kg_k", self.air_cp_j_kg_k.to_string(), "> 0");
        }
        Ok(())
    }
}
