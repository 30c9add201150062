//! The paper's search: differential evolution, then Adam from its best point.

use std::time::Instant;

use super::{Adam, DifferentialEvolution, Objective, ProjectedGradient, SearchOutcome, Searcher};
use crate::Result;

/// Generations after which the hybrid's DE hands over to Adam if none beat its initial best.
pub const HYBRID_DE_GIVE_UP_AFTER: usize = 20;

/// Differential evolution (global, gradient-free), then Adam (local, gradient) from DE's
/// best point, as in the paper (Section 4.2, after Wang et al. 2015).
///
/// Defaults, and why they work both at a few and at thousands of coordinates:
///
/// | Phase | Default |
/// |---|---|
/// | DE | population 10, CR 0.6, F 0.8, up to 100 generations (the paper's), handing over after [`HYBRID_DE_GIVE_UP_AFTER`] generations if none beat the initial population's best |
/// | Adam | learning rate 0.1, decay 0.8 per 10 steps, 100 steps |
/// | local (beyond the paper) | spectral projected gradient from the best point, 40 steps, monotone |
///
/// - With few coordinates (alpha per server type), DE does most of the work: a
///   population of 10 covers the box and soon beats the start point, and from then on DE
///   runs its 100 generations; Adam then polishes its best.
/// - With thousands of coordinates (alpha per server, 2,240 at `hall-a` size), nine
///   random members and their differences are far worse than the start point, and a
///   trial for the start member replaces about 60% of its coordinates with such
///   differences, so DE's best stays the start point. DE then hands over after 20
///   generations (210 evaluations instead of 1,010) and Adam, whose step moves every
///   coordinate at once, does the work. The same happens at a few coordinates when the
///   start is already better than anything DE finds in 20 generations (later iterations
///   of the loop start from the best point so far): Adam refines it.
/// - Near an optimum of a smooth, ill-conditioned loss (the corrected surrogate late in
///   a calibration), Adam's sign-like first steps overshoot the narrow valley and none of
///   its 100 steps may beat the start: the search would return its start point and waste
///   a model run. The local phase ([`ProjectedGradient`]) follows the projected gradient
///   with Barzilai-Borwein steps and a backtracking line search, so it takes whatever
///   descent is left, at any dimension. `with_local(ProjectedGradient::with_steps(0)?)`
///   gives the paper's two phases.
///
/// The outcome's trace holds DE's generations (phase `de`), Adam's steps (phase `adam`)
/// and the local steps (phase `spg`), numbered across all three.
#[derive(Debug, Clone, PartialEq)]
pub struct Hybrid {
    de: DifferentialEvolution,
    adam: Adam,
    local: ProjectedGradient,
}

impl Default for Hybrid {
    fn default() -> Self {
        let de = DifferentialEvolution::default()
            .to_builder()
            .with_give_up_after(Some(HYBRID_DE_GIVE_UP_AFTER))
            .build()
            .unwrap_or_default();
        Hybrid {
            de,
            adam: Adam::default(),
            local: ProjectedGradient::default(),
        }
    }
}

impl Hybrid {
    /// A hybrid of checked settings.
    pub fn new(de: DifferentialEvolution, adam: Adam) -> Self {
        Hybrid {
            de,
            adam,
            local: ProjectedGradient::default(),
        }
    }
    /// Replaces the DE phase's settings.
    pub fn with_de(mut self, de: DifferentialEvolution) -> Self {
        self.de = de;
        self
    }
    /// Replaces the Adam phase's settings.
    pub fn with_adam(mut self, adam: Adam) -> Self {
        self.adam = adam;
        self
    }

    /// Replaces the local phase (0 steps: none, as in the paper).
    pub fn with_local(mut self, local: ProjectedGradient) -> Self {
        self.local = local;
        self
    }

    /// The local phase.
    pub fn local(&self) -> &ProjectedGradient {
        &self.local
    }
    /// The DE phase's settings.
    pub fn de(&self) -> &DifferentialEvolution {
        &self.de
    }
    /// The Adam phase's settings.
    pub fn adam(&self) -> &Adam {
        &self.adam
    }
}

impl Searcher for Hybrid {
    fn search(&self, objective: &dyn Objective, start: &[f64], seed: u64) -> Result<SearchOutcome> {
        self.search_until(objective, start, seed, None)
    }

    fn search_until(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        seed: u64,
        deadline: Option<Instant>,
    ) -> Result<SearchOutcome> {
        let de = self.de.search_until(objective, start, seed, deadline)?;
        if de.timed_out {
            return Ok(de);
        }
        let adam = self
            .adam
            .run(objective, &de.best_unit, de.trace.len(), deadline)?;
        let mut timed_out = adam.timed_out;
        let mut trace = de.trace;
        trace.extend(adam.trace);
        // Adam starts at DE's best, so it can only match or improve it; `<` keeps DE's
        // point on a tie.
        let (best_unit, best_cost) = if adam.best_cost < de.best_cost {
            (adam.best_unit, adam.best_cost)
        } else {
            (de.best_unit, de.best_cost)
        };
        let mut evaluations = de.evaluations + adam.evaluations;
        let (best_unit, best_cost) =
            if self.local.steps() > 0 && best_cost.is_finite() && !timed_out {
                let local = self
                    .local
                    .run(objective, &best_unit, trace.len(), deadline)?;
                timed_out = local.timed_out;
                trace.extend(local.trace);
                evaluations += local.evaluations;
                if local.best_cost < best_cost {
                    (local.best_unit, local.best_cost)
                } else {
                    (best_unit, best_cost)
                }
            } else {
                (best_unit, best_cost)
            };
        Ok(SearchOutcome {
            best_unit,
            best_cost,
            evaluations,
            trace,
            timed_out,
        })
    }
}
