//! Kalibre on a data hall: the built-in simulator, the thermal graph surrogate, the
//! paper's search objective (with the temperature-rise prior) and the generic loop,
//! assembled once for the CLI, the demo, the experiments and the tests.

use std::path::Path;

use kalibre_core::calibrate::Report;
use kalibre_core::search::Hybrid;
use kalibre_core::{Calibrator, Model, Observe, RunStore, Settings};

use crate::hall::{AlphaMode, Hall};
use crate::sim::SimConfig;
use crate::snapshots::{self, HallSnapshot};
use crate::surrogate::{
    FlowBalance, FlowBalanceTerm, PenaltySettings, TemperatureRisePenalty, ThermalGraph,
    ThermalGraphSettings,
};
use crate::{Error, HallModel, Result};

/// Everything that shapes a hall calibration.
///
/// | Name | Default | Meaning |
/// |---|---|---|
/// | `seed` | 1 | seed of every random choice (augmentation, search) |
/// | `iterations` | 10 | four-step iterations after the initial design |
/// | `alpha_mode` | the hall's `calibrate.alpha` | per type, per server or fixed |
/// | `sim` | [`SimConfig::default`] | the built-in simulator (grid, tolerances) |
/// | `surrogate` | [`ThermalGraphSettings::default`] | Adam lr 0.1, decay 0.8, 150 epochs, fixed adjacency |
/// | `penalty` | [`PenaltySettings::default`] | rise range [5, 15] C, weight 1 |
/// | `searcher` | [`Hybrid::default`] | DE (population 10, crossover 0.6, 100 generations), then Adam |
/// | `target_mae_c` | none | stop once the model's MAE is at most this |
/// | `max_model_runs` | none | stop before exceeding this many model runs |
/// | `max_wall_s` | none | stop after this much wall time |
/// | `max_parallel_runs` | all threads | model runs at once |
/// | `focus` | 1 | runs with `m` times the best MAE weigh `exp(-((m-1)/focus)^2/2)` in the fit |
/// | `explore_on_repeat` | 0.015 | a repeated proposal is moved by this much noise (unit box, about 9% in alpha) rather than ending the loop |
/// | `output_correction` | true | search the surrogate corrected to match the model at the best run (beyond the paper) |
/// | `trust_region` | 0.1 | search within this distance (unit box) of the best point; grows on success, shrinks on failure |
/// | `local_recirculation_term` | false | add a per-sensor local draw-against-supply recirculation term (measured: mixed, see docs/performance.md) |
/// | `flow_balance_terms` | true | add recirculation and bypass terms to the surrogate (beyond the paper, which assumes neither) |
#[derive(Debug, Clone)]
pub struct HallCalibrationSettings {
    /// Seed.
    pub seed: u64,
    /// Iterations after the initial design.
    pub iterations: usize,
    /// Override of the hall's `calibrate.alpha`.
    pub alpha_mode: Option<AlphaMode>,
    /// Simulator configuration.
    pub sim: SimConfig,
    /// Surrogate training.
    pub surrogate: ThermalGraphSettings,
    /// The temperature-rise prior.
    pub penalty: PenaltySettings,
    /// The search on the surrogate.
    pub searcher: Hybrid,
    /// Target MAE (C).
    pub target_mae_c: Option<f64>,
    /// Model-run budget.
    pub max_model_runs: Option<usize>,
    /// Wall-clock budget (s).
    pub max_wall_s: Option<f64>,
    /// Parallel model runs.
    pub max_parallel_runs: Option<usize>,
    /// Add the mass-balance terms (recirculation, bypass) to the paper's thermal graph.
    pub flow_balance_terms: bool,
    /// Add the local recirculation term (local draw against local supply per sensor).
    pub local_recirculation_term: bool,
    /// Focus of the surrogate fit on runs near the measurements (see `kalibre_core::Settings`).
    pub focus: Option<f64>,
    /// Noise (unit box) that moves a repeated proposal instead of stopping.
    pub explore_on_repeat: Option<f64>,
    /// Correct the surrogate to the model at the best run before each search.
    pub output_correction: bool,
    /// Initial trust-region radius of the search (unit box).
    pub trust_region: Option<f64>,
}

impl Default for HallCalibrationSettings {
    fn default() -> Self {
        HallCalibrationSettings {
            seed: 1,
            iterations: 10,
            alpha_mode: None,
            sim: SimConfig::default(),
            surrogate: ThermalGraphSettings::default(),
            penalty: PenaltySettings::default(),
            searcher: Hybrid::default(),
            target_mae_c: None,
            max_model_runs: None,
            max_wall_s: None,
            max_parallel_runs: None,
            flow_balance_terms: true,
            local_recirculation_term: false,
            focus: Some(1.0),
            explore_on_repeat: Some(0.015),
            output_correction: true,
            trust_region: Some(0.1),
        }
    }
}

/// What a hall calibration returns: the report and the model it calibrated.
#[derive(Debug)]
pub struct HallCalibration {
    /// The calibration report (`report.json`).
    pub report: Report,
    /// The model, for follow-up runs (fields, VTK).
    pub model: HallModel,
    /// The temperature-rise prior's report at the best parameters.
    pub penalty_report: crate::surrogate::PenaltyReport,
}

/// Calibrates `hall` against `snaps`, journaling model runs in `journal` (a `runs.jsonl`
/// path) when given: a second call with the same journal replays finished runs instead
/// of repeating them.
pub fn calibrate_hall<'o>(
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &HallCalibrationSettings,
    journal: Option<&Path>,
    observers: Vec<Box<dyn Observe + 'o>>,
) -> Result<HallCalibration> {
    let mut hall = hall.clone();
    if let Some(mode) = settings.alpha_mode {
        hall.calibrate.alpha = mode;
    }
    let observations = snapshots::to_observations(&hall, snaps)?;
    let model = HallModel::new(&hall, settings.sim.clone())?;
    let layout = model.layout().clone();
    let space = layout.space().clone();
    if space.is_empty() {
        return Err(Error::Mismatch(format!(
            "hall `{}` has nothing to calibrate (alpha is fixed and no effect has parameters)",
            hall.name
        )));
    }
    let mut surrogate = ThermalGraph::new(&hall, layout.clone(), settings.surrogate)?;
    if settings.flow_balance_terms {
        for kind in [FlowBalance::Recirculation, FlowBalance::Bypass] {
            surrogate = surrogate.with_term(Box::new(FlowBalanceTerm::new(&hall, &layout, kind)));
        }
        if std::env::var("KALIBRE_LOCAL_TERM").is_ok() {
            surrogate = surrogate.with_term(Box::new(
                crate::surrogate::LocalRecirculationTerm::new(&hall, &layout),
            ));
        }
    }
    let scenarios: Vec<_> = snaps.iter().map(|s| s.state.clone()).collect();
    let penalty = TemperatureRisePenalty::new(&hall, &layout, &scenarios, settings.penalty)?;
    let store = match journal {
        Some(path) => {
            let store = RunStore::open(path, model.fingerprint())?;
            let load = store.load_report();
            if load.other_fingerprint > 0 {
                return Err(Error::Mismatch(format!(
                    "{}: holds {} runs of another model (a different hall, grid or effects); \
                     calibrate into another directory",
                    path.display(),
                    load.other_fingerprint
                )));
            }
            store
        }
        None => RunStore::in_memory(model.fingerprint()),
    };
    let core_settings = Settings {
        seed: settings.seed,
        max_iterations: settings.iterations,
        target_score: settings.target_mae_c,
        max_model_runs: settings.max_model_runs,
        max_wall_s: settings.max_wall_s,
        max_parallel_runs: settings.max_parallel_runs,
        regularizer_weight: settings.penalty.weight,
        focus: settings.focus,
        explore_on_repeat: settings.explore_on_repeat,
        output_correction: settings.output_correction,
        trust_region: settings.trust_region,
        ..Settings::default()
    };
    let mut calibrator = Calibrator::new(&model, surrogate, &observations, &space)
        .with_settings(core_settings)
        .with_searcher(settings.searcher.clone())
        .with_regularizer(&penalty, settings.penalty.weight)
        .with_store(store);
    for o in observers {
        calibrator = calibrator.with_observer(move |e: &kalibre_core::Event<'_>| o.observe(e));
    }
    let report = calibrator.run()?;
    let best = report.best.params.values();
    let penalty_report = penalty.report(&best);
    drop(calibrator);
    Ok(HallCalibration {
        report,
        model,
        penalty_report,
    })
}
