//! What runs the diagnosis's solves: the built-in simulator (cheap) or the calibrated
//! model itself when it can represent the candidate effects (OpenFOAM:
//! [`crate::openfoam::OpenFoamEffectSolver`]). Its residuals are the solver's own at the
//! calibrated parameters, so it should be the model that was calibrated.

use crate::effects::Effect;
use crate::sim::{SimConfig, Simulator};
use crate::snapshots::OperatingState;
use crate::Result;

/// A solver of one snapshot of the hall with any list of effects: what a diagnosis needs
/// to linearise the calibrated model and each candidate effect.
pub trait EffectSolver: Sync {
    /// What solves, for messages (e.g. `the built-in simulator`).
    fn name(&self) -> String;

    /// Whether effects of `kind` can be represented. Candidates of other kinds are not
    /// tried, and the diagnosis says so.
    fn supports(&self, kind: &str) -> bool;

    /// Sensor temperatures (C, hall order) of `state` at `alpha_per_server` (cfm/W) with
    /// `effects` at the given parameter values.
    fn solve(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        effects: &[(&dyn Effect, &[f64])],
    ) -> Result<Vec<f64>>;

    /// The same solver on a grid `factor` (in (0, 1)) times as fine, to estimate its own
    /// discretisation error; `None` when that is not offered (too costly, or not a grid).
    fn refined(&self, factor: f64) -> Result<Option<Box<dyn EffectSolver>>>;
}

impl EffectSolver for Simulator {
    fn name(&self) -> String {
        "the built-in simulator".into()
    }

    fn supports(&self, _kind: &str) -> bool {
        true
    }

    fn solve(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        effects: &[(&dyn Effect, &[f64])],
    ) -> Result<Vec<f64>> {
        Simulator::solve(self, state, alpha_per_server, effects).map(|s| s.sensor_c().to_vec())
    }

    fn refined(&self, factor: f64) -> Result<Option<Box<dyn EffectSolver>>> {
        let cfg = self.config();
        let fine = Simulator::new(
            self.hall(),
            SimConfig {
                cell_m: cfg.cell_m * factor,
                ..cfg.clone()
            },
        )?;
        Ok(Some(Box::new(fine)))
    }
}
