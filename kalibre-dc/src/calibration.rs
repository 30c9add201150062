//! Kalibre on a data hall: the built-in simulator, the thermal graph surrogate, the
//! paper's search objective (with the temperature-rise prior) and the generic loop,
//! assembled once for the CLI, the demo, the experiments and the tests.

use std::path::Path;

use kalibre_core::calibrate::Report;
use kalibre_core::search::Hybrid;
use kalibre_core::{Observe, Settings};

use crate::calibration_model::{calibrate_with_terms, ModelCalibration};
use crate::effects::{EffectRegistry, SurrogateTerm};
use crate::hall::{AlphaMode, Hall};
use crate::sim::SimConfig;
use crate::snapshots::HallSnapshot;
use crate::surrogate::{LocalRecirculationSettings, PenaltySettings, ThermalGraphSettings};
use crate::{Error, HallModel, Result};

/// The cut of [`HallCalibrationSettings::server_influence`]'s edges: entries under 1 % of
/// a sensor's largest are dropped. On `hall-a` (rise box, 9 runs) it keeps about 60
/// servers per hot-aisle sensor of 2,240, and fits as well as keeping all of them
/// (`examples/fig7_edges.rs`).
pub const SERVER_INFLUENCE_CUT: f64 = 0.01;

/// Everything that shapes a hall calibration.
///
/// | Name | Default | Meaning |
/// |---|---|---|
/// | `core` | [`HallCalibrationSettings::loop_defaults`] | the generic loop's [`Settings`] (seed, iterations, budgets, fit focus, exploration, output correction, trust region); its `regularizer_weight` is taken from `penalty.weight` |
/// | `alpha_mode` | the hall's `calibrate.alpha` | per type, per server or fixed |
/// | `sim` | [`SimConfig::default`] | the built-in simulator (grid, tolerances) |
/// | `surrogate` | [`ThermalGraphSettings::default`] | Adam lr 0.1, decay 0.8, 150 epochs, fixed adjacency |
/// | `penalty` | [`PenaltySettings::default`] | rise range [5, 20] C (the paper: [5, 15]), weight 1 |
/// | `searcher` | [`Hybrid::default`] | DE (population 10, crossover 0.6, 100 generations), then Adam |
/// | `flow_balance_terms` | true | add recirculation and bypass terms to the surrogate (beyond the paper, which assumes neither) |
/// | `local_recirculation` | none | add the local draw-against-supply recirculation term with these settings ([`LocalRecirculationSettings`]; measured: a better fit to random runs, a slightly worse loop on hall-b, see docs/experiments.md) |
/// | `server_influence` | none | build the hot-aisle server-sensor edges from the built-in simulator's own air flow ([`Adjacency::with_server_influence`](crate::surrogate::Adjacency::with_server_influence), at the initial alphas and the first snapshot, cut at this fraction of each row's largest edge; [`SERVER_INFLUENCE_CUT`] is the measured choice) instead of reciprocal distance; built-in model only |
/// | `design_within_prior` | false | the initial design spans the alphas whose rises the prior accepts ([`PenaltySettings::plausible_bounds`]) instead of the whole bounds |
/// | `grid_check` | `[0.75, 0.5]` | cell sizes, relative to `sim.cell_m`, at which the built-in model runs once per snapshot at the best parameters: the alphas' move from the grid alone is their numerical uncertainty (`ParamUncertainty::numerical`), counted when a parameter is called identified; with `core.numerical_weighting` (default) the grids run before the polish too, which weighs each sensor by them; empty: none |
/// | `polish_max_params` | 64 | the loop's polish stage (`core.polish_iterations`, 8 by default) runs only when there are at most this many parameters: each of its Jacobians costs `params + 1` model runs per snapshot (per-server alpha on a real hall would need thousands); above it the report's settings show `polish_iterations` 0 |
/// | `replay_failed` | false | a resume replays the journal's failed runs as failures rather than running them again (for failures that recur at the same point; by default a failure's cause may have passed) |
#[derive(Debug, Clone)]
pub struct HallCalibrationSettings {
    /// The generic loop's settings; `target_score` is a target MAE (C).
    pub core: Settings,
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
    /// Add the mass-balance terms (recirculation, bypass) to the paper's thermal graph.
    pub flow_balance_terms: bool,
    /// Add the local recirculation term (local draw against local supply per sensor)
    /// with these settings.
    pub local_recirculation: Option<LocalRecirculationSettings>,
    /// Server-sensor edges from the simulator's flow, cut at this relative weight.
    pub server_influence: Option<f64>,
    /// The initial design spans the prior's plausible alphas rather than the bounds.
    pub design_within_prior: bool,
    /// Most parameters for which the polish stage runs.
    pub polish_max_params: usize,
    /// Refined grids (cell size relative to `sim.cell_m`, each in (0, 1)) for the
    /// numerical uncertainty; built-in model only.
    pub grid_check: Vec<f64>,
    /// A resume replays the journal's failed runs as failures instead of running them
    /// again ([`kalibre_core::RunStore::open_replaying_failures`]).
    pub replay_failed: bool,
}

impl HallCalibrationSettings {
    /// The loop settings for halls: seed 1, 10 iterations, fits focused on runs near the
    /// measurements (`focus` 1), a repeated proposal moved by 0.015 in the unit box (about
    /// 9% in alpha) rather than ending the loop, and the surrogate corrected to the model
    /// at the best run, with a linear term fitted to the runs near it, and searched within
    /// a trust region of 0.1; when the corrected surrogate promises too little, a geometry
    /// step of 0.03 along the least explored direction instead (all beyond the paper; the
    /// variants are measured in docs/performance.md); then up to 8 Levenberg-Marquardt
    /// steps on the model itself (the built-in simulator is cheap; the surrogate alone
    /// stalls a few tenths of a degree above what the model can reach), each sensor
    /// weighed by how far the grid check moves it (`numerical_weighting`: the grid's own
    /// error at a few sensors would otherwise set the alphas of the types they see).
    /// The best run is judged by its MAE plus the temperature-rise prior there
    /// (`prior_in_best`): a run whose lower MAE needs rises the prior rules out must not
    /// become the trust region's centre (on OpenFOAM data it held a calibration at half
    /// the true alphas; docs/experiments.md, session 25).
    pub fn loop_defaults() -> Settings {
        Settings::recommended()
    }
}

impl Default for HallCalibrationSettings {
    fn default() -> Self {
        HallCalibrationSettings {
            core: Self::loop_defaults(),
            alpha_mode: None,
            sim: SimConfig::default(),
            surrogate: ThermalGraphSettings::default(),
            penalty: PenaltySettings::default(),
            searcher: Hybrid::default(),
            flow_balance_terms: true,
            local_recirculation: None,
            server_influence: None,
            design_within_prior: false,
            polish_max_params: 64,
            grid_check: vec![0.75, 0.5],
            replay_failed: false,
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
    calibrate_hall_with_registry(
        hall,
        snaps,
        settings,
        &EffectRegistry::builtin(),
        journal,
        observers,
    )
}

/// [`calibrate_hall`] with `hall.effects` built by `registry` (downstream effect kinds).
/// Each effect parameter whose effect asks for [`SurrogateTerm::LearnedLinear`] gets an
/// [`EffectLinearTerm`](crate::surrogate::EffectLinearTerm) in the surrogate, so that the search can move it.
pub fn calibrate_hall_with_registry<'o>(
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &HallCalibrationSettings,
    registry: &EffectRegistry,
    journal: Option<&Path>,
    observers: Vec<Box<dyn Observe + 'o>>,
) -> Result<HallCalibration> {
    let mut hall = hall.clone();
    if let Some(mode) = settings.alpha_mode {
        hall.calibrate.alpha = mode;
    }
    let model = HallModel::with_registry(&hall, settings.sim.clone(), registry)?;
    let layout = model.layout().clone();
    let learned: Vec<usize> = model
        .effects()
        .iter()
        .enumerate()
        .filter(|(_, effect)| effect.surrogate_term() == SurrogateTerm::LearnedLinear)
        .flat_map(|(e, _)| layout.effect_range(e))
        .collect();
    // The same hall on finer grids: the alphas' move between grids is what the model's
    // discretisation alone does to them (one solve per snapshot each, at the best run).
    let mut refined = Vec::new();
    for &factor in &settings.grid_check {
        if !(factor > 0.0 && factor < 1.0) {
            return Err(Error::Mismatch(format!(
                "grid_check: {factor} is not a refinement (a cell size factor in (0, 1))"
            )));
        }
        let cell_m = settings.sim.cell_m * factor;
        let config = SimConfig {
            cell_m,
            ..settings.sim.clone()
        };
        // A grid the geometry does not fit (an opening snapped under a rack) is reported
        // as a failed check; the calibration on the model's own grid stands.
        let fine = HallModel::with_registry(&hall, config, registry).map_err(|e| e.to_string());
        refined.push((format!("grid {} m", (cell_m * 1e4).round() / 1e4), fine));
    }
    let variants: Vec<(String, std::result::Result<&HallModel, String>)> = refined
        .iter()
        .map(|(n, m)| (n.clone(), m.as_ref().map_err(Clone::clone)))
        .collect();
    let ModelCalibration {
        report,
        penalty_report,
    } = calibrate_with_terms(
        &hall,
        snaps,
        &model,
        &layout,
        &learned,
        settings,
        journal,
        observers,
        &variants,
        Some(model.simulator()),
    )?;
    Ok(HallCalibration {
        report,
        model,
        penalty_report,
    })
}
