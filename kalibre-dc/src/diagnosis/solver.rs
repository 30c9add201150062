//! What runs the diagnosis's solves: the built-in simulator (cheap) or the calibrated
//! model itself when it can represent the candidate effects (OpenFOAM:
//! [`crate::openfoam::OpenFoamEffectSolver`]). Its residuals are the solver's own at the
//! calibrated parameters, so it should be the model that was calibrated.

use crate::effects::Effect;
use crate::sim::{jets, SimConfig, Simulator};
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

    /// Other plausible readings of the same physics (a model-form ensemble): what each
    /// reads beyond this solver at the calibrated parameters is a sensor's model-form
    /// uncertainty, as the finer grid's is its discretisation error. None by default.
    fn model_form_variants(&self) -> Result<Vec<Box<dyn EffectSolver + '_>>> {
        Ok(Vec::new())
    }
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

    /// The tile jets carried up the cold aisle ([`crate::sim::jets`]): the physics the
    /// built-in model lacks that moves most of its readings against OpenFOAM's.
    fn model_form_variants(&self) -> Result<Vec<Box<dyn EffectSolver + '_>>> {
        Ok(vec![Box::new(JetSupply { sim: self })])
    }
}

/// The built-in simulator with each tile's supply released up its jet
/// ([`jets::draw_matched_links`] from the floor), a model-form variant.
struct JetSupply<'a> {
    sim: &'a Simulator,
}

impl EffectSolver for JetSupply<'_> {
    fn name(&self) -> String {
        "the built-in simulator with tile jets".into()
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
        let mut mods = self.sim.effect_mods(effects)?;
        let opening_share = mods.supply_opening_share();
        mods.air_links.extend(jets::draw_matched_links(
            self.sim.hall(),
            state,
            alpha_per_server,
            0.0,
            opening_share,
        ));
        self.sim
            .solve_with_mods(state, alpha_per_server, &mods)
            .map(|s| s.sensor_c().to_vec())
    }

    fn refined(&self, _factor: f64) -> Result<Option<Box<dyn EffectSolver>>> {
        Ok(None)
    }
}
