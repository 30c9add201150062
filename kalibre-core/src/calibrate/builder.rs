//! The [`Calibrator`]'s builder: the constructor, the `with_*` setters and the accessors.

use super::{Calibrator, Settings};
use crate::observe::Observe;
use crate::{
    ErrorMetrics, Model, Observations, ParamSpace, Regularizer, RunStore, Searcher, Surrogate,
    Validator,
};

impl<'a, M, Su> Calibrator<'a, M, Su, ErrorMetrics>
where
    M: Model,
    M::Scenario: Clone,
    Su: Surrogate<Scenario = M::Scenario> + Sync,
{
    /// A calibrator with default settings, the paper's hybrid searcher
    /// ([`crate::search::Hybrid`]: differential evolution, then Adam, then
    /// projected-gradient steps), [`ErrorMetrics`] and an in-memory journal. The
    /// scenarios must be `Clone` ([`Model::Scenario`]): the fits take them as one
    /// slice, copied once per calibration.
    pub fn new(
        model: &'a M,
        surrogate: Su,
        observations: &'a Observations<M::Scenario>,
        space: &'a ParamSpace,
    ) -> Self {
        Calibrator {
            model,
            surrogate,
            observations,
            space,
            searcher: Box::new(crate::search::Hybrid::default()),
            validator: ErrorMetrics,
            regularizer: None,
            store: None,
            observers: Vec::new(),
            settings: Settings::default(),
            setters: Vec::new(),
            design_bounds: None,
            numerical_variants: Vec::new(),
        }
    }
}

impl<'a, M, Su, V> Calibrator<'a, M, Su, V>
where
    M: Model,
    M::Scenario: Clone,
    Su: Surrogate<Scenario = M::Scenario> + Sync,
    V: Validator,
{
    /// Replaces the settings at once, except those a `with_*` call set, before or after:
    /// `.with_seed(7).with_settings(Settings::recommended())` calibrates with seed 7, as
    /// the other order does.
    pub fn with_settings(mut self, settings: Settings) -> Self {
        self.settings = settings;
        for set in &self.setters {
            set(&mut self.settings);
        }
        self
    }

    /// Sets a setting now and keeps the setter, so that a later `with_settings` does not
    /// undo it.
    fn set(mut self, set: impl Fn(&mut Settings) + Send + Sync + 'a) -> Self {
        set(&mut self.settings);
        self.setters.push(Box::new(set));
        self
    }

    /// The calibration seed.
    pub fn with_seed(self, seed: u64) -> Self {
        self.set(move |s| s.seed = seed)
    }

    /// Four-step iterations after the initial design.
    pub fn with_max_iterations(self, n: usize) -> Self {
        self.set(move |s| s.max_iterations = n)
    }

    /// Stop once the best score (by default the MAE) is at most `target`.
    pub fn with_target_score(self, target: f64) -> Self {
        self.set(move |s| s.target_score = Some(target))
    }

    /// Budget of model runs, initial design included.
    pub fn with_max_model_runs(self, n: usize) -> Self {
        self.set(move |s| s.max_model_runs = Some(n))
    }

    /// Budget of wall-clock time, seconds.
    pub fn with_max_wall_s(self, seconds: f64) -> Self {
        self.set(move |s| s.max_wall_s = Some(seconds))
    }

    /// At most this many model runs at once (a dedicated rayon pool).
    pub fn with_max_parallel_runs(self, n: usize) -> Self {
        self.set(move |s| s.max_parallel_runs = Some(n))
    }

    /// First-fit augmentation: samples per design run and noise sigma (unit box).
    pub fn with_augmentation(self, copies: usize, sigma: f64) -> Self {
        self.set(move |s| {
            s.augment_copies = copies;
            s.augment_sigma = sigma;
        })
    }

    /// Adds `weight * regularizer` to the search loss.
    pub fn with_regularizer(mut self, regularizer: &'a dyn Regularizer, weight: f64) -> Self {
        self.regularizer = Some(regularizer);
        self.set(move |s| s.regularizer_weight = weight)
    }

    /// The searcher of step 2.
    pub fn with_searcher(mut self, searcher: impl Searcher + 'a) -> Self {
        self.searcher = Box::new(searcher);
        self
    }

    /// The validator of step 4.
    pub fn with_validator<V2: Validator>(self, validator: V2) -> Calibrator<'a, M, Su, V2> {
        Calibrator {
            model: self.model,
            surrogate: self.surrogate,
            observations: self.observations,
            space: self.space,
            searcher: self.searcher,
            validator,
            regularizer: self.regularizer,
            store: self.store,
            observers: self.observers,
            settings: self.settings,
            setters: self.setters,
            design_bounds: self.design_bounds,
            numerical_variants: self.numerical_variants,
        }
    }

    /// The initial design spans this box (physical lower and upper values per parameter,
    /// within the space's bounds) instead of the whole space; checked when the loop starts.
    pub fn with_design_bounds(mut self, lower: Vec<f64>, upper: Vec<f64>) -> Self {
        self.design_bounds = Some((lower, upper));
        self
    }

    /// A numerical variant of the model (the same physics on a finer grid, say), run once
    /// per snapshot at the best parameters: how far its outputs would move the parameters
    /// is their numerical uncertainty (`ParamUncertainty::numerical`), and the report
    /// lists what each variant changed (`Report::numerical_checks`). With
    /// `Settings::numerical_weighting` and a polish, the variants also run at the loop's
    /// best before the polish, which then weighs each output by how far they move it.
    /// Its runs are not journaled.
    pub fn with_numerical_variant(mut self, name: impl Into<String>, model: &'a M) -> Self {
        self.numerical_variants.push((name.into(), Ok(model)));
        self
    }

    /// A numerical variant that could not be set up (a grid the geometry does not fit,
    /// say): the report lists it with `reason` as its error, and the calibration stands.
    pub fn with_unavailable_numerical_variant(
        mut self,
        name: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        self.numerical_variants
            .push((name.into(), Err(reason.into())));
        self
    }

    /// The run journal (its fingerprint must be the model's).
    pub fn with_store(mut self, store: RunStore) -> Self {
        self.store = Some(store);
        self
    }

    /// Adds an observer.
    pub fn with_observer(mut self, observer: impl Observe + 'a) -> Self {
        self.observers.push(Box::new(observer));
        self
    }

    /// The settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The surrogate (fitted, after [`Self::run`]).
    pub fn surrogate(&self) -> &Su {
        &self.surrogate
    }

    /// The run journal (after [`Self::run`], always present).
    pub fn store(&self) -> Option<&RunStore> {
        self.store.as_ref()
    }
}
