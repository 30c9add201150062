//! `kalibre calibrate`'s settings from its flags, each checked and any error named by
//! its flag.

use kalibre_core::search::{Adam, DifferentialEvolution, Hybrid};
use kalibre_dc::calibration::HallCalibrationSettings;
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::surrogate::PenaltySettings;

use super::super::simulate::sim_config;
use super::super::{CliError, CliResult};
use super::{AlphaArg, CalibrateArgs, ModelArg};

/// The command-line flag of a loop setting, for error messages.
fn flag_of(setting: &str) -> &str {
    match setting {
        "max_iterations" => "iterations",
        "target_score" => "target-mae",
        "max_model_runs" => "max-runs",
        "max_wall_s" => "max-wall-s",
        "max_parallel_runs" => "parallel-runs",
        "explore_on_repeat" => "explore",
        "trust_region" => "trust-region",
        "robust_nu" => "nu",
        other => other,
    }
}

/// A loop setting the calibration itself refused (`max_model_runs` below the initial
/// design's runs, known only once the design is): named by its flag.
pub(super) fn flag_error(e: kalibre_dc::Error) -> CliError {
    match e {
        kalibre_dc::Error::Core(kalibre_core::Error::InvalidSetting { name, reason }) => {
            CliError::Input(format!("--{}: {reason}", flag_of(&name)))
        }
        other => other.into(),
    }
}

/// Builds the hall calibration settings from the arguments.
pub(super) fn settings(args: &CalibrateArgs) -> CliResult<HallCalibrationSettings> {
    // 0 is a choice here (stop when a point repeats), so the loop's own (0, 1] does not
    // say the flag's range.
    if !(args.explore.is_finite() && (0.0..=1.0).contains(&args.explore)) {
        return Err(CliError::Input(format!(
            "--explore: must be in [0, 1] (0 stops at a repeated point), got {}",
            args.explore
        )));
    }
    let (lo, hi) = args
        .rise_range()
        .split_once(',')
        .and_then(|(a, b)| Some((a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?)))
        .ok_or_else(|| {
            CliError::Input(format!(
                "--rise-range: expected LOW,HIGH in C (e.g. 5,15), got `{}`",
                args.rise_range()
            ))
        })?;
    let penalty = PenaltySettings::default()
        .with_range_c(lo, hi)
        .with_weight(args.rise_weight())
        .check()
        .map_err(|e| CliError::Input(format!("--rise-range/--rise-weight: {e}")))?;
    let de = DifferentialEvolution::builder()
        .with_population(args.population)
        .with_crossover(args.crossover)
        .with_iterations(args.de_iterations)
        .with_give_up_after(Some(kalibre_core::search::HYBRID_DE_GIVE_UP_AFTER))
        .build()
        .map_err(|e| {
            CliError::Input(match &e {
                // The setting's flag, not the library's field name.
                kalibre_core::Error::InvalidSetting { name, reason } => {
                    let flag = match name.as_str() {
                        "population" => "--population",
                        "crossover" => "--crossover",
                        "iterations" | "max_iterations" => "--de-iterations",
                        _ => "--population/--crossover/--de-iterations",
                    };
                    format!("{flag}: {reason}")
                }
                e => format!("--population/--crossover/--de-iterations: {e}"),
            })
        })?;
    let adam = Adam::builder()
        .with_steps(args.adam_steps)
        .build()
        .map_err(|e| CliError::Input(format!("--adam-steps: {}", setting_reason(&e))))?;
    if args.linear_correction == Some(true) && !args.output_correction {
        return Err(CliError::Input(
            "--linear-correction true: the linear term corrects the output correction, \
             which --output-correction false turns off"
                .into(),
        ));
    }
    let linear_correction = args.linear_correction.unwrap_or(true) && args.output_correction;
    let core = kalibre_core::Settings {
        seed: args.seed,
        max_iterations: args.iterations,
        target_score: args.target_mae,
        max_model_runs: args.max_runs,
        max_wall_s: args.max_wall_s,
        max_parallel_runs: args.parallel_runs,
        // 0 turns an option off; anything else is checked below with the loop's own rules.
        focus: (args.focus() != 0.0).then_some(args.focus()),
        explore_on_repeat: (args.explore != 0.0).then_some(args.explore),
        trust_region: (args.trust_region != 0.0).then_some(args.trust_region),
        output_correction: args.output_correction,
        linear_correction,
        stall_step: HallCalibrationSettings::loop_defaults()
            .stall_step
            .filter(|_| linear_correction),
        polish_iterations: args.polish.unwrap_or(match args.model {
            ModelArg::Builtin => HallCalibrationSettings::loop_defaults().polish_iterations,
            ModelArg::Openfoam | ModelArg::Command => 0,
        }),
        robust_nu: args.likelihood.robust_nu(args.nu)?,
        numerical_weighting: !args.no_grid_weighting,
        ..HallCalibrationSettings::loop_defaults()
    };
    core.check().map_err(|e| match e {
        kalibre_core::Error::InvalidSetting { name, reason } => {
            CliError::Input(format!("--{}: {reason}", flag_of(&name)))
        }
        other => CliError::Input(other.to_string()),
    })?;
    let mut s = HallCalibrationSettings {
        core,
        alpha_mode: args.alpha.map(|a| match a {
            AlphaArg::PerType => AlphaMode::PerType,
            AlphaArg::PerServer => AlphaMode::PerServer,
            AlphaArg::Fixed => AlphaMode::Fixed,
        }),
        sim: sim_config(args.grid_m)?,
        penalty,
        searcher: Hybrid::new(de, adam),
        flow_balance_terms: !args.paper_surrogate,
        local_recirculation: args
            .local_recirculation
            .then(kalibre_dc::surrogate::LocalRecirculationSettings::default),
        server_influence: args
            .influence_edges
            .then_some(kalibre_dc::calibration::SERVER_INFLUENCE_CUT),
        replay_failed: args.replay_failed,
        ..HallCalibrationSettings::default()
    };
    if !(1..=MAX_EPOCHS).contains(&args.epochs()) {
        return Err(CliError::Input(format!(
            "--epochs: must be in 1..={MAX_EPOCHS}, got {}",
            args.epochs()
        )));
    }
    s.surrogate =
        (s.surrogate.with_epochs(args.epochs())).with_trainable_adjacency(args.trainable_adjacency);
    let grid_check = args
        .grid_check
        .clone()
        .unwrap_or_else(|| std::mem::take(&mut s.grid_check));
    check_grid_factors(&grid_check)?;
    s.grid_check = if args.no_grid_check {
        Vec::new()
    } else {
        grid_check
    };
    Ok(s)
}

/// The most surrogate training epochs per fit `--epochs` takes (the paper: 150): a bound
/// on one fit's time without `--max-wall-s`.
const MAX_EPOCHS: usize = 100_000;

/// Every `--grid-check` factor a finer grid: a cell size factor in (0, 1).
pub(in crate::cli) fn check_grid_factors(factors: &[f64]) -> CliResult {
    match factors
        .iter()
        .find(|f| !(f.is_finite() && **f > 0.0 && **f < 1.0))
    {
        Some(f) => Err(CliError::Input(format!(
            "--grid-check: {} is not a finer grid (give cell size factors in (0, 1), e.g. 0.75,0.5)",
            kalibre_dc::snapshots::number(*f)
        ))),
        // The same grid twice would solve it twice and report it twice.
        None => match (1..factors.len()).find(|&i| factors[..i].contains(&factors[i])) {
            Some(i) => Err(CliError::Input(format!(
                "--grid-check: {} is given twice; give each finer grid once",
                kalibre_dc::snapshots::number(factors[i])
            ))),
            None => Ok(()),
        },
    }
}

/// Refuses a `--grid-check` factor whose grid is the model's own in this room (a check
/// that would report no numerical uncertainty at all) or too fine to build, before the
/// calibration rather than in its report.
pub(in crate::cli) fn check_finer_grids(hall: &Hall, cell_m: f64, factors: &[f64]) -> CliResult {
    use kalibre_dc::sim::{cells_beyond_cap, Grid, MAX_CELLS};
    let size = hall.room.size_m;
    for &f in factors {
        let fine_m = cell_m * f;
        let why = if let Some(cells) = cells_beyond_cap(size, fine_m) {
            format!("{cells:.3e} cells, above the built-in simulator's {MAX_CELLS}")
        } else if Grid::new(size, fine_m).n == Grid::new(size, cell_m).n {
            "the model's own cells in this room, so it would check nothing".into()
        } else {
            continue;
        };
        return Err(CliError::Input(format!(
            "--grid-check: {} gives cells of {} m: {why}",
            kalibre_dc::snapshots::number(f),
            if fine_m < 1e-3 {
                format!("{fine_m:.1e}")
            } else {
                format!("{:.4}", fine_m)
            }
        )));
    }
    Ok(())
}

/// What an algorithm's setting error says, without the library's field name (the CLI
/// names its flag instead).
fn setting_reason(e: &kalibre_core::Error) -> String {
    match e {
        kalibre_core::Error::InvalidSetting { reason, .. } => reason.clone(),
        e => e.to_string(),
    }
}
