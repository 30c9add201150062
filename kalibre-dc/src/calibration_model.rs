//! The hall calibration with any model of a hall (OpenFOAM, an external command): the
//! surrogate, its terms and the temperature-rise prior are built from the hall exactly as
//! in [`crate::calibration::calibrate_hall`]; only the model runs change.

use std::path::Path;

use kalibre_core::calibrate::Report;
use kalibre_core::{Calibrator, Model, Observe, RunStore, Settings};

use crate::calibration::HallCalibrationSettings;
use crate::hall::Hall;
use crate::sim::{SensorInfluence, Simulator};
use crate::snapshots::{self, HallSnapshot, OperatingState};
use crate::surrogate::{
    Adjacency, EffectLinearTerm, FlowBalance, FlowBalanceTerm, LocalRecirculationTerm,
    PenaltyReport, TemperatureRisePenalty, ThermalGraph,
};
use crate::{Error, ParamLayout, Result};

/// The thermal graph every hall calibration searches on: the paper's cooling and heating
/// blocks, plus the mass-balance terms (`settings.flow_balance_terms`) and the local
/// recirculation term (`settings.local_recirculation`) when asked for.
///
/// With `settings.server_influence`, `flow` must be the built-in simulator and the
/// operating state whose air flow gives the hot-aisle edges
/// ([`server_influence_adjacency`]); other models have no flow to give, and are refused.
pub fn hall_surrogate(
    hall: &Hall,
    layout: &ParamLayout,
    settings: &HallCalibrationSettings,
    flow: Option<(&Simulator, &OperatingState)>,
) -> Result<ThermalGraph> {
    let mut surrogate = ThermalGraph::new(hall, layout.clone(), settings.surrogate)?;
    if let Some(cut) = settings.server_influence {
        let (sim, state) = flow.ok_or_else(|| {
            Error::Mismatch(
                "server_influence: the server-sensor edges from the air flow need the \
                 built-in simulator; this model does not give its flow"
                    .into(),
            )
        })?;
        let adjacency = server_influence_adjacency(sim, layout, state, settings, cut)?;
        surrogate = surrogate.with_adjacency(adjacency)?;
    }
    if settings.flow_balance_terms {
        for kind in [FlowBalance::Recirculation, FlowBalance::Bypass] {
            surrogate = surrogate.with_term(Box::new(FlowBalanceTerm::new(hall, layout, kind)));
        }
    }
    if let Some(local) = settings.local_recirculation {
        surrogate = surrogate.with_term(Box::new(LocalRecirculationTerm::with_settings(
            hall, layout, local,
        )?));
    }
    Ok(surrogate)
}

/// The graph's adjacency with hot-aisle edges from `sim`'s air flow at `state` and the
/// layout's initial alphas, without effects ([`Simulator::sensor_influence`], then
/// [`Adjacency::with_server_influence`] with `cut`); the CRAC edges stay geometric.
pub fn server_influence_adjacency(
    sim: &Simulator,
    layout: &ParamLayout,
    state: &OperatingState,
    settings: &HallCalibrationSettings,
    cut: f64,
) -> Result<Adjacency> {
    let influence = initial_influence(sim, layout, state)?;
    influence_adjacency(sim.hall(), state, settings, &influence, cut)
}

/// The sensors' influence in `sim`'s flow at `state` and the layout's initial alphas,
/// without effects: their values are what the loop is still to find.
pub fn initial_influence(
    sim: &Simulator,
    layout: &ParamLayout,
    state: &OperatingState,
) -> Result<SensorInfluence> {
    let alpha = layout.alpha_per_server(&layout.space().initial());
    Ok(sim.sensor_influence(state, &alpha, &[])?.1)
}

/// The graph's adjacency with hot-aisle edges from `influence` (taken at `state`), cut at
/// `cut`; the CRAC edges stay geometric.
pub fn influence_adjacency(
    hall: &Hall,
    state: &OperatingState,
    settings: &HallCalibrationSettings,
    influence: &SensorInfluence,
    cut: f64,
) -> Result<Adjacency> {
    Adjacency::from_hall(hall, &settings.surrogate.adjacency)?.with_server_influence(
        &influence.per_sensor,
        &state.power_w,
        cut,
    )
}

/// What a calibration with an external model returns.
#[derive(Debug)]
pub struct ModelCalibration {
    /// The calibration report (`report.json`).
    pub report: Report,
    /// The temperature-rise prior's report at the best parameters.
    pub penalty_report: PenaltyReport,
}

/// Calibrates `model` (whose parameters are laid out as `layout`, the layout the built-in
/// model would use for `hall`) against `snaps`, journaling runs in `journal` when given.
///
/// `settings.alpha_mode` and `settings.sim` are not used: the model fixes the layout and
/// does its own solving.
pub fn calibrate_hall_model<'o, M>(
    hall: &Hall,
    snaps: &[HallSnapshot],
    model: &M,
    layout: &ParamLayout,
    settings: &HallCalibrationSettings,
    journal: Option<&Path>,
    observers: Vec<Box<dyn Observe + 'o>>,
) -> Result<ModelCalibration>
where
    M: Model<Scenario = OperatingState>,
{
    calibrate_with_terms(
        hall,
        snaps,
        model,
        layout,
        &[],
        settings,
        journal,
        observers,
        &[],
        None,
    )
}

/// [`calibrate_hall_model`] with an [`EffectLinearTerm`] in the surrogate for each
/// parameter index in `learned_params` (effect parameters whose effect asks for a
/// learned linear term), so that the search can move them, and the model's numerical
/// variants (`Calibrator::with_numerical_variant`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn calibrate_with_terms<'o, M>(
    hall: &Hall,
    snaps: &[HallSnapshot],
    model: &M,
    layout: &ParamLayout,
    learned_params: &[usize],
    settings: &HallCalibrationSettings,
    journal: Option<&Path>,
    observers: Vec<Box<dyn Observe + 'o>>,
    numerical_variants: &[(String, std::result::Result<&M, String>)],
    simulator: Option<&Simulator>,
) -> Result<ModelCalibration>
where
    M: Model<Scenario = OperatingState>,
{
    let observations = snapshots::to_observations(hall, snaps)?;
    // The flow of the first snapshot sets the influence edges (when asked for).
    let flow = simulator.zip(snaps.first().map(|s| &s.state));
    let space = layout.space().clone();
    if space.is_empty() {
        return Err(Error::Mismatch(format!(
            "hall `{}` has nothing to calibrate (alpha is fixed and no effect has parameters)",
            hall.name
        )));
    }
    // Parameters with equal bounds are given, not calibrated: a loop over them alone
    // would run its design and call a fixed point calibrated.
    if space.params().iter().all(|p| p.is_fixed()) {
        return Err(Error::Mismatch(format!(
            "hall `{}` has nothing to calibrate: every parameter has equal bounds ({}), so \
             it is given, not calibrated; widen a bound (or use `kalibre simulate`)",
            hall.name,
            kalibre_core::some_names(&space.names())
        )));
    }
    let mut surrogate = hall_surrogate(hall, layout, settings, flow)?;
    for &i in learned_params {
        surrogate =
            surrogate.with_term(Box::new(EffectLinearTerm::new(space.names()[i].clone(), i)));
    }
    let scenarios: Vec<_> = snaps.iter().map(|s| s.state.clone()).collect();
    let penalty = TemperatureRisePenalty::new(hall, layout, &scenarios, settings.penalty)?;
    let store = match journal {
        Some(path) => {
            // Runs an earlier version journaled under another fingerprint of this
            // model are its runs too.
            let store = RunStore::open_with_aliases(
                path,
                model.fingerprint(),
                &model.legacy_fingerprints(),
                settings.replay_failed,
            )?;
            let load = store.load_report();
            if load.other_fingerprint > 0 {
                return Err(Error::OtherModelJournal {
                    path: path.display().to_string(),
                    runs: load.other_fingerprint,
                    // Worth naming where the file mixes two models' runs.
                    first_line: load
                        .other_fingerprint_first_line
                        .filter(|_| load.loaded > 0),
                });
            }
            store
        }
        None => RunStore::in_memory(model.fingerprint()),
    };
    // As in `calibrate_hall`: the polish stage's Jacobians cost `dim + 1` runs per
    // snapshot, so it runs only for few parameters.
    let core_settings = Settings {
        regularizer_weight: settings.penalty.weight,
        polish_iterations: if space.dim() <= settings.polish_max_params {
            settings.core.polish_iterations
        } else {
            0
        },
        ..settings.core.clone()
    };
    let mut calibrator = Calibrator::new(model, surrogate, &observations, &space)
        .with_settings(core_settings)
        .with_searcher(settings.searcher.clone())
        .with_regularizer(&penalty, settings.penalty.weight)
        .with_store(store);
    if settings.design_within_prior {
        let (lower, upper) = settings.penalty.plausible_bounds(layout);
        calibrator = calibrator.with_design_bounds(lower, upper);
    }
    for (name, variant) in numerical_variants {
        calibrator = match variant {
            Ok(model) => calibrator.with_numerical_variant(name.clone(), *model),
            Err(reason) => {
                calibrator.with_unavailable_numerical_variant(name.clone(), reason.clone())
            }
        };
    }
    for o in observers {
        calibrator = calibrator.with_observer(move |e: &kalibre_core::Event<'_>| o.observe(e));
    }
    let report = calibrator.run()?;
    let best = report.best.params.values();
    // With its weight at 0 the prior took no part in the fit: it binds nothing.
    let penalty_report = match settings.penalty.weight > 0.0 {
        true => penalty.report(&best),
        false => penalty.report(&best).without_prior(),
    };
    Ok(ModelCalibration {
        report,
        penalty_report,
    })
}
