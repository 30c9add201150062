//! The options of `kalibre calibrate`, and their defaults where a flag's absence must be
//! told from its default value (a model of your own refuses a hall's flags when given).

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};

use super::super::likelihood::Likelihood;
use super::super::openfoam_args::OpenFoamArgs;

/// `--epochs`' default (the paper's 150).
const DEFAULT_EPOCHS: usize = 150;
/// `--rise-weight`'s default (the paper's 1).
const DEFAULT_RISE_WEIGHT: f64 = 1.0;
/// `--rise-range`'s default (C).
const DEFAULT_RISE_RANGE: &str = "5,20";
/// `--focus`' default.
const DEFAULT_FOCUS: f64 = 1.0;

/// How alpha is calibrated (overrides `calibrate.alpha` in hall.json).
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum AlphaArg {
    /// One alpha per server type.
    PerType,
    /// One alpha per server (the paper's formulation).
    PerServer,
    /// Alpha fixed at its initial values (only effect parameters are calibrated).
    Fixed,
}

/// Which model the calibration runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// The built-in thermal simulator (seconds per run).
    Builtin,
    /// OpenFOAM (`buoyantBoussinesqSimpleFoam`) on a case generated from hall.json.
    Openfoam,
    /// Any simulator driven through files, described by `--config model.toml`.
    Command,
}

/// Options of `kalibre calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The hall (`hall.json`).
    #[arg(long)]
    pub(super) hall: Option<PathBuf>,
    /// Operating conditions and measurements (`snapshots.csv`).
    #[arg(long)]
    pub(super) snapshots: Option<PathBuf>,
    /// A model of your own, not a hall: what was measured of it (`measurements.csv`:
    /// `scenario,output,value` rows, the scenarios and outputs of --config's model.toml).
    /// With `--model command --config model.toml`; the surrogate is a Gaussian process
    /// (docs/models.md, "A model of your own").
    #[arg(long, conflicts_with_all = ["hall", "snapshots"])]
    pub(super) measurements: Option<PathBuf>,
    /// Output directory: report.json, runs.jsonl (the run journal), report.html, and
    /// runs-hall.json (the hall the journal's runs were made on); with --measurements,
    /// report.json, runs.jsonl and model-parts.json (the digest of each part of the
    /// model's fingerprint), no report.html; either way .kalibre.lock, locked while
    /// calibrate works there. Running again on the same directory resumes from the
    /// journal without repeating a model run.
    #[arg(long)]
    pub(super) out: PathBuf,
    /// Four-step iterations after the initial design (each runs the model once per snapshot).
    #[arg(long, default_value_t = 10)]
    pub(super) iterations: usize,
    /// Seed of every random choice; the same seed gives the same result at any thread count.
    #[arg(long, default_value_t = 1)]
    pub(super) seed: u64,
    /// Grid cell size (m) of the built-in simulator, or of the OpenFOAM mesh with
    /// `--model openfoam` (the hall's edges must lie on it); default 0.2.
    #[arg(long = "grid-m")]
    pub(super) grid_m: Option<f64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub(super) threads: usize,
    /// Built-in model: finer grids (cell size relative to --grid-m, each in (0, 1)) at
    /// which the model runs once per snapshot at the best parameters. How far the grid
    /// alone moves each parameter is its numerical uncertainty, reported beside its
    /// spread and counted when a parameter is called identified. Default: 0.75,0.5.
    #[arg(long = "grid-check", value_delimiter = ',')]
    pub(super) grid_check: Option<Vec<f64>>,
    /// Skip the finer-grid runs of --grid-check.
    #[arg(long = "no-grid-check", conflicts_with = "grid_check")]
    pub(super) no_grid_check: bool,
    /// Do not weigh the sensors by the grid check in the polish: by default the grids run
    /// before the polish too, and a sensor the grid moves by u counts s^2 / (s^2 + u^2)
    /// (s: the noise the grid leaves unexplained), so the grid's error at a few sensors
    /// does not set the alphas.
    #[arg(long = "no-grid-weighting", conflicts_with = "no_grid_check")]
    pub(super) no_grid_weighting: bool,
    /// How alpha is calibrated; default: the hall's `calibrate.alpha`.
    #[arg(long, value_enum)]
    pub(super) alpha: Option<AlphaArg>,
    /// Stop once the model's MAE over all sensors and snapshots is at most this (C; with
    /// --measurements, in the outputs' units, or in sd units when the measurements have
    /// an `sd` column).
    #[arg(long = "target-mae")]
    pub(super) target_mae: Option<f64>,
    /// Stop before exceeding this many model runs (initial design included).
    #[arg(long = "max-runs")]
    pub(super) max_runs: Option<usize>,
    /// Stop after this much wall time (s): checked before each step (the grid check's
    /// runs are skipped once it has passed, and the report says so), and inside each
    /// surrogate fit and search, which then end with their best so far and no model run
    /// at the proposal (a model run under way finishes; see --of-timeout-s for OpenFOAM).
    #[arg(long = "max-wall-s")]
    pub(super) max_wall_s: Option<f64>,
    /// Resume without running the journal's failed runs again: each is replayed as the
    /// failure it was. For failures that recur at the same point (a solver that diverges
    /// at a corner of the box); by default a resume runs them again, since a failure's
    /// cause (a timeout, a busy machine, a setting since fixed) may have passed.
    #[arg(long = "replay-failed")]
    pub(super) replay_failed: bool,
    /// Model runs at once (default: one per snapshot, up to the threads).
    #[arg(long = "parallel-runs")]
    pub(super) parallel_runs: Option<usize>,
    /// Adam epochs per surrogate fit (the paper: 150). They train the graph's edges with
    /// --trainable-adjacency; with the default fixed adjacency the fit's least-squares
    /// start already minimises its loss, and Adam keeps it. Default 150.
    #[arg(long)]
    pub(super) epochs: Option<usize>,
    /// Train the surrogate's sensor-to-CRAC and sensor-to-server edges too, by Adam
    /// (--epochs), instead of fixing them from the hall's geometry (docs/experiments.md,
    /// Fig. 7 compares the two).
    #[arg(long = "trainable-adjacency")]
    pub(super) trainable_adjacency: bool,
    /// Differential evolution: population (the paper: 10).
    #[arg(long, default_value_t = 10)]
    pub(super) population: usize,
    /// Differential evolution: crossover probability (the paper: 0.6).
    #[arg(long, default_value_t = 0.6)]
    pub(super) crossover: f64,
    /// Differential evolution: generations (the paper: 100).
    #[arg(long = "de-iterations", default_value_t = 100)]
    pub(super) de_iterations: usize,
    /// Adam steps after differential evolution.
    #[arg(long = "adam-steps", default_value_t = 100)]
    pub(super) adam_steps: usize,
    /// Weight of the temperature-rise prior in the search and in judging which run is the
    /// best (the paper: 1; 0 turns it off). Default 1.
    #[arg(long = "rise-weight")]
    pub(super) rise_weight: Option<f64>,
    /// Plausible server temperature rise range, `LOW,HIGH` in C (the paper: 5,15; real
    /// servers run up to 15-20 C, and a prior below the truth pulls alpha away from it).
    /// Default 5,20.
    #[arg(long = "rise-range")]
    pub(super) rise_range: Option<String>,
    /// Weight the surrogate's fit towards runs near the measurements: a run with `m` times
    /// the best run's MAE weighs exp(-((m-1)/FOCUS)^2/2), FOCUS at least 0.01; 0 turns it
    /// off (every run weighs 1). Default 1. Not with --measurements: its Gaussian process
    /// weighs every run alike.
    #[arg(long)]
    pub(super) focus: Option<f64>,
    /// When the search proposes a point already run, move it by this much noise (unit box,
    /// at most 1) and go on; 0 stops the calibration there instead (converged).
    #[arg(long = "explore", default_value_t = 0.015)]
    pub(super) explore: f64,
    /// Search the surrogate corrected to match the model at the best run so far
    /// (`true` or `false`).
    #[arg(long = "output-correction", default_value_t = true, action = clap::ArgAction::Set)]
    pub(super) output_correction: bool,
    /// With the output correction, also correct the surrogate's slopes: a linear term
    /// fitted to the model-minus-surrogate discrepancy at the other runs (`true` or `false`;
    /// default: true, and refused as `true` with `--output-correction false`).
    #[arg(long = "linear-correction", action = clap::ArgAction::Set)]
    pub(super) linear_correction: Option<bool>,
    /// Search only within this distance (unit box) of the best point, growing after a
    /// step that improved the model and shrinking after one that did not (0.001 to 1);
    /// 0: whole box.
    #[arg(long = "trust-region", default_value_t = 0.1)]
    pub(super) trust_region: f64,
    /// After the iterations, up to this many Levenberg-Marquardt steps on the model itself
    /// (finite-difference Jacobians: parameters + 1 runs per snapshot each); they take the
    /// fit to what the model can reach when the surrogate stalls. Default: 8 with the
    /// built-in model (cheap), 0 with `openfoam` and `command` (each run costs a solve).
    /// Skipped when more than 64 parameters are calibrated.
    #[arg(long)]
    pub(super) polish: Option<usize>,
    /// How residuals are weighed: `gaussian` (the paper's mean squared error) or
    /// `student-t` (robust: a few sensors the model cannot match, through its own physics
    /// or a faulty sensor, count less, so they do not set the parameters). The iterations'
    /// search keeps least squares to find the basin; the polish steps (--polish) and the
    /// reported uncertainty weigh each residual by the t likelihood, its scale fitted to
    /// the residuals. `kalibre diagnose` weighs residuals this way by default.
    #[arg(long, value_enum, default_value_t = Likelihood::Gaussian)]
    pub(super) likelihood: Likelihood,
    /// Degrees of freedom of the Student-t likelihood (smaller: more robust; at least 1;
    /// default 4).
    #[arg(long)]
    pub(super) nu: Option<f64>,
    /// Leave out the surrogate's mass-balance terms (recirculation and bypass), as in the paper.
    #[arg(long = "paper-surrogate")]
    pub(super) paper_surrogate: bool,
    /// Add the surrogate's local recirculation term to the cold-aisle sensors: the draw of
    /// the hall's servers against its supply openings, each weighed by its reciprocal
    /// distance to the sensor.
    #[arg(long = "local-recirculation")]
    pub(super) local_recirculation: bool,
    /// Build the surrogate's hot-aisle edges from the built-in simulator's own air flow
    /// (each sensor's sensitivity to each server's exhaust, one adjoint solve per sensor
    /// at the initial alphas) instead of reciprocal distance. Built-in model only. The
    /// graph fits random runs better with it, but the loop did worse on the synthetic
    /// halls (docs/experiments.md); for halls whose air does not go where distance says.
    #[arg(long = "influence-edges")]
    pub(super) influence_edges: bool,
    /// The model: `builtin` (the built-in simulator), `openfoam` (a case generated from
    /// hall.json, meshed once into OUT/openfoam and solved per run) or `command` (an
    /// external program described by --config). The surrogate is the same for all three.
    #[arg(long, value_enum, default_value_t = ModelArg::Builtin)]
    pub(super) model: ModelArg,
    #[command(flatten)]
    pub(super) openfoam: OpenFoamArgs,
    /// `--model command`: the model description (`model.toml`, see docs/models.md). With
    /// `--measurements`, a model of your own; with `--hall`, its params must be the
    /// hall's calibrated parameters in order and its outputs the hall's sensors in order.
    #[arg(long)]
    pub(super) config: Option<PathBuf>,
    /// No progress bars (they are off anyway when stderr is not a terminal).
    #[arg(long)]
    pub(super) quiet: bool,
}

impl CalibrateArgs {
    /// `--epochs`, else its default.
    pub(super) fn epochs(&self) -> usize {
        self.epochs.unwrap_or(DEFAULT_EPOCHS)
    }

    /// `--rise-weight`, else its default.
    pub(super) fn rise_weight(&self) -> f64 {
        self.rise_weight.unwrap_or(DEFAULT_RISE_WEIGHT)
    }

    /// `--rise-range`, else its default.
    pub(super) fn rise_range(&self) -> &str {
        self.rise_range.as_deref().unwrap_or(DEFAULT_RISE_RANGE)
    }

    /// `--focus`, else its default.
    pub(super) fn focus(&self) -> f64 {
        self.focus.unwrap_or(DEFAULT_FOCUS)
    }

    /// `--hall`, which clap requires unless `--measurements` is given (the generic path,
    /// which never asks for it).
    pub(super) fn hall_path(&self) -> &Path {
        self.hall
            .as_deref()
            .expect("run checks --hall without --measurements")
    }

    /// `--snapshots`, required as `--hall` is.
    pub(super) fn snapshots_path(&self) -> &Path {
        self.snapshots
            .as_deref()
            .expect("run checks --snapshots without --measurements")
    }
}
