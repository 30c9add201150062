//! The paper's search: differential evolution, then Adam from its best point.

use super::{Adam, DifferentialEvolution, Objective, SearchOutcome, Searcher};
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
///
/// The outcome's trace holds DE's generations (phase `de`) followed by Adam's steps
/// (phase `adam`), numbered across both.
#[derive(Debug, Clone, PartialEq)]
pub struct Hybrid {
    de: DifferentialEvolution,
    adam: Adam,
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
        }
    }
}

impl Hybrid {
    /// A hybrid of checked settings.
    pub fn new(de: DifferentialEvolution, adam: Adam) -> Self {
        Hybrid { de, adam }
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
        let de = self.de.search(objective, start, seed)?;
        let adam = self.adam.run(objective, &de.best_unit, de.trace.len())?;
        let mut trace = de.trace;
        trace.extend(adam.trace);
        // Adam starts at DE's best, so it can only match or improve it; `<` keeps DE's
        // point on a tie.
        let (best_unit, best_cost) = if adam.best_cost < de.best_cost {
            (adam.best_unit, adam.best_cost)
        } else {
            (de.best_unit, de.best_cost)
        };
        Ok(SearchOutcome {
            best_unit,
            best_cost,
            evaluations: de.evaluations + adam.evaluations,
            trace,
        })
    }
}
