//! `kalibre calibrate`: the four-step loop on a hall, with the built-in simulator.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use kalibre_core::calibrate::Report;
use kalibre_core::search::{Adam, DifferentialEvolution, Hybrid};
use kalibre_core::{Event, Observe};
use kalibre_dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::snapshots;
use kalibre_dc::surrogate::PenaltySettings;

use super::simulate::sim_config;
use super::{io_err, with_threads, CliError, CliResult};

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

/// Options of `kalibre calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The hall (`hall.json`).
    #[arg(long)]
    hall: PathBuf,
    /// Operating conditions and measurements (`snapshots.csv`).
    #[arg(long)]
    snapshots: PathBuf,
    /// Output directory: report.json, runs.jsonl (the run journal), report.html. Running
    /// again on the same directory resumes from the journal without repeating a model run.
    #[arg(long)]
    out: PathBuf,
    /// Four-step iterations after the initial design (each runs the model once per snapshot).
    #[arg(long, default_value_t = 10)]
    iterations: usize,
    /// Seed of every random choice; the same seed gives the same result at any thread count.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Grid cell size of the built-in simulator (m); default: the simulator's.
    #[arg(long = "grid-m")]
    grid_m: Option<f64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// How alpha is calibrated; default: the hall's `calibrate.alpha`.
    #[arg(long, value_enum)]
    alpha: Option<AlphaArg>,
    /// Stop once the model's MAE over all sensors and snapshots is at most this (C).
    #[arg(long = "target-mae")]
    target_mae: Option<f64>,
    /// Stop before exceeding this many model runs (initial design included).
    #[arg(long = "max-runs")]
    max_runs: Option<usize>,
    /// Stop after this much wall time (s).
    #[arg(long = "max-wall-s")]
    max_wall_s: Option<f64>,
    /// Model runs at once (default: one per snapshot, up to the threads).
    #[arg(long = "parallel-runs")]
    parallel_runs: Option<usize>,
    /// Surrogate training epochs per fit (the paper: 150).
    #[arg(long, default_value_t = 150)]
    epochs: usize,
    /// Differential evolution: population (the paper: 10).
    #[arg(long, default_value_t = 10)]
    population: usize,
    /// Differential evolution: crossover probability (the paper: 0.6).
    #[arg(long, default_value_t = 0.6)]
    crossover: f64,
    /// Differential evolution: generations (the paper: 100).
    #[arg(long = "de-iterations", default_value_t = 100)]
    de_iterations: usize,
    /// Adam steps after differential evolution.
    #[arg(long = "adam-steps", default_value_t = 100)]
    adam_steps: usize,
    /// Weight of the temperature-rise prior in the search (the paper: 1; 0 turns it off).
    #[arg(long = "rise-weight", default_value_t = 1.0)]
    rise_weight: f64,
    /// Plausible server temperature rise range, `LOW,HIGH` in C (the paper: 5,15).
    #[arg(long = "rise-range", default_value = "5,15")]
    rise_range: String,
    /// Weight the surrogate's fit towards runs near the measurements: a run with `m` times
    /// the best run's MAE weighs exp(-((m-1)/FOCUS)^2/2); 0 turns it off (every run weighs 1).
    #[arg(long, default_value_t = 1.0)]
    focus: f64,
    /// When the search proposes a point already run, move it by this much noise (unit box)
    /// and go on; 0 stops the calibration there instead (converged).
    #[arg(long = "explore", default_value_t = 0.015)]
    explore: f64,
    /// Search the surrogate corrected to match the model at the best run so far
    /// (`true` or `false`).
    #[arg(long = "output-correction", default_value_t = true, action = clap::ArgAction::Set)]
    output_correction: bool,
    /// Search only within this distance (unit box) of the best point, growing after a
    /// step that improved the model and shrinking after one that did not; 0: whole box.
    #[arg(long = "trust-region", default_value_t = 0.1)]
    trust_region: f64,
    /// Leave out the surrogate's mass-balance terms (recirculation and bypass), as in the paper.
    #[arg(long = "paper-surrogate")]
    paper_surrogate: bool,
    /// Add the surrogate's local recirculation term (draw of the servers near each sensor
    /// against the supply openings near it).
    #[arg(long = "local-recirculation")]
    local_recirculation: bool,
    /// No progress bars (they are off anyway when stderr is not a terminal).
    #[arg(long)]
    quiet: bool,
}

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
        other => other,
    }
}

/// Builds the hall calibration settings from the arguments.
fn settings(args: &CalibrateArgs) -> CliResult<HallCalibrationSettings> {
    let (lo, hi) = args
        .rise_range
        .split_once(',')
        .and_then(|(a, b)| Some((a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?)))
        .ok_or_else(|| {
            CliError::Input(format!(
                "--rise-range: expected LOW,HIGH in C (e.g. 5,15), got `{}`",
                args.rise_range
            ))
        })?;
    let penalty = PenaltySettings::default()
        .with_range_c(lo, hi)
        .with_weight(args.rise_weight)
        .check()
        .map_err(|e| CliError::Input(format!("--rise-range/--rise-weight: {e}")))?;
    let de = DifferentialEvolution::builder()
        .with_population(args.population)
        .with_crossover(args.crossover)
        .with_iterations(args.de_iterations)
        .with_give_up_after(Some(kalibre_core::search::HYBRID_DE_GIVE_UP_AFTER))
        .build()
        .map_err(|e| CliError::Input(format!("--population/--crossover/--de-iterations: {e}")))?;
    let adam = Adam::builder()
        .with_steps(args.adam_steps)
        .build()
        .map_err(|e| CliError::Input(format!("--adam-steps: {e}")))?;
    let core = kalibre_core::Settings {
        seed: args.seed,
        max_iterations: args.iterations,
        target_score: args.target_mae,
        max_model_runs: args.max_runs,
        max_wall_s: args.max_wall_s,
        max_parallel_runs: args.parallel_runs,
        // 0 turns an option off; anything else is checked below with the loop's own rules.
        focus: (args.focus != 0.0).then_some(args.focus),
        explore_on_repeat: (args.explore != 0.0).then_some(args.explore),
        trust_region: (args.trust_region != 0.0).then_some(args.trust_region),
        output_correction: args.output_correction,
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
        local_recirculation_term: args.local_recirculation,
        ..HallCalibrationSettings::default()
    };
    s.surrogate = s.surrogate.with_epochs(args.epochs);
    Ok(s)
}

/// Progress bars driven by calibration events; hidden when stderr is not a terminal.
struct Progress {
    runs: ProgressBar,
    best_mae: Mutex<Option<f64>>,
}

impl Progress {
    fn new(total_runs: u64, quiet: bool) -> Self {
        let target = if quiet || !std::io::stderr().is_terminal() {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        };
        let runs = ProgressBar::with_draw_target(Some(total_runs), target);
        runs.set_style(
            ProgressStyle::with_template(
                "{spinner} model runs {pos}/{len} [{bar:30}] {elapsed_precise} {msg}",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        Progress {
            runs,
            best_mae: Mutex::new(None),
        }
    }
}

impl Observe for Progress {
    fn observe(&self, event: &Event<'_>) {
        match event {
            Event::RunFinished { .. } => self.runs.inc(1),
            Event::IterationDone { record } => {
                let mut best = self.best_mae.lock().unwrap_or_else(|p| p.into_inner());
                if let Some(m) = record.mae_c.filter(|m| m.is_finite()) {
                    *best = Some(best.map_or(m, |b: f64| b.min(m)));
                }
                self.runs.set_message(format!(
                    "iteration {} | best MAE {}",
                    record.iteration,
                    best.map_or("-".into(), |b| format!("{b:.3} C"))
                ));
            }
            Event::Stopped { .. } => self.runs.finish_and_clear(),
            _ => {}
        }
    }
}

/// Runs `kalibre calibrate`.
pub fn run(args: CalibrateArgs) -> CliResult {
    let settings = settings(&args)?;
    let hall = Hall::load(&args.hall)?;
    let snaps = snapshots::load_snapshots(&hall, &args.snapshots)?;
    std::fs::create_dir_all(&args.out).map_err(|e| io_err(&args.out, e))?;
    let journal = args.out.join("runs.jsonl");
    let total_runs = ((4 + args.iterations) * snaps.len()) as u64;
    let progress = Progress::new(total_runs, args.quiet);
    let started = Instant::now();
    let outcome = with_threads(args.threads, || {
        calibrate_hall(
            &hall,
            &snaps,
            &settings,
            Some(&journal),
            vec![Box::new(progress)],
        )
    })??;
    let wall_s = started.elapsed().as_secs_f64();
    let report_path = args.out.join("report.json");
    let json = serde_json::to_string_pretty(&outcome.report)
        .map_err(|e| CliError::Run(format!("report.json: {e}")))?;
    std::fs::write(&report_path, json).map_err(|e| io_err(&report_path, e))?;
    let html_path = args.out.join("report.html");
    let html = kalibre_dc::report::calibration_html(
        &hall,
        &snaps,
        &outcome.report,
        &outcome.penalty_report,
    );
    std::fs::write(&html_path, html).map_err(|e| io_err(&html_path, e))?;
    print_summary(&outcome.report, wall_s, &outcome.penalty_report);
    println!(
        "wrote {}, {}, {}",
        report_path.display(),
        journal.display(),
        html_path.display()
    );
    Ok(())
}

fn fmt_c(v: Option<f64>) -> String {
    v.filter(|v| v.is_finite())
        .map_or("-".into(), |v| format!("{v:.3} C"))
}

/// The end-of-run summary table.
fn print_summary(report: &Report, wall_s: f64, penalty: &kalibre_dc::surrogate::PenaltyReport) {
    println!();
    println!("calibration summary");
    println!("  {:<28} {}", "initial MAE", fmt_c(report.initial.mae_c));
    println!(
        "  {:<28} {} (iteration {})",
        "best MAE",
        fmt_c(Some(report.best.mae_c)),
        report.best.iteration
    );
    println!("  {:<28} {}", "best RMSE", fmt_c(Some(report.best.rmse_c)));
    println!(
        "  {:<28} {}",
        "best max abs error",
        fmt_c(Some(report.best.max_abs_c))
    );
    if let Some(rec) = report
        .history
        .iter()
        .find(|h| h.iteration == report.best.iteration)
    {
        for (group, e) in &rec.per_group {
            println!(
                "  {:<28} {}",
                format!("best MAE, {group} aisle"),
                fmt_c(Some(e.mae_c))
            );
        }
    }
    println!(
        "  {:<28} {} ({} new, {} from the journal, {} failed)",
        "model runs", report.runs.total, report.runs.new, report.runs.cached, report.runs.failed
    );
    println!("  {:<28} {:?}", "stopped", report.stop_reason);
    println!("  {:<28} {wall_s:.1} s", "wall time");
    if !penalty.violations.is_empty() {
        println!(
            "  note: the temperature-rise prior binds at the best parameters for {} server(s): \
             a prior-data conflict; check --rise-range",
            penalty.violations.len()
        );
    }
    println!("  best parameters:");
    for (name, value) in &report.best.params.0 {
        println!("    {name:<30} {value:.5}");
    }
}
