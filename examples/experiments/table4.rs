//! Table 4: Kalibre against the paper's baselines on the same measurements and model.
//!
//! Rows: Kalibre (the thermal graph in the four-step loop), the vanilla MLP in the same
//! loop, the (1+1)-ES over the model, and the expert's manual heuristic. Columns: best
//! MAE after 10 iterations, lowest MAE within the budget, the iteration and model runs
//! that reached it, model runs to reach 1.0 C, wall time; mean and spread over seeds.

use std::time::Instant;

use kalibre::baselines::{
    run_es, BaselineReport, InputLevel, ManualHeuristic, ManualSettings, Mlp, MlpSettings,
    OnePlusOneEs,
};
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::synth::Preset;
use serde::{Deserialize, Serialize};

use super::{best_at, kalibre_surrogate, loop_history, run_loop, setup, Result, Setup, Stats};

/// The MAE the "model runs to reach" column counts to (C), as in the issue.
pub const REACH_MAE_C: f64 = 1.0;

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
    /// `(iteration, model_runs, best_mae_c)` per iteration.
    pub history: Vec<(usize, usize, f64)>,
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

    /// Mean model runs to 1.0 C, counting a seed that never got there with all its runs
    /// (then a lower bound: the flag is true).
    pub fn runs_to_1c_bound(&self) -> (f64, bool) {
        let v: Vec<f64> = self
            .runs
            .iter()
            .map(|r| r.model_runs_to_1c.unwrap_or(r.model_runs) as f64)
            .collect();
        (
            v.iter().sum::<f64>() / v.len() as f64,
            self.reached_1c < self.runs.len(),
        )
    }
}

/// Whether the targets hold on one hall.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Targets {
    /// Kalibre has the lowest mean MAE after 10 iterations.
    pub best_after_10: bool,
    /// Kalibre needs the fewest mean model runs to its lowest MAE.
    pub fewest_runs_to_lowest: bool,
    /// ES model runs to 1.0 C over Kalibre's (a lower bound when ES never got there).
    pub es_over_kalibre_runs_to_1c: Option<f64>,
    /// MLP model runs to 1.0 C over Kalibre's (a lower bound when it never got there).
    pub mlp_over_kalibre_runs_to_1c: Option<f64>,
    /// ES ratio at least 5.
    pub es_ratio_met: Option<bool>,
    /// MLP ratio at least 2.
    pub mlp_ratio_met: Option<bool>,
}

/// Table 4 on one hall.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HallTable {
    /// Preset.
    pub preset: String,
    /// Servers, sensors, calibrated parameters, snapshots (model runs per point).
    pub size: (usize, usize, usize, usize),
    /// Seeds per seeded approach.
    pub seeds: usize,
    /// Budgets used.
    pub budgets: Budgets,
    /// MAE at the initial alphas (C).
    pub initial_mae_c: f64,
    /// MAE of the model at the true alphas (C), when measured.
    pub model_at_truth_mae_c: Option<f64>,
    /// MAE of the noise alone (C), when measured.
    pub noise_only_mae_c: Option<f64>,
    /// Rows: Kalibre, MLP, ES, manual.
    pub rows: Vec<ApproachRow>,
    /// The targets.
    pub targets: Targets,
}

/// Runs every approach on `preset` with seeds `1..=seeds`. `progress` receives one line
/// per finished run.
pub fn run_hall(
    preset: Preset,
    seeds: usize,
    budgets: Budgets,
    reference: bool,
    progress: &dyn Fn(&str),
) -> Result<HallTable> {
    let s = setup(preset, reference)?;
    progress(&format!("{preset}: synthesised in {:.0} s", s.synth_s));
    let settings = HallCalibrationSettings::default();
    let mut kal = Vec::new();
    let mut mlp = Vec::new();
    let mut es = Vec::new();
    for seed in 1..=seeds as u64 {
        kal.push(kalibre_run(&s, &settings, seed, budgets.kalibre)?);
        progress(&line(preset, "kalibre", &kal[kal.len() - 1]));
        if budgets.mlp_seeds.unwrap_or(usize::MAX) >= seed as usize {
            mlp.push(mlp_run(&s, &settings, seed, budgets.mlp)?);
            progress(&line(preset, "mlp", &mlp[mlp.len() - 1]));
        }
        let e = OnePlusOneEs::default()
            .with_seed(seed)
            .with_max_iterations(budgets.es);
        let r = run_es(&s.model, &s.obs, s.model.layout().space(), &e, None)?;
        es.push(ApproachRun::from_baseline(Some(seed), &r));
        progress(&line(preset, "es", &es[es.len() - 1]));
    }
    // The expert's procedure is deterministic: one run stands for every seed.
    let m = ManualHeuristic::new(
        &s.hall,
        s.model.layout().clone(),
        ManualSettings::default().with_max_iterations(budgets.manual),
    )?;
    let manual = vec![ApproachRun::from_baseline(
        None,
        &m.run(&s.model, &s.obs, None)?,
    )];
    progress(&line(preset, "manual", &manual[0]));
    let rows = vec![
        ApproachRow::new("Kalibre (thermal graph loop)", kal),
        ApproachRow::new("Vanilla MLP loop", mlp),
        ApproachRow::new("(1+1)-ES", es),
        ApproachRow::new("Manual heuristic", manual),
    ];
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
    )
}

fn kalibre_run(
    s: &Setup,
    settings: &HallCalibrationSettings,
    seed: u64,
    iterations: usize,
) -> Result<ApproachRun> {
    let mut st = settings.clone();
    st.core.seed = seed;
    st.core.max_iterations = iterations;
    let t = Instant::now();
    let r = run_loop(
        s,
        kalibre_surrogate(s, &st)?,
        st.searcher.clone(),
        &st,
        None,
    )?;
    let initial = r.initial.mae_c.unwrap_or(f64::INFINITY);
    Ok(ApproachRun::from_history(
        Some(seed),
        initial,
        loop_history(&r),
        t.elapsed().as_secs_f64(),
    ))
}

/// The vanilla MLP (518-128-32 style, rack-level inputs) in the same loop, with the same
/// loop settings, prior and searcher as Kalibre.
fn mlp_run(
    s: &Setup,
    settings: &HallCalibrationSettings,
    seed: u64,
    iterations: usize,
) -> Result<ApproachRun> {
    let mut st = settings.clone();
    st.core.seed = seed;
    st.core.max_iterations = iterations;
    let net = Mlp::new(
        &s.hall,
        s.model.layout().clone(),
        MlpSettings::default().with_inputs(InputLevel::Rack),
    )?;
    let t = Instant::now();
    let r = run_loop(s, net, st.searcher.clone(), &st, None)?;
    let initial = r.initial.mae_c.unwrap_or(f64::INFINITY);
    Ok(ApproachRun::from_history(
        Some(seed),
        initial,
        loop_history(&r),
        t.elapsed().as_secs_f64(),
    ))
}

fn targets(rows: &[ApproachRow]) -> Targets {
    let k = &rows[0];
    let others = &rows[1..];
    let best_after_10 = others
        .iter()
        .all(|o| k.mae_after_10_c.mean < o.mae_after_10_c.mean);
    let fewest_runs_to_lowest = others
        .iter()
        .all(|o| k.model_runs_to_lowest.mean < o.model_runs_to_lowest.mean);
    // A ratio is only defined when Kalibre reached 1.0 C on every seed.
    let kal_runs = (k.reached_1c == k.runs.len()).then(|| k.runs_to_1c_bound().0);
    let ratio = |o: &ApproachRow| kal_runs.map(|kr| o.runs_to_1c_bound().0 / kr);
    let es = ratio(&rows[2]);
    let mlp = ratio(&rows[1]);
    Targets {
        best_after_10,
        fewest_runs_to_lowest,
        es_over_kalibre_runs_to_1c: es,
        mlp_over_kalibre_runs_to_1c: mlp,
        es_ratio_met: es.map(|r| r >= 5.0),
        mlp_ratio_met: mlp.map(|r| r >= 2.0),
    }
}

/// Reads the halls of `table4.json` files written by separate invocations (e.g. one
/// hall each, run side by side); a later file's hall replaces an earlier one's.
pub fn combine(files: &[std::path::PathBuf]) -> Result<Vec<HallTable>> {
    let mut out: Vec<HallTable> = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(f).map_err(|e| format!("{}: {e}", f.display()))?;
        #[derive(Deserialize)]
        struct Doc {
            halls: Vec<HallTable>,
        }
        let doc: Doc = serde_json::from_str(&text)
            .map_err(|e| format!("{}: not a table4.json ({e})", f.display()))?;
        for h in doc.halls {
            out.retain(|o| o.preset != h.preset);
            out.push(h);
        }
    }
    Ok(out)
}

/// The tables as markdown.
pub fn markdown(tables: &[HallTable]) -> String {
    let mut s = String::from(
        "| hall | approach | seeds | MAE after 10 it. (C) | lowest MAE (C) | iteration of lowest | model runs to lowest | model runs to 1.0 C | wall s |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for t in tables {
        for r in &t.rows {
            let reach = match &r.model_runs_to_1c {
                Some(st) if r.reached_1c == r.runs.len() => st.show(0),
                Some(st) => format!("{} ({}/{} seeds)", st.show(0), r.reached_1c, r.runs.len()),
                None => format!("not reached (> {})", r.runs_to_1c_bound().0 as usize),
            };
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                t.preset,
                r.approach,
                r.runs.len(),
                r.mae_after_10_c.show(2),
                r.lowest_mae_c.show(2),
                r.iterations_to_lowest.show(1),
                r.model_runs_to_lowest.show(0),
                reach,
                r.wall_s.show(0)
            ));
        }
    }
    s.push('\n');
    for t in tables {
        let g = &t.targets;
        let ratio = |r: Option<f64>, met: Option<bool>, need: f64| match (r, met) {
            (Some(r), Some(m)) => format!(
                "{r:.1}x (need >= {need}x: {})",
                if m { "met" } else { "NOT met" }
            ),
            _ => "undefined (Kalibre did not reach 1.0 C on every seed)".into(),
        };
        s.push_str(&format!(
            "- {}: initial MAE {:.2} C; model at truth {}; Kalibre best after 10 iterations: {}; fewest model runs to lowest: {}; ES/Kalibre runs to 1.0 C: {}; MLP/Kalibre: {}\n",
            t.preset,
            t.initial_mae_c,
            t.model_at_truth_mae_c.map_or("n/a".into(), |v| format!("{v:.2} C")),
            if g.best_after_10 { "met" } else { "NOT met" },
            if g.fewest_runs_to_lowest { "met" } else { "NOT met" },
            ratio(g.es_over_kalibre_runs_to_1c, g.es_ratio_met, 5.0),
            ratio(g.mlp_over_kalibre_runs_to_1c, g.mlp_ratio_met, 2.0),
        ));
    }
    s
}
