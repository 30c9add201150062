//! The four-step calibration loop: fit, search, run, validate.
//!
//! The [`Calibrator`] reads like argmin's `Executor`: a builder with `with_*` setters,
//! settings checked once, and [`Calibrator::run`] returning a serialisable [`Report`].

mod builder;
mod contract;
mod correction;
mod design;
mod geometry;
mod numerical;
mod polish;
mod propose;
mod report;
mod robust;
pub(crate) mod runner;
mod settings;
mod slopes;
mod state;
mod trust;
mod uncertainty;
mod unreached;

pub use numerical::{NumericalCheck, SKIPPED_PAST_WALL};
pub use propose::FAILED_NEIGHBOURHOOD_UNIT;
pub use report::{
    Best, Errors, Initial, IterationRecord, NamedValues, PassedOver, Report, Residual, RunCounts,
    SnapshotErrors, StopReason, Timings, REPORT_SCHEMA,
};
pub use settings::{Settings, MIN_FOCUS, MIN_ROBUST_NU, MIN_TRUST_REGION};
pub use slopes::UncertaintySlopes;
pub use uncertainty::{
    ParamUncertainty, CONVERGED_SHIFT_STDS, IDENTIFIED_REL_STD, REPEATED_RESIDUAL_ICC,
    SETTLED_REL_SHIFT, UNCERTAINTY_MAX_PARAMS,
};
pub use unreached::{UnreachedBest, UnreachedRuns};

use std::time::Instant;

use crate::observe::{Event, Observe};
use crate::{
    Error, ErrorMetrics, Model, Observations, ParamSpace, Regularizer, Result, RunStore, Sample,
    Searcher, Surrogate, SurrogateObjective, TrainingSet, Validation, Validator,
};
use design::{derive_seed, Stream};
use propose::Placement;
use robust::residuals as residuals_of;
use runner::Runner;
use state::State;

/// A `with_*` call's change to the settings, kept to apply again after `with_settings`.
type Setter<'a> = Box<dyn Fn(&mut Settings) + Send + Sync + 'a>;

/// The calibration loop over a model, a surrogate, a searcher and a validator.
///
/// See the crate documentation for a complete example.
pub struct Calibrator<'a, M: Model, Su, V = ErrorMetrics> {
    model: &'a M,
    surrogate: Su,
    observations: &'a Observations<M::Scenario>,
    space: &'a ParamSpace,
    searcher: Box<dyn Searcher + 'a>,
    validator: V,
    regularizer: Option<&'a dyn Regularizer>,
    store: Option<RunStore>,
    observers: Vec<Box<dyn Observe + 'a>>,
    settings: Settings,
    /// The `with_*` calls' settings, applied again by `with_settings`.
    setters: Vec<Setter<'a>>,
    design_bounds: Option<(Vec<f64>, Vec<f64>)>,
    /// Numerical variants of the model, or why one could not be set up.
    numerical_variants: Vec<(String, std::result::Result<&'a M, String>)>,
}

impl<'a, M, Su, V> Calibrator<'a, M, Su, V>
where
    M: Model,
    M::Scenario: Clone,
    Su: Surrogate<Scenario = M::Scenario> + Sync,
    V: Validator,
{
    fn emit(&self, event: Event<'_>) {
        for o in &self.observers {
            o.observe(&event);
        }
    }

    /// Replaces the search's proposal `unit` by `moved`, telling the observers.
    fn move_proposal(&self, iteration: usize, unit: &mut Vec<f64>, moved: Vec<f64>) {
        self.emit(Event::Perturbed {
            iteration,
            from_unit: unit,
            to_unit: &moved,
        });
        *unit = moved;
    }

    /// Runs the loop: initial design, then fit, search, run, validate until a stop rule fires.
    pub fn run(&mut self) -> Result<Report> {
        let t_start = Instant::now();
        let st = self.settings.clone();
        st.check()?;
        contract::check_inputs(self.model, self.space, self.observations)?;
        let fingerprint = self.model.fingerprint();
        let store = self
            .store
            .take()
            .unwrap_or_else(|| RunStore::in_memory(fingerprint.clone()));
        if store.fingerprint() != fingerprint {
            return Err(Error::Mismatch(format!(
                "run journal is for model fingerprint `{}`, the model's is `{fingerprint}`",
                store.fingerprint()
            )));
        }
        let result = self.run_with(&store, &st, t_start);
        self.store = Some(store);
        result
    }

    fn run_with(&mut self, store: &RunStore, st: &Settings, t_start: Instant) -> Result<Report> {
        let space = self.space;
        // With scales the loop works in scale units throughout: the measurements here,
        // the model's outputs in the runner.
        let normalised;
        let obs = match self.observations.scales() {
            Some(_) => {
                normalised = self.observations.normalised();
                &normalised
            }
            None => self.observations,
        };
        let names = space.names();
        let output_names = obs.output_names();
        let n_snap = obs.snapshots().len();
        let (design_units, initial_idx) =
            design::initial_design(space, self.design_bounds.as_ref())?;
        let design_runs = design_units.len() * n_snap;
        design::check_budget(st.max_model_runs, design_units.len(), n_snap)?;
        let pool = runner::pool(st.max_parallel_runs)?;
        let scenario_keys: Vec<String> = (obs.snapshots().iter())
            .map(|s| self.model.scenario_key(&s.scenario))
            .collect();
        let runner = Runner {
            model: self.model,
            observations: obs,
            store,
            param_names: &names,
            scenario_keys: &scenario_keys,
            output_names: &output_names,
            observers: &self.observers,
            pool: pool.as_ref(),
            scales: self.observations.scales(),
        };
        let judge = self.regularizer.filter(|_| st.prior_in_best);
        let mut state = State::judged_with(judge.map(|r| (r, st.regularizer_weight)));

        // The initial design.
        let design_phys: Vec<Vec<f64>> = design_units
            .iter()
            .map(|u| space.from_unit(u))
            .collect::<Result<_>>()?;
        let t_design = Instant::now();
        let design_results = runner.run(0, &design_phys)?;
        let design_s = t_design.elapsed().as_secs_f64();
        let mut design_samples = Vec::new();
        let mut initial_eval = None;
        // Why the design failed, should every run fail: the first reason, by design order.
        let first_failure = design_results
            .iter()
            .flatten()
            .find_map(|r| r.result.as_ref().err().cloned());
        let labels: Vec<&str> = obs.snapshots().iter().map(|s| s.label.as_str()).collect();
        let dead_snapshots =
            runner::snapshots_failed_throughout(&design_results, &labels, obs.noun(), store);
        for (i, results) in design_results.into_iter().enumerate() {
            let eval = state.absorb(
                &self.validator,
                obs,
                0,
                &design_units[i],
                &design_phys[i],
                results,
            )?;
            for s in state.samples[state.samples.len() - eval.ok_runs..].iter() {
                design_samples.push((design_units[i].clone(), s.clone()));
            }
            if i == initial_idx {
                initial_eval = Some(eval);
            }
        }
        let design_failed = state.counts.failed;
        self.emit(Event::DesignDone {
            points: design_units.len(),
            model_runs: design_runs,
            failed: design_failed,
        });
        if state.samples.is_empty() {
            return Err(runner::design_failed(design_runs, first_failure, store));
        }
        let augmented = design::augment(
            space,
            &design_samples,
            st.augment_copies,
            st.augment_sigma,
            derive_seed(st.seed, 0, Stream::Augment),
        )?;
        let initial_eval = initial_eval.expect("the design contains the initial point");
        let stat = |f: fn(&Validation) -> f64| initial_eval.validation.as_ref().map(f);
        let initial = Initial {
            mae_c: stat(|v| v.overall.mae),
            rmse_c: stat(|v| v.overall.rmse),
            max_abs_c: stat(|v| v.overall.max_abs),
            params: NamedValues::new(&names, &space.initial()),
            design_points: design_units.len(),
            design_runs,
            failed_runs: design_failed,
            wall_s: design_s,
        };

        // Fits take the scenarios as one slice; they are cloned once per calibration.
        let scenarios: Vec<M::Scenario> =
            obs.snapshots().iter().map(|s| s.scenario.clone()).collect();
        let mut history = Vec::new();
        let mut radius = st.trust_region;
        // The wall budget reaches inside the fits and searches too (none when too far off
        // to represent).
        let deadline = (st.max_wall_s)
            .and_then(|w| std::time::Duration::try_from_secs_f64(w).ok())
            .and_then(|w| t_start.checked_add(w));
        let mut iteration = 0;
        let mut stop = loop {
            let best_score = state.best.as_ref().map(|b| b.score);
            if let (Some(t), Some(b)) = (st.target_score, best_score) {
                if b <= t {
                    break StopReason::TargetError;
                }
            }
            if iteration >= st.max_iterations {
                break StopReason::MaxIterations;
            }
            if st
                .max_model_runs
                .is_some_and(|b| state.counts.total + n_snap > b)
            {
                break StopReason::ModelRunBudget;
            }
            if st
                .max_wall_s
                .is_some_and(|w| t_start.elapsed().as_secs_f64() >= w)
            {
                break StopReason::WallClockBudget;
            }
            iteration += 1;
            let t_iter = Instant::now();

            // Step 1: fit.
            let samples: &[Sample] = if iteration == 1 {
                &augmented
            } else {
                &state.samples
            };
            let focused;
            // The first fit learns the design, which spans the box: focusing it on the
            // best design run would leave the surrogate one point to learn from.
            let samples: &[Sample] = match st.focus.filter(|_| iteration > 1) {
                Some(width) => {
                    focused = design::focus(obs, samples, width);
                    &focused
                }
                None => samples,
            };
            let t = Instant::now();
            let fit = self.surrogate.fit_until(
                TrainingSet {
                    scenarios: &scenarios,
                    samples,
                },
                derive_seed(st.seed, iteration, Stream::Fit),
                deadline,
            )?;
            let training_samples = samples.len();
            let fit_s = t.elapsed().as_secs_f64();
            self.emit(Event::FitDone {
                iteration,
                samples: training_samples,
                summary: &fit,
                wall_s: fit_s,
            });
            // The budget is spent: a model run at a proposal would only overrun it more.
            if fit.timed_out {
                break StopReason::WallClockBudget;
            }

            // Step 2: search from the best point so far.
            let t = Instant::now();
            let start = match &state.best {
                Some(b) => b.unit.clone(),
                None => design_units[initial_idx].clone(),
            };
            let start_params = space.from_unit(&start)?;
            // A snapshot whose design runs all failed gave the surrogate nothing to learn
            // there; a surrogate that then predicts nothing for it is not the fault.
            contract::check_surrogate(&self.surrogate, obs, &start_params, iteration).map_err(
                |e| match &dead_snapshots {
                    Some(dead) => Error::NoSuccessfulRun(format!(
                        "{dead}: leave that {} out of the observations, or fix what fails \
                         there",
                        obs.noun()
                    )),
                    None => e,
                },
            )?;
            if let Some(reg) = self.regularizer {
                contract::check_regularizer(reg, &start_params)?;
            }
            let mut objective = SurrogateObjective::new(&self.surrogate, obs, space);
            if st.output_correction {
                if let Some(best) = &state.best {
                    objective = objective.with_correction(correction::fit(
                        &self.surrogate,
                        obs,
                        &state,
                        best,
                        st.linear_correction,
                    ));
                }
            }
            if let Some(reg) = self.regularizer {
                objective = objective.with_regularizer(reg, st.regularizer_weight);
            }
            let centre = state.best.as_ref().map(|b| b.unit.as_slice());
            let mut outcome = trust::search_within(
                self.searcher.as_ref(),
                &objective,
                &start,
                centre.zip(radius),
                derive_seed(st.seed, iteration, Stream::Search),
                deadline,
            )?;
            outcome.best_unit.iter_mut().for_each(|u| {
                if u.is_finite() {
                    *u = u.clamp(0.0, 1.0)
                }
            });
            let search_s = t.elapsed().as_secs_f64();
            // The data term alone: the rest of the loss is the regulariser's (a prior that
            // binds at the optimum shows as a gap between the two).
            let search_data_mse = space
                .from_unit(&outcome.best_unit)
                .map_or(f64::NAN, |p| objective.data_mse(&p));
            self.emit(Event::SearchDone {
                iteration,
                outcome: &outcome,
                wall_s: search_s,
            });
            if outcome.timed_out {
                break StopReason::WallClockBudget;
            }
            if outcome.best_unit.len() != space.dim()
                || outcome.best_unit.iter().any(|u| !u.is_finite())
            {
                return Err(Error::Search(format!(
                    "the searcher returned an invalid point {:?}",
                    outcome.best_unit
                )));
            }
            let mut unit: Vec<f64> = outcome
                .best_unit
                .iter()
                .map(|u| u.clamp(0.0, 1.0))
                .collect();
            let Placement::Run {
                perturbed,
                geometry_step,
            } = self.place_proposal(
                iteration,
                &mut unit,
                st,
                &state,
                &objective,
                outcome.best_cost,
            )
            else {
                break StopReason::Converged;
            };

            // Steps 3 and 4: run at every snapshot, validate.
            let params = space.from_unit(&unit)?;
            let t = Instant::now();
            let results = runner
                .run(iteration, std::slice::from_ref(&params))?
                .pop()
                .unwrap_or_default();
            let model_s = t.elapsed().as_secs_f64();
            let eval = state.absorb(&self.validator, obs, iteration, &unit, &params, results)?;
            // A geometry step tests the model, not the surrogate's proposal: the radius
            // stays.
            if let Some(r) = radius.as_mut().filter(|_| !geometry_step) {
                let improved = state
                    .best
                    .as_ref()
                    .is_some_and(|b| b.iteration == iteration);
                *r = if improved {
                    (*r * 2.0).min(1.0)
                } else {
                    (*r * 0.5).max(settings::MIN_TRUST_REGION)
                };
            }
            let record = polish::record(
                iteration,
                &state,
                &eval,
                n_snap,
                &names,
                &params,
                polish::StepInfo {
                    fit_mse: fit.train_mse,
                    training_samples,
                    search_loss: outcome.best_cost,
                    search_data_mse,
                    search_evaluations: outcome.evaluations,
                    perturbed,
                    wall_s: Timings {
                        fit_s,
                        search_s,
                        model_s,
                        total_s: t_iter.elapsed().as_secs_f64(),
                    },
                },
            );
            self.emit(Event::IterationDone { record: &record });
            history.push(record);
        };
        let mut model_jacobian = None;
        let polishing = st.polish_iterations > 0 && stop != StopReason::TargetError;
        // With numerical weighting the variants run before the polish, at the loop's best,
        // so that the polish can weigh each output by how far the numerics move it.
        let mut pre_polish_variants: Option<numerical::VariantRuns> = None;
        let numerical_changes = match state.best.as_ref() {
            Some(b)
                if polishing && st.numerical_weighting && !self.numerical_variants.is_empty() =>
            {
                let (checks, outputs) = numerical::run_variants(
                    &self.numerical_variants,
                    obs,
                    self.observations.scales(),
                    &b.outputs,
                    &b.params,
                    deadline,
                );
                let changes = numerical::row_changes(obs, &b.outputs, &outputs);
                pre_polish_variants = Some(numerical::VariantRuns {
                    unit: b.unit.clone(),
                    checks,
                    outputs,
                });
                changes
            }
            _ => None,
        };
        if polishing {
            let polish = polish::Polish {
                runner: &runner,
                validator: &self.validator,
                observations: obs,
                space,
                settings: st,
                names: &names,
                t_start,
                numerical_changes: numerical_changes.as_deref(),
            };
            let observers = &self.observers;
            let outcome = polish.run(&mut state, iteration, |record| {
                for o in observers {
                    o.observe(&Event::IterationDone { record });
                }
            })?;
            history.extend(outcome.records);
            model_jacobian = outcome.jacobian;
            // A budget that cut the polish short is why the calibration stopped where it
            // did, not the loop's own reason.
            if let Some(cut) = outcome.cut {
                stop = cut;
            }
        }
        self.emit(Event::Stopped { reason: stop });

        let repetition = state
            .best
            .as_ref()
            .and_then(|b| uncertainty::repetition(obs, &b.outputs));
        // Spreads (and the numerical variants weighed against them) only once a fit has
        // run: an unfitted surrogate has no slopes to speak of.
        let linearised_best = state
            .best
            .as_ref()
            .filter(|_| iteration > 0 && space.dim() <= UNCERTAINTY_MAX_PARAMS);
        let (numerical_checks, variant_outputs) = match (linearised_best, pre_polish_variants) {
            // The variants already ran at this point (the polish did not move it).
            (Some(b), Some(v)) if v.unit == b.unit => (v.checks, v.outputs),
            (Some(b), _) => numerical::run_variants(
                &self.numerical_variants,
                obs,
                self.observations.scales(),
                &b.outputs,
                &b.params,
                deadline,
            ),
            (None, _) => (Vec::new(), Vec::new()),
        };
        // The weights the polish used, at the reported point: the uncertainty of the
        // weighted estimate uses them too.
        let numerical_weights = match linearised_best {
            Some(b) if numerical_changes.is_some() => {
                numerical::row_changes(obs, &b.outputs, &variant_outputs).map(|u| {
                    numerical::row_weights(&residuals_of(obs, &b.outputs), &u, space.dim())
                })
            }
            _ => None,
        };
        let (uncertainty, uncertainty_slopes) = match linearised_best {
            Some(b) => {
                match slopes::slopes_at(
                    b,
                    model_jacobian.as_ref(),
                    &state,
                    &self.surrogate,
                    obs,
                    space,
                ) {
                    Some((jac, source)) => {
                        let design_effect = repetition.map_or(1.0, |r| r.design_effect());
                        let u = uncertainty::estimate(
                            &jac,
                            obs,
                            space,
                            b,
                            st.robust_nu,
                            design_effect,
                            numerical::Numerics {
                                variant_outputs: &variant_outputs,
                                weights: numerical_weights.as_deref(),
                            },
                        );
                        let source = (!u.is_empty()).then_some(source);
                        (u, source)
                    }
                    None => (Vec::new(), None),
                }
            }
            None => (Vec::new(), None),
        };
        let passed_over = state.best.as_ref().and_then(|b| state.passed_over(b));
        let best = state.best.ok_or_else(|| {
            let why = dead_snapshots.map_or_else(String::new, |d| format!(": {d}"));
            Error::NoSuccessfulRun(format!(
                "no parameter point ran successfully at every {}{why}",
                obs.noun()
            ))
        })?;
        let prior = state.prior.map(|_| best.rank - best.score);
        let prior = prior.filter(|p| p.is_finite());
        let residuals = report::residual_rows(
            self.observations,
            &best.outputs,
            numerical_weights.as_deref(),
        );
        Ok(Report {
            schema: REPORT_SCHEMA.into(),
            seed: st.seed,
            settings: st.clone(),
            best: Best {
                iteration: best.iteration,
                mae_c: best.validation.overall.mae,
                rmse_c: best.validation.overall.rmse,
                max_abs_c: best.validation.overall.max_abs,
                score: best.score,
                params: NamedValues::new(&names, &best.params),
                prior,
                passed_over,
            },
            uncertainty,
            uncertainty_slopes,
            residual_icc: repetition.map(|r| r.icc),
            numerical_checks,
            initial,
            history,
            residuals,
            stop_reason: stop,
            runs: state.counts,
            journal: store.path().map(|_| store.load_report().clone()),
            unreached: unreached::summarise(
                store,
                obs,
                &self.validator,
                self.space,
                &scenario_keys,
                self.observations.scales(),
            ),
            wall_s: t_start.elapsed().as_secs_f64(),
            model: None,
        })
    }
}
