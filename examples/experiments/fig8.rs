//! Fig. 8: the search loss and gradient per loop iteration, with differential evolution
//! before Adam (Kalibre's hybrid) and with Adam alone (the paper's baseline).
//!
//! Both variants run the full Kalibre loop (same surrogate, prior, loop settings and
//! seeds); only the searcher differs. Per loop iteration the search's trace gives the
//! mean loss and mean gradient norm over its Adam steps (the quantities the paper's
//! TensorFlow loop averages), the loss at the proposal, and the model's MAE there.

use std::sync::Mutex;

use kalibre::core::search::{Adam, Objective, ProjectedGradient};
use kalibre::core::{Event, SearchOutcome, Searcher};
use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::synth::Preset;
use serde::{Deserialize, Serialize};

use super::chart::{panels, LineChart, Series};
use super::{kalibre_surrogate, run_loop, setup, use_paper_loop, Result, Stats};

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fig8Config {
    /// Hall preset.
    #[serde(
        serialize_with = "super::ser_preset",
        deserialize_with = "super::de_preset"
    )]
    pub preset: Preset,
    /// Loop iterations.
    pub iterations: usize,
    /// Seeds.
    pub seeds: usize,
    /// Run the paper's loop (no trust region, no output correction, no fit focus,
    /// the paper's rise prior [5, 15] K)
    /// instead of kalibre's default loop settings.
    #[serde(default)]
    pub paper_loop: bool,
}

impl Fig8Config {
    /// The paper's: 10 iterations on `hall-a`, 3 seeds.
    pub fn full() -> Self {
        Fig8Config {
            preset: Preset::HallA,
            iterations: 10,
            seeds: 3,
            paper_loop: false,
        }
    }
    /// Seconds-long: 3 iterations of `demo`, 1 seed.
    pub fn quick() -> Self {
        Fig8Config {
            preset: Preset::Demo,
            iterations: 3,
            seeds: 1,
            paper_loop: false,
        }
    }
}

/// One loop iteration of one run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IterationTrace {
    /// Loop iteration (1-based).
    pub iteration: usize,
    /// Mean search loss over the Adam steps.
    pub mean_loss: f64,
    /// Mean gradient norm (unit box) over the Adam steps.
    pub mean_grad_norm: f64,
    /// Search loss at the proposal.
    pub final_loss: f64,
    /// Model MAE at the proposal (C).
    pub mae_c: f64,
    /// Best model MAE so far (C).
    pub best_mae_c: f64,
}

/// One variant over its seeds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Variant {
    /// `with DE` or `Adam only`.
    pub name: String,
    /// Per seed, per iteration.
    pub runs: Vec<Vec<IterationTrace>>,
    /// Per iteration: mean loss over seeds.
    pub mean_loss: Vec<Stats>,
    /// Per iteration: mean gradient norm over seeds.
    pub mean_grad_norm: Vec<Stats>,
    /// Per iteration: loss at the proposal over seeds.
    pub final_loss: Vec<Stats>,
    /// Per iteration: best model MAE over seeds (C).
    pub best_mae_c: Vec<Stats>,
}

/// The figure's data.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Fig8Result {
    /// What was run.
    pub config: Fig8Config,
    /// MAE at the initial alphas (C).
    pub initial_mae_c: f64,
    /// With DE, then Adam only.
    pub variants: Vec<Variant>,
}

/// The hybrid without its DE phase: Adam from the start, then the local phase from
/// Adam's best (none when it has 0 steps).
struct AdamThenLocal {
    adam: Adam,
    local: ProjectedGradient,
}

impl Searcher for AdamThenLocal {
    fn search(
        &self,
        objective: &dyn Objective,
        start: &[f64],
        seed: u64,
    ) -> kalibre::core::Result<SearchOutcome> {
        let mut out = self.adam.search(objective, start, seed)?;
        if self.local.steps() > 0 && out.best_cost.is_finite() {
            let local = self.local.search(objective, &out.best_unit, seed)?;
            let offset = out.trace.len();
            out.trace.extend(local.trace.into_iter().map(|mut t| {
                t.iteration += offset;
                t
            }));
            out.evaluations += local.evaluations;
            if local.best_cost < out.best_cost {
                out.best_unit = local.best_unit;
                out.best_cost = local.best_cost;
            }
        }
        Ok(out)
    }
}

fn one_run(
    s: &super::Setup,
    seed: u64,
    cfg: &Fig8Config,
    with_de: bool,
) -> Result<(f64, Vec<IterationTrace>)> {
    let mut st = HallCalibrationSettings::default();
    st.core.seed = seed;
    st.core.max_iterations = cfg.iterations;
    if cfg.paper_loop {
        use_paper_loop(&mut st)?;
    }
    let seen: Mutex<Vec<IterationTrace>> = Mutex::new(Vec::new());
    let record = |e: &Event<'_>| match e {
        Event::SearchDone {
            iteration, outcome, ..
        } => {
            let adam: Vec<_> = outcome.trace.iter().filter(|t| t.phase == "adam").collect();
            let n = adam.len().max(1) as f64;
            let g: Vec<f64> = adam.iter().filter_map(|t| t.grad_norm).collect();
            seen.lock().expect("recorder").push(IterationTrace {
                iteration: *iteration,
                mean_loss: adam.iter().map(|t| t.cost).sum::<f64>() / n,
                mean_grad_norm: g.iter().sum::<f64>() / g.len().max(1) as f64,
                final_loss: outcome.best_cost,
                mae_c: f64::NAN,
                best_mae_c: f64::NAN,
            });
        }
        Event::IterationDone { record } => {
            let mut v = seen.lock().expect("recorder");
            if let Some(t) = v.iter_mut().find(|t| t.iteration == record.iteration) {
                t.mae_c = record.mae_c.unwrap_or(f64::INFINITY);
                t.best_mae_c = record.best_mae_c.unwrap_or(f64::INFINITY);
            }
        }
        _ => {}
    };
    let g = kalibre_surrogate(s, &st)?;
    let report = if with_de {
        run_loop(s, g, st.searcher.clone(), &st, Some(&record))?
    } else {
        // The hybrid without its DE phase: its own Adam phase, then its local phase.
        let adam_only = AdamThenLocal {
            adam: st.searcher.adam().clone(),
            local: st.searcher.local().clone(),
        };
        run_loop(s, g, adam_only, &st, Some(&record))?
    };
    let trace = seen.into_inner().expect("recorder");
    Ok((report.initial.mae_c.unwrap_or(f64::INFINITY), trace))
}

/// Runs both variants; `progress` receives a line per finished run.
pub fn run_fig8(cfg: &Fig8Config, progress: &dyn Fn(&str)) -> Result<Fig8Result> {
    let s = setup(cfg.preset, false)?;
    let mut initial = f64::NAN;
    let mut variants = Vec::new();
    for (name, with_de) in [("with DE", true), ("Adam only", false)] {
        let mut runs = Vec::new();
        for seed in 1..=cfg.seeds as u64 {
            let (init, trace) = one_run(&s, seed, cfg, with_de)?;
            initial = init;
            progress(&format!(
                "{name} seed {seed}: final loss per iteration {:?}",
                trace
                    .iter()
                    .map(|t| (t.final_loss * 1e3).round() / 1e3)
                    .collect::<Vec<_>>()
            ));
            runs.push(trace);
        }
        let len = runs.iter().map(Vec::len).min().unwrap_or(0);
        let col = |f: &dyn Fn(&IterationTrace) -> f64| -> Vec<Stats> {
            (0..len)
                .map(|i| {
                    Stats::of(&runs.iter().map(|r| f(&r[i])).collect::<Vec<_>>()).expect("a seed")
                })
                .collect()
        };
        variants.push(Variant {
            name: name.into(),
            mean_loss: col(&|t| t.mean_loss),
            mean_grad_norm: col(&|t| t.mean_grad_norm),
            final_loss: col(&|t| t.final_loss),
            best_mae_c: col(&|t| t.best_mae_c),
            runs,
        });
    }
    Ok(Fig8Result {
        config: *cfg,
        initial_mae_c: initial,
        variants,
    })
}

/// Four panels: search loss at the proposal, mean search loss, mean gradient norm (both log scale) and best model
/// MAE per loop iteration, both variants.
pub fn svg(r: &Fig8Result) -> String {
    let colours = ["#1f77b4", "#d62728"];
    let panel =
        |title: &str, y: &str, log_y: bool, f: &dyn Fn(&Variant) -> &Vec<Stats>| LineChart {
            title: title.into(),
            x_label: "loop iteration".into(),
            y_label: y.into(),
            log_y,
            series: r
                .variants
                .iter()
                .zip(colours)
                .map(|(v, colour)| Series {
                    name: v.name.clone(),
                    colour,
                    points: f(v)
                        .iter()
                        .enumerate()
                        .map(|(i, s)| ((i + 1) as f64, s.mean))
                        .collect(),
                    spread: if log_y {
                        Vec::new()
                    } else {
                        f(v).iter().map(|s| s.sd).collect()
                    },
                    dashed: v.name != "with DE",
                })
                .collect(),
        };
    panels(&[
        panel(
            "(a) search loss at the proposal",
            "loss (C^2)",
            true,
            &|v| &v.final_loss,
        ),
        panel(
            "(b) mean search loss over Adam steps",
            "loss (C^2)",
            true,
            &|v| &v.mean_loss,
        ),
        panel(
            "(c) mean gradient norm over Adam steps",
            "|grad| (unit box)",
            true,
            &|v| &v.mean_grad_norm,
        ),
        panel("(d) best model MAE", "MAE (C)", false, &|v| &v.best_mae_c),
    ])
}

/// The figure's numbers as a markdown table.
pub fn markdown(r: &Fig8Result) -> String {
    let mut s = String::from(
        "| iteration | mean loss, with DE | mean loss, Adam only | loss at proposal, with DE | loss at proposal, Adam only | grad norm, with DE | grad norm, Adam only | best MAE with DE (C) | best MAE Adam only (C) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    let (a, b) = (&r.variants[0], &r.variants[1]);
    for i in 0..a.mean_loss.len().min(b.mean_loss.len()) {
        s.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} |\n",
            i + 1,
            a.mean_loss[i].mean,
            b.mean_loss[i].mean,
            a.final_loss[i].mean,
            b.final_loss[i].mean,
            a.mean_grad_norm[i].mean,
            b.mean_grad_norm[i].mean,
            a.best_mae_c[i].show(2),
            b.best_mae_c[i].show(2)
        ));
    }
    s.push_str(&format!(
        "\nMeans over {} seeds on {} ({}); initial MAE {:.2} C.\n",
        r.config.seeds,
        r.config.preset,
        if r.config.paper_loop {
            "the paper's loop: no trust region, output correction or focus; rise prior [5, 15] K"
        } else {
            "kalibre's default loop"
        },
        r.initial_mae_c
    ));
    s
}
