//! Table 4: Kalibre against the paper's baselines on the same measurements and model.
//!
//! Rows: Kalibre (the thermal graph in the four-step loop), the vanilla MLP in the same
//! loop, the (1+1)-ES over the model, and the expert's manual heuristic. Columns: best
//! MAE after 10 iterations, lowest MAE within the budget, the iteration and model runs
//! that reached it, model runs to reach 1.0 C, wall time; mean and spread over seeds.

use std::sync::Mutex;
use std::time::Instant;

use kalibre::baselines::{
    run_es, BaselineReport, InputLevel, ManualHeuristic, ManualSettings, Mlp, MlpSettings,
    OnePlusOneEs,
};
use kalibre::core::{Event, Surrogate};
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::snapshots::OperatingState;
use kalibre::dc::synth::Preset;
use serde::{Deserialize, Serialize};

mod combine;
mod markdown;
mod targets;

// Used by the table4 binary and the tests; fig7 and fig8 include this module too.
#[allow(unused_imports)]
pub use combine::combine;
#[allow(unused_imports)]
pub use markdown::markdown;
use targets::targets;
pub use targets::Targets;

use super::{
    best_at, kalibre_surrogate, loop_history, run_loop, setup, use_paper_loop, Result, Setup, Stats,
};

/// The MAE the "model runs to reach" column counts to (C), as in the issue.
pub const REACH_MAE_C: f64 = 1.0;

/// One approach of the table (a row).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Approach {
    /// The thermal graph in the four-step loop.
    Kalibre,
    /// The vanilla MLP in the same loop.
    Mlp,
    /// The (1+1)-ES over the model.
    Es,
    /// The expert's manual heuristic.
    Manual,
}

impl Approach {
    /// Every approach, in table order.
    pub const ALL: [Approach; 4] = [
        Approach::Kalibre,
        Approach::Mlp,
        Approach::Es,
        Approach::Manual,
    ];

    /// Command-line name (`--approaches kalibre,mlp,es,manual`).
    pub fn key(self) -> &'static str {
        match self {
            Approach::Kalibre => "kalibre",
            Approach::Mlp => "mlp",
            Approach::Es => "es",
            Approach::Manual => "manual",
        }
    }

    /// The row's title in the table (and in `table4.json`'s `approach`).
    pub fn title(self) -> &'static str {
        match self {
            Approach::Kalibre => "Kalibre (thermal graph loop)",
            Approach::Mlp => "Vanilla MLP loop",
            Approach::Es => "(1+1)-ES",
            Approach::Manual => "Manual heuristic",
        }
    }

    /// The approach of a row title or command-line name.
    pub fn parse(name: &str) -> Option<Approach> {
        Approach::ALL
            .into_iter()
            .find(|a| a.key() == name || a.title() == name)
    }

    /// Parses a comma-separated list (`kalibre,es`) into table order, without repeats.
    pub fn parse_list(list: &str) -> std::result::Result<Vec<Approach>, String> {
        let mut out = Vec::new();
        for item in list.split(',').map(str::trim) {
            let a = Approach::parse(item).ok_or_else(|| {
                format!("--approaches: unknown approach `{item}` (use kalibre, mlp, es, manual)")
            })?;
            out.push(a);
        }
        out.sort();
        out.dedup();
        Ok(out)
    }

    /// Copies this approach's budget (and the MLP's seed limit) from `from` into `to`.
    fn copy_budget(self, from: &Budgets, to: &mut Budgets) {
        match self {
            Approach::Kalibre => to.kalibre = from.kalibre,
            Approach::Mlp => {
                to.mlp = from.mlp;
                to.mlp_seeds = from.mlp_seeds;
            }
            Approach::Es => to.es = from.es,
            Approach::Manual => to.manual = from.manual,
        }
    }
}

/// Iteration budgets per approach.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Budgets {
    /// Kalibre loop iterations.
    pub kalibre: usize,
    /// MLP loop iterations.
    pub mlp: usize,
    /// (1+1)-ES mutations.
    pub es: usize,
    /// Manual heuristic iterations.
    pub manual: usize,
    /// Run the MLP loop (the slowest approach) on the first this many seeds only (none:
    /// every seed).
    #[serde(default)]
    pub mlp_seeds: Option<usize>,
}

impl Budgets {
    /// The budgets: 20 Kalibre, 60 MLP, 150 ES, 30 manual iterations.
    pub fn full() -> Self {
        Budgets {
            kalibre: 20,
            mlp: 60,
            es: 150,
            manual: 30,
            mlp_seeds: None,
        }
    }
    /// Seconds-long budgets for `--quick` and the test suite.
    pub fn quick() -> Self {
        Budgets {
            kalibre: 4,
            mlp: 3,
            es: 12,
            manual: 6,
            mlp_seeds: None,
        }
    }

    /// Overrides single budgets from a list such as `mlp=5,es=20` (`--budgets`).
    pub fn with_overrides(mut self, list: &str) -> std::result::Result<Self, String> {
        for item in list.split(',').map(str::trim) {
            let parsed = item.split_once('=').and_then(|(name, n)| {
                Some((
                    Approach::parse(name)?,
                    n.parse::<usize>().ok().filter(|&n| n >= 1)?,
                ))
            });
            let Some((a, n)) = parsed else {
                return Err(format!(
                    "--budgets: `{item}` is not approach=iterations (kalibre, mlp, es, manual; at least 1)"
                ));
            };
            match a {
                Approach::Kalibre => self.kalibre = n,
                Approach::Mlp => self.mlp = n,
                Approach::Es => self.es = n,
                Approach::Manual => self.manual = n,
            }
        }
        Ok(self)
    }
}

/// One approach, one seed.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ApproachRun {
    /// Seed of the approach (none for the deterministic manual heuristic).
    pub seed: Option<u64>,
    /// MAE at the initial alphas (C).
    pub initial_mae_c: f64,
    /// Best MAE after 10 iterations (C).
    pub mae_after_10_c: f64,
    /// Lowest MAE within the budget (C).
    pub lowest_mae_c: f64,
    /// Iteration that first reached the lowest MAE.
    pub iterations_to_lowest: usize,
    /// Model runs (all snapshots) used when the lowest MAE was first reached.
    pub model_runs_to_lowest: usize,
    /// Model runs used when the best MAE first reached 1.0 C (none: never).
    pub model_runs_to_1c: Option<usize>,
    /// Model runs used in all.
    pub model_runs: usize,
    /// Wall time, seconds.
    pub wall_s: f64,
    /// Where a loop approach's wall time went (none for the model-only baselines).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loop_time: Option<LoopTime>,
    /// `(iteration, model_runs, best_mae_c)` per iteration.
    pub history: Vec<(usize, usize, f64)>,
}

/// Seconds spent in the steps of the four-step loop, summed over its iterations.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopTime {
    /// Step 1: surrogate fits.
    pub fit_s: f64,
    /// Step 2: searches on the surrogate.
    pub search_s: f64,
    /// Step 3: model runs, summed over runs (above the wall time when runs overlap).
    pub model_runs_s: f64,
}

impl LoopTime {
    /// Adds one loop event's wall time to its step.
    fn add(&mut self, e: &Event<'_>) {
        match e {
            Event::FitDone { wall_s, .. } => self.fit_s += wall_s,
            Event::SearchDone { wall_s, .. } => self.search_s += wall_s,
            Event::RunFinished {
                wall_s,
                cached: false,
                ..
            } => self.model_runs_s += wall_s,
            _ => {}
        }
    }
}

impl ApproachRun {
    fn from_history(
        seed: Option<u64>,
        initial: f64,
        h: Vec<(usize, usize, f64)>,
        wall_s: f64,
    ) -> Self {
        let lowest = h.iter().map(|p| p.2).fold(f64::INFINITY, f64::min);
        let at_lowest = h
            .iter()
            .find(|p| p.2 <= lowest)
            .copied()
            .unwrap_or((0, 0, lowest));
        ApproachRun {
            seed,
            initial_mae_c: initial,
            mae_after_10_c: best_at(&h, 10),
            lowest_mae_c: lowest,
            iterations_to_lowest: at_lowest.0,
            model_runs_to_lowest: at_lowest.1,
            model_runs_to_1c: h.iter().find(|p| p.2 <= REACH_MAE_C).map(|p| p.1),
            model_runs: h.last().map_or(0, |p| p.1),
            wall_s,
            loop_time: None,
            history: h,
        }
    }

    fn from_baseline(seed: Option<u64>, r: &BaselineReport) -> Self {
        let h = r
            .history
            .iter()
            .map(|p| (p.iteration, p.model_runs, p.best_mae_c))
            .collect();
        Self::from_history(seed, r.initial_mae_c, h, r.wall_s)
    }
}

/// One row of the table: an approach over its seeds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ApproachRow {
    /// Approach name.
    pub approach: String,
    /// Per seed.
    pub runs: Vec<ApproachRun>,
    /// Best MAE after 10 iterations (C).
    pub mae_after_10_c: Stats,
    /// Lowest MAE (C).
    pub lowest_mae_c: Stats,
    /// Iterations to the lowest MAE.
    pub iterations_to_lowest: Stats,
    /// Model runs to the lowest MAE.
    pub model_runs_to_lowest: Stats,
    /// Model runs to 1.0 C over the seeds that reached it.
    pub model_runs_to_1c: Option<Stats>,
    /// Seeds that reached 1.0 C.
    pub reached_1c: usize,
    /// Wall time, seconds.
    pub wall_s: Stats,
}

impl ApproachRow {
    fn new(approach: &str, runs: Vec<ApproachRun>) -> Self {
        let col = |f: &dyn Fn(&ApproachRun) -> f64| {
            Stats::of(&runs.iter().map(f).collect::<Vec<_>>()).expect("at least one run")
        };
        let reached: Vec<f64> = runs
            .iter()
            .filter_map(|r| r.model_runs_to_1c.map(|n| n as f64))
            .collect();
        ApproachRow {
            approach: approach.into(),
            mae_after_10_c: col(&|r| r.mae_after_10_c),
            lowest_mae_c: col(&|r| r.lowest_mae_c),
            iterations_to_lowest: col(&|r| r.iterations_to_lowest as f64),
            model_runs_to_lowest: col(&|r| r.model_runs_to_lowest as f64),
            model_runs_to_1c: Stats::of(&reached),
            reached_1c: reached.len(),
            wall_s: col(&|r| r.wall_s),
            runs,
        }
    }

    /// Model runs to 1.0 C per seed, counting a seed that never got there with all its
    /// runs.
    pub fn runs_to_1c_per_seed(&self) -> Vec<f64> {
        self.runs
            .iter()
            .map(|r| r.model_runs_to_1c.unwrap_or(r.model_runs) as f64)
            .collect()
    }

    /// Mean model runs to 1.0 C, counting a seed that never got there with all its runs
    /// (then a lower bound: the flag is true).
    pub fn runs_to_1c_bound(&self) -> (f64, bool) {
        let v = self.runs_to_1c_per_seed();
        (
            v.iter().sum::<f64>() / v.len() as f64,
            self.reached_1c < self.runs.len(),
        )
    }
}

/// Table 4 on one hall.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HallTable {
    /// Preset.
    pub preset: String,
    /// Servers, sensors, calibrated parameters, snapshots (model runs per point).
    pub size: (usize, usize, usize, usize),
    /// Seeds per seeded approach (the most of any row, after `--combine`).
    pub seeds: usize,
    /// Budgets used.
    pub budgets: Budgets,
    /// Whether the loop rows ran the paper's Algorithm 1 ([`super::use_paper_loop`])
    /// instead of kalibre's loop.
    #[serde(default)]
    pub paper_loop: bool,
    /// MAE at the initial alphas (C).
    pub initial_mae_c: f64,
    /// MAE of the model at the true alphas (C), when measured.
    pub model_at_truth_mae_c: Option<f64>,
    /// MAE of the noise alone (C), when measured.
    pub noise_only_mae_c: Option<f64>,
    /// Rows in table order (Kalibre, MLP, ES, manual), those that were run.
    pub rows: Vec<ApproachRow>,
    /// The targets.
    pub targets: Targets,
}

/// Runs `approaches` on `preset` with seeds `1..=seeds`; with `paper_loop`, Kalibre and
/// the MLP run the paper's Algorithm 1 instead of kalibre's loop (the ES and the manual
/// procedure run no loop). `progress` receives one line per finished run.
pub fn run_hall(
    preset: Preset,
    seeds: usize,
    budgets: Budgets,
    approaches: &[Approach],
    reference: bool,
    paper_loop: bool,
    progress: &dyn Fn(&str),
) -> Result<HallTable> {
    if approaches.is_empty() || seeds == 0 {
        return Err("table4: needs at least one approach and one seed".into());
    }
    let s = setup(preset, reference)?;
    progress(&format!("{preset}: synthesised in {:.0} s", s.synth_s));
    // The four-step loop alone, as the paper runs it: without the polish stage, which
    // would spend its Levenberg-Marquardt model runs on both loop rows alike and hide
    // what the surrogate does (it is measured in docs/performance.md).
    let mut settings = HallCalibrationSettings::default();
    settings.core.polish_iterations = 0;
    if paper_loop {
        use_paper_loop(&mut settings)?;
    }
    let wanted = |a: Approach| approaches.contains(&a);
    let mut runs: Vec<(Approach, Vec<ApproachRun>)> = Approach::ALL
        .into_iter()
        .filter(|&a| wanted(a))
        .map(|a| (a, Vec::new()))
        .collect();
    let mut push = |a: Approach, r: ApproachRun| {
        progress(&line(preset, a.key(), &r));
        if let Some((_, v)) = runs.iter_mut().find(|(b, _)| *b == a) {
            v.push(r);
        }
    };
    for seed in 1..=seeds as u64 {
        if wanted(Approach::Kalibre) {
            push(
                Approach::Kalibre,
                kalibre_run(&s, &settings, seed, budgets.kalibre)?,
            );
        }
        if wanted(Approach::Mlp) && budgets.mlp_seeds.unwrap_or(usize::MAX) >= seed as usize {
            push(Approach::Mlp, mlp_run(&s, &settings, seed, budgets.mlp)?);
        }
        if wanted(Approach::Es) {
            let e = OnePlusOneEs::default()
                .with_seed(seed)
                .with_max_iterations(budgets.es);
            let r = run_es(&s.model, &s.obs, s.model.layout().space(), &e, None)?;
            push(Approach::Es, ApproachRun::from_baseline(Some(seed), &r));
        }
    }
    if wanted(Approach::Manual) {
        // The expert's procedure is deterministic: one run stands for every seed.
        let m = ManualHeuristic::new(
            &s.hall,
            s.model.layout().clone(),
            ManualSettings::default().with_max_iterations(budgets.manual),
        )?;
        let r = m.run(&s.model, &s.obs, None)?;
        push(Approach::Manual, ApproachRun::from_baseline(None, &r));
    }
    let rows: Vec<ApproachRow> = runs
        .into_iter()
        .map(|(a, v)| ApproachRow::new(a.title(), v))
        .collect();
    let targets = targets(&rows);
    Ok(HallTable {
        preset: preset.to_string(),
        size: (
            s.hall.server_count(),
            s.hall.sensors.len(),
            s.model.layout().space().dim(),
            s.snaps.len(),
        ),
        seeds,
        budgets,
        paper_loop,
        initial_mae_c: rows[0].runs[0].initial_mae_c,
        model_at_truth_mae_c: s.model_at_truth_mae_c,
        noise_only_mae_c: s.noise_only_mae_c,
        rows,
        targets,
    })
}

fn line(preset: Preset, name: &str, r: &ApproachRun) -> String {
    format!(
        "{preset} {name} seed {:?}: initial {:.3} C, after 10 {:.3} C, lowest {:.3} C at iteration {} \
         ({} runs), 1.0 C after {:?} runs, {:.0} s",
        r.seed,
        r.initial_mae_c,
        r.mae_after_10_c,
        r.lowest_mae_c,
        r.iterations_to_lowest,
        r.model_runs_to_lowest,
        r.model_runs_to_1c,
        r.wall_s
    ) + &r.loop_time.map_or(String::new(), |t| {
        format!(
            " (fit {:.0} s, search {:.0} s, model runs {:.0} s)",
            t.fit_s, t.search_s, t.model_runs_s
        )
    })
}

fn kalibre_run(
    s: &Setup,
    settings: &HallCalibrationSettings,
    seed: u64,
    iterations: usize,
) -> Result<ApproachRun> {
    let st = loop_settings(settings, seed, iterations);
    let surrogate = kalibre_surrogate(s, &st)?;
    timed_loop(s, surrogate, &st, seed)
}

/// The vanilla MLP (518-128-32 style, rack-level inputs) in the same loop, with the same
/// loop settings, prior and searcher as Kalibre.
fn mlp_run(
    s: &Setup,
    settings: &HallCalibrationSettings,
    seed: u64,
    iterations: usize,
) -> Result<ApproachRun> {
    let st = loop_settings(settings, seed, iterations);
    let net = Mlp::new(
        &s.hall,
        s.model.layout().clone(),
        MlpSettings::default().with_inputs(InputLevel::Rack),
    )?;
    timed_loop(s, net, &st, seed)
}

fn loop_settings(
    settings: &HallCalibrationSettings,
    seed: u64,
    iterations: usize,
) -> HallCalibrationSettings {
    let mut st = settings.clone();
    st.core.seed = seed;
    st.core.max_iterations = iterations;
    st
}

/// Runs the loop with `surrogate`, timing it and its steps.
fn timed_loop<Su>(
    s: &Setup,
    surrogate: Su,
    st: &HallCalibrationSettings,
    seed: u64,
) -> Result<ApproachRun>
where
    Su: Surrogate<Scenario = OperatingState> + Sync,
{
    let steps = Mutex::new(LoopTime::default());
    let observe = |e: &Event<'_>| {
        if let Ok(mut t) = steps.lock() {
            t.add(e);
        }
    };
    let t = Instant::now();
    let r = run_loop(s, surrogate, st.searcher.clone(), st, Some(&observe))?;
    let wall_s = t.elapsed().as_secs_f64();
    let initial = r.initial.mae_c.unwrap_or(f64::INFINITY);
    let mut run = ApproachRun::from_history(Some(seed), initial, loop_history(&r), wall_s);
    run.loop_time = steps.into_inner().ok();
    Ok(run)
}
