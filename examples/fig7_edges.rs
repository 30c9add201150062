//! Fig. 7's two aisles, asked separately how far a fixed graph could go on the built-in
//! simulator: which server-to-sensor edge rule best explains the hot aisle, and how low
//! the cold aisle's features reach.
//!
//! ```sh
//! cargo run --release --example fig7_edges [-- --preset hall-b] [--per-rack] [--out FILE]
//! ```
//!
//! 160 runs of the preset's first snapshot, alpha drawn as Fig. 7's `--rise-box` draws it
//! (server rise uniform in 5-20 K) per server type, or per rack with `--per-rack`; seed 7.
//! The last 40 runs test. Each fit is per-sensor ridge least squares (ridge 1e-3 per
//! sample on standardised features, scales floored at 0.1, as the graph's start), on 13
//! disjoint training sets of 9 runs (Fig. 7's 5 %) and on all 120 runs before the test
//! runs (the form's floor).
//! - **Hot aisle:** one feature, the paper's heating block `sum_j Wss_jk P_j / alpha_j`,
//!   with `Wss` built by [`Adjacency::from_hall`] under each edge rule: the default, other
//!   cuts, powers of the reciprocal distance, and the height difference scaled; and
//!   with `Wss` from the model's own flow at the initial alphas
//!   ([`Adjacency::with_server_influence`], session 20).
//! - **Cold aisle:** the hall-wide recirculation and bypass features, the local
//!   recirculation term (its first, 3 m form and its default, whole-hall form), and
//!   linear fits on the 11 per-type rises (and alphas): what a
//!   per-sensor form that is linear in such features can reach.

#[path = "experiments/mod.rs"]
mod experiments;

use experiments::fig7::{draw_alphas, AlphaDraw, AlphaGrain, Fig7Config};
use kalibre::core::Model;
use kalibre::dc::calibration::SERVER_INFLUENCE_CUT;
use kalibre::dc::hall::AlphaMode;
use kalibre::dc::surrogate::{
    Adjacency, AdjacencySettings, FlowBalance, FlowBalanceTerm, LocalRecirculationSettings,
    LocalRecirculationTerm, PenaltySettings, SurrogateTerm, LOCAL_RADIUS_M,
};
use kalibre::dc::synth::Preset;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde_json::json;

const RUNS: usize = 160;
const TEST_FROM: usize = 120;
const SMALL: usize = 9;

/// A fitted per-sensor model: feature means and scales, weights, and the output mean.
struct Fit {
    mean: Vec<f64>,
    scale: Vec<f64>,
    weight: Vec<f64>,
    y_mean: f64,
}

impl Fit {
    /// Ridge least squares of `y` on the standardised rows `x[i]`, `i` in `train`.
    fn new(x: &[Vec<f64>], y: &[f64], train: &[usize]) -> Fit {
        let d = x[0].len();
        let n = train.len() as f64;
        let mean: Vec<f64> = (0..d)
            .map(|j| train.iter().map(|&i| x[i][j]).sum::<f64>() / n)
            .collect();
        let scale: Vec<f64> = (0..d)
            .map(|j| {
                let var = train
                    .iter()
                    .map(|&i| (x[i][j] - mean[j]).powi(2))
                    .sum::<f64>()
                    / n;
                var.sqrt().max(0.1)
            })
            .collect();
        let y_mean = train.iter().map(|&i| y[i]).sum::<f64>() / n;
        let mut a = vec![vec![0.0; d]; d];
        let mut b = vec![0.0; d];
        for &i in train {
            let z: Vec<f64> = (0..d).map(|j| (x[i][j] - mean[j]) / scale[j]).collect();
            for p in 0..d {
                for q in 0..d {
                    a[p][q] += z[p] * z[q];
                }
                b[p] += z[p] * (y[i] - y_mean);
            }
        }
        for (p, row) in a.iter_mut().enumerate() {
            row[p] += 1e-3 * n;
        }
        let weight = experiments::solve_spd(a, b);
        Fit {
            mean,
            scale,
            weight,
            y_mean,
        }
    }

    fn predict(&self, x: &[f64]) -> f64 {
        self.y_mean
            + (0..x.len())
                .map(|j| self.weight[j] * (x[j] - self.mean[j]) / self.scale[j])
                .sum::<f64>()
    }
}

/// Test MAE over `sensors` of per-sensor fits on `features(run, sensor)`: the mean over
/// the small training sets, and with all training runs.
fn score(
    sensors: &[usize],
    outputs: &[Vec<f64>],
    features: &dyn Fn(usize, usize) -> Vec<f64>,
) -> (f64, f64) {
    let smalls: Vec<Vec<usize>> = (0..TEST_FROM / SMALL)
        .map(|i| (SMALL * i..SMALL * (i + 1)).collect())
        .collect();
    let all: Vec<usize> = (0..TEST_FROM).collect();
    let (mut small, mut large, mut n) = (0.0, 0.0, 0usize);
    for &k in sensors {
        let y: Vec<f64> = outputs.iter().map(|o| o[k]).collect();
        let x: Vec<Vec<f64>> = (0..RUNS).map(|i| features(i, k)).collect();
        let test_error = |fit: &Fit| {
            (TEST_FROM..RUNS)
                .map(|i| (fit.predict(&x[i]) - y[i]).abs())
                .sum::<f64>()
        };
        for train in &smalls {
            small += test_error(&Fit::new(&x, &y, train)) / smalls.len() as f64;
        }
        large += test_error(&Fit::new(&x, &y, &all));
        n += RUNS - TEST_FROM;
    }
    (small / n as f64, large / n as f64)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = experiments::preset_flag(&args, Preset::HallA);
    let per_rack = args.iter().any(|a| a == "--per-rack");
    let out = experiments::flag_value(&args, "--out").map(std::path::PathBuf::from);
    let usage = "usage: fig7_edges [--preset hall-a|hall-b|demo] [--per-rack] [--out FILE.json]\n(without --out nothing is written; threads: RAYON_NUM_THREADS)";
    experiments::exit_with_help_if_asked(&args, usage);
    experiments::refuse_unknown_flags(&args, &["--preset", "--per-rack", "--out"], usage);
    if let Some(Err(e)) = out.as_deref().map(experiments::prepare_out_file) {
        eprintln!("{e}");
        std::process::exit(2);
    }

    let mode = per_rack.then_some(AlphaMode::PerServer);
    let s = experiments::setup_with_alpha(preset, false, mode).expect("the synthetic hall");
    let layout = s.model.layout().clone();
    let state = s.snaps[0].state.clone();
    let rise = PenaltySettings::default();
    let rack_of: Vec<usize> = s.hall.servers().map(|r| r.rack_index).collect();
    // Fig. 7's own rise-box draw, at this example's run count and seed.
    let draw = Fig7Config {
        samples: RUNS,
        draw: AlphaDraw::Rise,
        grain: if per_rack {
            AlphaGrain::Rack
        } else {
            AlphaGrain::Type
        },
        ..Fig7Config::full()
    };
    let space = layout.space();
    let params: Vec<Vec<f64>> = draw_alphas(
        &draw,
        space,
        &rack_of,
        &mut Xoshiro256PlusPlus::seed_from_u64(7),
    )
    .and_then(|points| {
        points
            .iter()
            .map(|u| space.from_unit(u).map_err(Into::into))
            .collect()
    })
    .expect("the rise-box draw");
    let outputs: Vec<Vec<f64>> = params
        .par_iter()
        .map(|p| s.model.evaluate(&state, p).expect("a run").values)
        .collect();
    let alpha: Vec<Vec<f64>> = params.iter().map(|p| layout.alpha_per_server(p)).collect();
    let hot_flags = s.hot_sensors();
    let (hot, cold): (Vec<usize>, Vec<usize>) = (0..hot_flags.len()).partition(|&k| hot_flags[k]);

    let mut rows = Vec::new();
    let mut print = |aisle: &str, name: String, (small, large): (f64, f64)| {
        println!("{aisle:<4} {name:<52} {SMALL} runs {small:.3} C   {TEST_FROM} runs {large:.3} C");
        rows.push(
            json!({"aisle": aisle, "model": name, "small_mae_c": small, "large_mae_c": large}),
        );
    };

    // Hot aisle: the heating block under each edge rule.
    let default = AdjacencySettings::default();
    let mut rules: Vec<(String, AdjacencySettings)> = vec![
        ("default (1/d, cut 0.6)".into(), default),
        ("cut 0.3".into(), default.with_server_threshold(0.3)),
        ("cut 0.9".into(), default.with_server_threshold(0.9)),
    ];
    for power in [2.0, 4.0] {
        for vertical in [1.0, 0.5, 0.25] {
            for cut in [0.6, 0.3] {
                rules.push((
                    format!("1/d^{power}, height x{vertical}, cut {cut}"),
                    default
                        .with_server_distance_power(power)
                        .with_server_vertical_scale(vertical)
                        .with_server_threshold(cut),
                ));
            }
        }
    }
    rules.push((
        "1/d, height x0.5".into(),
        default.with_server_vertical_scale(0.5),
    ));
    // The model's own transport (session 20): each sensor's sensitivity to each server's
    // rise in the flow at the initial alphas, cut at 1 % of the row's largest and not cut.
    let initial = layout.alpha_per_server(&space.initial());
    let (_, influence) = s
        .model
        .simulator()
        .sensor_influence(&state, &initial, &[])
        .expect("the adjoint solves");
    let mut adjacencies: Vec<(String, Adjacency)> = rules
        .into_iter()
        .map(|(name, rule)| {
            (
                name,
                Adjacency::from_hall(&s.hall, &rule).expect("adjacency"),
            )
        })
        .collect();
    for cut in [SERVER_INFLUENCE_CUT, 0.0] {
        adjacencies.push((
            format!("from the model's flow, cut {cut}"),
            Adjacency::from_hall(&s.hall, &default)
                .and_then(|a| a.with_server_influence(&influence.per_sensor, &state.power_w, cut))
                .expect("influence edges"),
        ));
    }
    for (name, adj) in adjacencies {
        let block = |i: usize, k: usize| {
            vec![adj
                .ss
                .range(k)
                .map(|e| {
                    let j = adj.ss.col[e] as usize;
                    adj.ss.val[e] * state.power_w[j] / alpha[i][j]
                })
                .sum::<f64>()]
        };
        print("hot", name, score(&hot, &outputs, &block));
    }

    // Cold aisle: hall-wide and local mass-balance features, and per-type linear fits.
    let n_out = hot_flags.len();
    let terms: Vec<Box<dyn SurrogateTerm>> = vec![
        Box::new(FlowBalanceTerm::new(
            &s.hall,
            &layout,
            FlowBalance::Recirculation,
        )),
        Box::new(FlowBalanceTerm::new(&s.hall, &layout, FlowBalance::Bypass)),
        // The local term's first form (3 m, every sensor) and its default form (the
        // whole hall weighed by 1/d, cold-aisle sensors only).
        Box::new(
            LocalRecirculationTerm::with_settings(
                &s.hall,
                &layout,
                LocalRecirculationSettings::within(LOCAL_RADIUS_M),
            )
            .expect("the 3 m reach"),
        ),
        Box::new(LocalRecirculationTerm::new(&s.hall, &layout)),
    ];
    let term_features: Vec<Vec<Vec<f64>>> = params
        .iter()
        .map(|p| {
            terms
                .iter()
                .map(|t| {
                    let mut f = vec![0.0; n_out];
                    t.features(&state, p, &mut f);
                    f
                })
                .collect()
        })
        .collect();
    let rises: Vec<Vec<f64>> = params
        .iter()
        .map(|p| p.iter().map(|a| rise.rise_coefficient() / a).collect())
        .collect();
    let hall_wide = |i: usize, k: usize| vec![term_features[i][0][k], term_features[i][1][k]];
    let with_local = |i: usize, k: usize| {
        let mut v = hall_wide(i, k);
        v.push(term_features[i][2][k]);
        v
    };
    print(
        "cold",
        "hall-wide recirculation + bypass (the graph's)".into(),
        score(&cold, &outputs, &hall_wide),
    );
    print(
        "cold",
        "hall-wide + local recirculation".into(),
        score(&cold, &outputs, &with_local),
    );
    let whole_hall = |i: usize, k: usize| vec![term_features[i][3][k]];
    let with_whole_hall = |i: usize, k: usize| {
        let mut v = hall_wide(i, k);
        v.push(term_features[i][3][k]);
        v
    };
    print(
        "cold",
        "whole-hall local recirculation alone".into(),
        score(&cold, &outputs, &whole_hall),
    );
    print(
        "cold",
        "hall-wide + whole-hall local recirculation".into(),
        score(&cold, &outputs, &with_whole_hall),
    );
    if !per_rack {
        // One rise and one alpha per type: 22 features, linear.
        let per_type = |i: usize, k: usize| {
            let mut v = rises[i].clone();
            v.extend(&params[i]);
            v.extend(hall_wide(i, k));
            v
        };
        print(
            "cold",
            "per-type rises and alphas + hall-wide".into(),
            score(&cold, &outputs, &per_type),
        );
    }
    if let Some(path) = out {
        let doc = json!({
            "experiment": "fig7_edges",
            "preset": preset.as_str(),
            "draw": if per_rack { "rise, per rack" } else { "rise, per type" },
            "runs": RUNS,
            "test_runs": RUNS - TEST_FROM,
            "small_training_runs": SMALL,
            "rows": rows,
        });
        std::fs::write(&path, serde_json::to_string_pretty(&doc).expect("json"))
            .unwrap_or_else(|e| eprintln!("{}: {e}", path.display()));
    }
}
