//! Where the model runs after a search: at the search's proposal, or at a point moved
//! off it when the surrogate stalls, when it lies beside a failed run, or when it repeats
//! a run.

use super::design::{self, derive_seed, Stream};
use super::geometry;
use super::state::State;
use super::{Calibrator, Settings};
use crate::search::Objective;
use crate::{Model, Surrogate, Validator};

/// A proposal whose corrected-surrogate loss is less than this fraction below the best
/// run's counts as a stall: the surrogate promises too little to spend a model run on (see `Settings::stall_step`).
const STALL_GAIN: f64 = 0.1;
/// A proposal within this max-norm distance (unit box) of a failed run is moved off it
/// with `perturb_sigma`'s noise: a model that fails at a point fails beside it too.
pub const FAILED_NEIGHBOURHOOD_UNIT: f64 = 1e-3;

/// What becomes of a search's proposal.
pub(super) enum Placement {
    /// Run the model there (the point as placed).
    Run {
        /// It was moved off the proposal.
        perturbed: bool,
        /// It was moved by a geometry step, which tests the model rather than the
        /// surrogate (the trust region then stays).
        geometry_step: bool,
    },
    /// It repeats a run and the loop does not explore: converged.
    Converged,
}

fn near(pts: &[Vec<f64>], u: &[f64], tol: f64) -> bool {
    pts.iter().any(|p| design::distance(p, u) <= tol)
}

impl<M, Su, V> Calibrator<'_, M, Su, V>
where
    M: Model,
    M::Scenario: Clone,
    Su: Surrogate<Scenario = M::Scenario> + Sync,
    V: Validator,
{
    /// Places iteration `iteration`'s proposal `unit` (the search found it at
    /// `proposal_cost` of `objective`), moving it where it would waste a model run.
    pub(super) fn place_proposal(
        &self,
        iteration: usize,
        unit: &mut Vec<f64>,
        st: &Settings,
        state: &State<'_>,
        objective: &impl Objective,
        proposal_cost: f64,
    ) -> Placement {
        let mut perturbed = false;
        let mut geometry_step = false;
        if let (Some(h), Some(best)) = (st.stall_step, &state.best) {
            // The corrected surrogate matches the model at the best run, so its loss
            // there is the best run's loss (plus the regulariser's).
            let anchor_cost = objective.cost(&best.unit);
            let stalled = proposal_cost > anchor_cost - STALL_GAIN * anchor_cost.abs()
                || near(&state.ok_units, unit, st.duplicate_tol);
            if stalled {
                let moved = geometry::least_covered_step(
                    &best.unit,
                    &state.ok_units,
                    3.0 * crate::search::CORRECTION_LENGTH_UNIT,
                    h,
                    derive_seed(st.seed, iteration, Stream::Geometry),
                );
                self.move_proposal(iteration, unit, moved);
                perturbed = true;
                geometry_step = true;
            }
        }
        // Within a neighbourhood of a failed run, not only on it: a search's repeats
        // of one optimum differ by 1e-7 or so, and a failure there was paid again
        // every iteration.
        let failed_tol = st.duplicate_tol.max(FAILED_NEIGHBOURHOOD_UNIT);
        if near(&state.failed_units, unit, failed_tol) {
            let moved = design::perturb(
                unit,
                &state.failed_units,
                failed_tol,
                st.perturb_sigma,
                derive_seed(st.seed, iteration, Stream::Perturb),
            );
            self.move_proposal(iteration, unit, moved);
            perturbed = true;
        }
        if near(&state.ok_units, unit, st.duplicate_tol) {
            // The surrogate has nothing new to say here: stop, or sample near the
            // proposal so the next fit learns the neighbourhood.
            let Some(sigma) = st.explore_on_repeat else {
                return Placement::Converged;
            };
            let known: Vec<Vec<f64>> = state
                .ok_units
                .iter()
                .chain(&state.failed_units)
                .cloned()
                .collect();
            let moved = design::perturb(
                unit,
                &known,
                st.duplicate_tol,
                sigma,
                derive_seed(st.seed, iteration, Stream::Explore),
            );
            self.move_proposal(iteration, unit, moved);
            perturbed = true;
        }
        Placement::Run {
            perturbed,
            geometry_step,
        }
    }
}
