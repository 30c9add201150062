//! Shared code of the paper's experiments (`table4`, `fig7`, `fig8`): the synthetic
//! halls, the four-step loop with any surrogate and searcher, statistics over seeds, and
//! writing results. The example binaries and `tests/experiments.rs` include this module
//! with `#[path]`, so the test suite runs the same code as the binaries (in quick mode).

#![allow(dead_code)] // Each binary uses part of the shared code.

pub mod chart;
pub mod fig7;
pub mod fig8;
pub mod table4;

use std::path::{Path, PathBuf};

use kalibre::core::search::ProjectedGradient;
use kalibre::core::{Calibrator, Event, Observations, Report, RunStore, Searcher, Surrogate};
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::calibration_model;
use kalibre::dc::hall::{AlphaMode, Hall};
use kalibre::dc::sim::{SensorInfluence, SimConfig};
use kalibre::dc::snapshots::{self, HallSnapshot, OperatingState};
use kalibre::dc::surrogate::{PenaltySettings, TemperatureRisePenalty, ThermalGraph};
use kalibre::dc::synth::{self, Preset, SynthOptions};
use kalibre::dc::HallModel;
use serde::{Deserialize, Serialize};

/// Any error of an experiment.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;
/// Result of an experiment step.
pub type Result<T> = std::result::Result<T, BoxError>;

/// The measurements of every experiment: synth seed 1, 3 snapshots, noise 0.2 C, no
/// hidden effect (issue 5).
pub const SYNTH_SEED: u64 = 1;
/// Snapshots per synthetic hall.
pub const SNAPSHOTS: usize = 3;
/// Sensor noise of the synthetic measurements (C).
pub const NOISE_C: f64 = 0.2;

/// A synthetic hall, its measurements and the model calibrated against them.
pub struct Setup {
    /// Preset name.
    pub preset: Preset,
    /// The hall (initial alpha per the preset's policy).
    pub hall: Hall,
    /// Snapshots with noisy measurements.
    pub snaps: Vec<HallSnapshot>,
    /// The same as core observations.
    pub obs: Observations<OperatingState>,
    /// The built-in simulator on its default grid.
    pub model: HallModel,
    /// MAE of the model at the true alphas (C), when the reference runs were made.
    pub model_at_truth_mae_c: Option<f64>,
    /// MAE of the noise alone (C), when the reference runs were made.
    pub noise_only_mae_c: Option<f64>,
    /// Wall time of the synthesis, seconds.
    pub synth_s: f64,
    /// The true alpha per server type (cfm/W), as `truth.json` has it.
    pub true_alpha_type: std::collections::BTreeMap<String, f64>,
    /// The sensors' influence from the model's flow at the initial alphas and the first
    /// snapshot, once computed (its adjoint solves take seconds; every surrogate of a
    /// setup shares it).
    pub influence: std::sync::OnceLock<SensorInfluence>,
}

impl Setup {
    /// Per sensor, whether it is in a hot aisle.
    pub fn hot_sensors(&self) -> Vec<bool> {
        self.hall
            .sensors
            .iter()
            .map(|x| x.aisle == kalibre::dc::hall::Aisle::Hot)
            .collect()
    }
}

/// Synthesises `preset` (seed 1, 3 snapshots, noise 0.2 C) and builds its model.
/// `reference` also runs the model at the truth (a few extra runs) for context.
pub fn setup(preset: Preset, reference: bool) -> Result<Setup> {
    setup_with_alpha(preset, reference, None)
}

/// [`setup`], with the hall's alpha calibrated per `alpha` instead of the preset's mode.
pub fn setup_with_alpha(
    preset: Preset,
    reference: bool,
    alpha: Option<AlphaMode>,
) -> Result<Setup> {
    let t = std::time::Instant::now();
    let opts = SynthOptions::new(preset, SYNTH_SEED)
        .with_snapshots(SNAPSHOTS)
        .with_noise_c(NOISE_C)
        .with_reference_runs(reference);
    let mut s = synth::generate(&opts)?;
    if let Some(mode) = alpha {
        s.hall.calibrate.alpha = mode;
    }
    let synth_s = t.elapsed().as_secs_f64();
    let obs = snapshots::to_observations(&s.hall, &s.snapshots)?;
    let model = HallModel::new(&s.hall, SimConfig::default())?;
    let reference = s.truth.reference.as_ref();
    Ok(Setup {
        preset,
        model_at_truth_mae_c: reference.map(|r| r.model_at_truth_mae_c),
        noise_only_mae_c: reference.map(|r| r.noise_only_mae_c),
        hall: s.hall,
        snaps: s.snapshots,
        obs,
        model,
        synth_s,
        true_alpha_type: s.truth.alpha_type_cfm_per_w,
        influence: std::sync::OnceLock::new(),
    })
}

/// The paper's Algorithm 1 in place of kalibre's loop: the whole box, the surrogate as
/// fitted, every run weighted alike (a repeated proposal still moves on rather than
/// stopping), the best run by its error alone, the paper's rise prior, and DE then Adam
/// without kalibre's local phase.
pub fn use_paper_loop(st: &mut HallCalibrationSettings) -> Result<()> {
    st.core.trust_region = None;
    st.core.output_correction = false;
    st.core.linear_correction = false;
    st.core.stall_step = None;
    st.core.focus = None;
    // Algorithm 1 keeps the run with the lowest error, whatever the prior says there.
    st.core.prior_in_best = false;
    st.penalty = PenaltySettings::paper();
    st.searcher = st
        .searcher
        .clone()
        .with_local(ProjectedGradient::with_steps(0)?);
    Ok(())
}

/// Runs the four-step loop on `setup` with `surrogate` and `searcher`, assembled exactly
/// as [`kalibre::dc::calibration::calibrate_hall`] assembles it (the temperature-rise
/// prior as regulariser, the loop settings of `settings.core` with the penalty's
/// weight), so a baseline surrogate or searcher runs in the same loop as Kalibre.
/// Without `settings.grid_check` (the finer grids): the experiments stop before the
/// polish, where those runs would weigh the sensors, and report no uncertainty.
pub fn run_loop<'o, Su>(
    setup: &Setup,
    surrogate: Su,
    searcher: impl Searcher + 'o,
    settings: &HallCalibrationSettings,
    observer: Option<&'o (dyn Fn(&Event<'_>) + Sync)>,
) -> Result<Report>
where
    Su: Surrogate<Scenario = OperatingState> + Sync,
{
    let layout = setup.model.layout();
    let space = layout.space().clone();
    let scenarios: Vec<_> = setup.snaps.iter().map(|s| s.state.clone()).collect();
    let penalty = TemperatureRisePenalty::new(&setup.hall, layout, &scenarios, settings.penalty)?;
    let core = kalibre::core::Settings {
        regularizer_weight: settings.penalty.weight,
        // As `calibrate_hall`: the model-in-the-loop polish only for few parameters.
        polish_iterations: if space.dim() <= settings.polish_max_params {
            settings.core.polish_iterations
        } else {
            0
        },
        ..settings.core.clone()
    };
    let mut cal = Calibrator::new(&setup.model, surrogate, &setup.obs, &space)
        .with_settings(core)
        .with_searcher(searcher)
        .with_regularizer(&penalty, settings.penalty.weight)
        .with_store(RunStore::in_memory(kalibre::core::Model::fingerprint(
            &setup.model,
        )));
    if settings.design_within_prior {
        let (lower, upper) = settings.penalty.plausible_bounds(layout);
        cal = cal.with_design_bounds(lower, upper);
    }
    if let Some(o) = observer {
        cal = cal.with_observer(move |e: &Event<'_>| o(e));
    }
    Ok(cal.run()?)
}

/// Kalibre's thermal graph as `calibrate_hall` builds it: the paper's cooling and heating
/// blocks plus the recirculation and bypass terms (and the local recirculation term when
/// the settings ask for it).
pub fn kalibre_surrogate(
    setup: &Setup,
    settings: &HallCalibrationSettings,
) -> Result<ThermalGraph> {
    let Some(cut) = settings.server_influence else {
        return Ok(calibration_model::hall_surrogate(
            &setup.hall,
            setup.model.layout(),
            settings,
            None,
        )?);
    };
    // As `calibration_model::server_influence_adjacency` builds it, with the adjoint
    // solves done once per setup.
    let state = &setup.snaps[0].state;
    let influence = match setup.influence.get() {
        Some(i) => i,
        None => {
            let i = calibration_model::initial_influence(
                setup.model.simulator(),
                setup.model.layout(),
                state,
            )?;
            setup.influence.get_or_init(|| i)
        }
    };
    let adjacency =
        calibration_model::influence_adjacency(&setup.hall, state, settings, influence, cut)?;
    let geometric = HallCalibrationSettings {
        server_influence: None,
        ..settings.clone()
    };
    Ok(
        calibration_model::hall_surrogate(&setup.hall, setup.model.layout(), &geometric, None)?
            .with_adjacency(adjacency)?,
    )
}

/// Serialises a preset by its CLI name.
pub fn ser_preset<S: serde::Serializer>(p: &Preset, s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(p.as_str())
}

/// Reads a preset from its CLI name.
pub fn de_preset<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Preset, D::Error> {
    let s = String::deserialize(d)?;
    s.parse().map_err(serde::de::Error::custom)
}

/// Reads an experiment's JSON result (to redraw its figure without rerunning it).
/// `--render FILE.json` among the arguments: redraws an earlier run's figure (`.svg`) and
/// table (`.md`) beside the file. Returns the exit code (0 done, 1 failed, 2 no file
/// given), or none when the flag is absent.
pub fn render_if_asked<R: serde::de::DeserializeOwned>(
    raw: &[String],
    figure: &str,
    svg: fn(&R) -> String,
    markdown: fn(&R) -> String,
) -> Option<i32> {
    let i = raw.iter().position(|a| a == "--render")?;
    let Some(file) = raw.get(i + 1).map(PathBuf::from) else {
        eprintln!("--render needs a {figure}.json file");
        return Some(2);
    };
    let written = read_json::<R>(&file).and_then(|r| {
        let dir = file.parent().unwrap_or(Path::new("."));
        let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or(figure);
        write_file(dir, &format!("{stem}.svg"), &svg(&r))?;
        write_file(dir, &format!("{stem}.md"), &markdown(&r))
    });
    Some(match written {
        Ok(_) => 0,
        Err(e) => {
            eprintln!("{e}");
            1
        }
    })
}

pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?)
}

/// Mean, sample standard deviation, minimum and maximum of a set of values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Values summarised.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (0 for one value).
    pub sd: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

impl Stats {
    /// Summarises `v`; `None` when it is empty.
    pub fn of(v: &[f64]) -> Option<Stats> {
        if v.is_empty() {
            return None;
        }
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = if n > 1 {
            v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        Some(Stats {
            n,
            mean,
            sd: var.sqrt(),
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        })
    }

    /// `mean ± sd` with `digits` decimals (no spread for one value).
    pub fn show(&self, digits: usize) -> String {
        if self.n > 1 {
            format!("{:.digits$} ± {:.digits$}", self.mean, self.sd)
        } else {
            format!("{:.digits$}", self.mean)
        }
    }
}

/// The value after `flag` in `args`, when the flag is there (the analysis examples'
/// `--flag VALUE` options).
pub fn flag_value<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
    let i = args.iter().position(|a| a == flag)?;
    args.get(i + 1).map(String::as_str)
}

/// `--preset NAME` from `args`, or `default` without it; an unknown name exits with
/// code 2 and a message naming the flag.
pub fn preset_flag(args: &[String], default: Preset) -> Preset {
    flag_value(args, "--preset")
        .map_or(Ok(default), str::parse)
        .unwrap_or_else(|e| {
            eprintln!("--preset: {e}");
            std::process::exit(2)
        })
}

/// Resamples behind [`ratio_interval`].
pub const BOOTSTRAP_RESAMPLES: usize = 10_000;
const BOOTSTRAP_SEED: u64 = 2020;

/// A 95 % percentile bootstrap interval for `mean(num) / mean(den)` over seeds: each
/// sample is resampled on its own, with replacement ([`BOOTSTRAP_RESAMPLES`] times, seeded,
/// so the same values give the same interval). The two are independent runs of two
/// approaches, so seeds are not paired. `None` when a sample has fewer than 2 values or a
/// resampled denominator is not positive.
pub fn ratio_interval(num: &[f64], den: &[f64]) -> Option<(f64, f64)> {
    use rand::{Rng, SeedableRng};
    // One seed resamples to itself: an interval of one point says nothing.
    if num.len() < 2 || den.len() < 2 {
        return None;
    }
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(BOOTSTRAP_SEED);
    let mut resample_mean = |v: &[f64]| {
        (0..v.len())
            .map(|_| v[rng.random_range(0..v.len())])
            .sum::<f64>()
            / v.len() as f64
    };
    let mut ratios = Vec::with_capacity(BOOTSTRAP_RESAMPLES);
    for _ in 0..BOOTSTRAP_RESAMPLES {
        let n = resample_mean(num);
        let d = resample_mean(den);
        if !(d > 0.0 && n.is_finite()) {
            return None;
        }
        ratios.push(n / d);
    }
    ratios.sort_by(f64::total_cmp);
    let at = |q: f64| ratios[((q * (BOOTSTRAP_RESAMPLES - 1) as f64).round()) as usize];
    Some((at(0.025), at(0.975)))
}

/// Shows an optional summary, `n/a` when absent.
pub fn show_opt(s: &Option<Stats>, digits: usize) -> String {
    s.as_ref().map_or_else(|| "n/a".into(), |s| s.show(digits))
}

/// Command-line options shared by the experiment binaries.
#[derive(Debug, Clone, PartialEq)]
pub struct Args {
    /// Tiny budgets on the demo hall.
    pub quick: bool,
    /// Where results are written.
    pub out_dir: PathBuf,
    /// Number of seeds (None: the experiment's default).
    pub seeds: Option<usize>,
    /// Presets with an optional seed count each (`hall-a:3,hall-b:1`).
    pub presets: Option<Vec<(Preset, Option<usize>)>>,
}

/// Where the experiments write without `--out-dir`: a scratch directory, so that a
/// reproduction (or a `--quick` try) never replaces the stored `docs/results` (give
/// `--out-dir docs/results` to update those).
pub const DEFAULT_OUT_DIR: &str = "target/experiments";

/// With `--help` or `-h` among `raw`, prints `usage` and exits 0: before anything runs
/// (a program that ignored the flag ran its whole experiment).
pub fn exit_with_help_if_asked(raw: &[String], usage: &str) {
    if raw.iter().any(|a| a == "--help" || a == "-h") {
        println!("{}", usage.trim());
        std::process::exit(0);
    }
}

/// Exits with code 2 naming the first of `raw` that is a flag (`--...`) not in `known`
/// (flags taking a value are in `known` with their value skipped by the caller's own
/// parse): a misspelt switch must not run another experiment than the one asked for.
pub fn refuse_unknown_flags(raw: &[String], known: &[&str], usage: &str) {
    if let Some(f) = raw
        .iter()
        .find(|a| a.starts_with("--") && !known.contains(&a.as_str()))
    {
        eprintln!("unknown argument `{f}`\n\n{}", usage.trim());
        std::process::exit(2);
    }
}

/// Makes `dir` (the results' directory) now, so that a path that cannot be one (a file)
/// is refused before the experiment runs, not after.
pub fn prepare_out_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("--out-dir {}: {e}; expected a directory", dir.display()).into())
}

/// Makes the parent directory of `file` (an analysis program's `--out FILE`) now, and
/// refuses a directory as the file, before the experiment runs.
pub fn prepare_out_file(file: &Path) -> Result<()> {
    if file.is_dir() {
        return Err(format!("--out {}: is a directory; expected a file", file.display()).into());
    }
    match file.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => std::fs::create_dir_all(dir)
            .map_err(|e| format!("--out {}: {e}", file.display()).into()),
        None => Ok(()),
    }
}

/// Exits with code 2 unless `args.presets` is absent or one hall without a seed count:
/// `program` (Fig. 7 or 8) runs one hall, and used to take the first of a list and drop
/// the rest and the counts without a word.
pub fn one_hall(args: &Args, program: &str) {
    match args.presets.as_deref() {
        None | Some([(_, None)]) => {}
        Some(_) => {
            eprintln!(
                "--presets: {program} runs one hall: give one name without a seed count \
                 (--seeds N sets the seeds)"
            );
            std::process::exit(2);
        }
    }
}

/// Parses `--quick`, `--out-dir DIR`, `--seeds N`, `--presets a[:n],b[:n]`.
pub fn parse_args(args: impl IntoIterator<Item = String>) -> std::result::Result<Args, String> {
    let mut a = Args {
        quick: false,
        out_dir: PathBuf::from(DEFAULT_OUT_DIR),
        seeds: None,
        presets: None,
    };
    let mut it = args.into_iter();
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("`{flag}` needs a value"));
        match flag.as_str() {
            "--quick" => a.quick = true,
            "--out-dir" => a.out_dir = PathBuf::from(value()?),
            "--seeds" => {
                let v = value()?;
                let n: usize = v
                    .parse()
                    .map_err(|_| format!("--seeds: `{v}` is not a count"))?;
                if n == 0 {
                    return Err("--seeds must be at least 1".into());
                }
                a.seeds = Some(n);
            }
            "--presets" => {
                let mut list = Vec::new();
                for item in value()?.split(',') {
                    let (name, n) = match item.split_once(':') {
                        Some((p, n)) => (
                            p,
                            Some(n.parse::<usize>().map_err(|_| {
                                format!("--presets: `{n}` in `{item}` is not a seed count")
                            })?),
                        ),
                        None => (item, None),
                    };
                    list.push((name.parse::<Preset>().map_err(|e| e.to_string())?, n));
                }
                a.presets = Some(list);
            }
            other => {
                return Err(format!(
                    "unknown argument `{other}` (use --quick, --out-dir DIR, --seeds N, \
                     --presets hall-a[:seeds],hall-b[:seeds])"
                ))
            }
        }
    }
    Ok(a)
}

/// Writes `text` to `dir/name`, creating `dir`; errors name the file.
pub fn write_file(dir: &Path, name: &str, text: &str) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join(name);
    std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path)
}

/// Writes `value` as pretty JSON to `dir/name`.
pub fn write_json(dir: &Path, name: &str, value: &impl Serialize) -> Result<PathBuf> {
    write_file(dir, name, &serde_json::to_string_pretty(value)?)
}

/// Best MAE so far at or before `iteration` in a `(iteration, model_runs, best_mae_c)`
/// history (the last point when the history stopped earlier).
pub fn best_at(history: &[(usize, usize, f64)], iteration: usize) -> f64 {
    history
        .iter()
        .take_while(|h| h.0 <= iteration)
        .last()
        .map_or(f64::NAN, |h| h.2)
}

/// The loop report as `(iteration, model_runs, best_mae_c)`, with iteration 0 the initial
/// values after the design (counted with every design run; the design's own best may be
/// lower, and is credited to iteration 1 at the latest).
pub fn loop_history(report: &Report) -> Vec<(usize, usize, f64)> {
    let mut h = vec![(
        0,
        report.initial.design_runs,
        report.initial.mae_c.unwrap_or(f64::INFINITY),
    )];
    for r in &report.history {
        h.push((
            r.iteration,
            r.model_runs,
            r.best_mae_c.unwrap_or(f64::INFINITY),
        ));
    }
    h
}

/// Solves `a x = b` for a small symmetric positive definite `a` (Gaussian elimination
/// without pivoting): the per-sensor normal equations of the analysis examples.
pub fn solve_spd(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let d = b.len();
    for c in 0..d {
        for r in c + 1..d {
            let f = a[r][c] / a[c][c];
            let pivot_row = a[c].clone();
            for (x, p) in a[r].iter_mut().zip(&pivot_row).skip(c) {
                *x -= f * p;
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; d];
    for c in (0..d).rev() {
        let s: f64 = (c + 1..d).map(|j| a[c][j] * x[j]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    x
}
