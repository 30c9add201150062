//! The thermal graph surrogate: gradients against finite differences, recovery of a
//! planted truth, alpha recovery by search, adjacency structure, the rise penalty and the
//! specialised objective against the generic one.
//!
//! One test binary: the tests live in `surrogate/`, one concept per module; this root
//! holds the helpers they share (graphs, designs, training samples, planted truths).

mod surrogate_fixture;

#[path = "surrogate/adjacency.rs"]
mod adjacency;
#[path = "surrogate/bad_input.rs"]
mod bad_input;
#[path = "surrogate/fitting.rs"]
mod fitting;
#[path = "surrogate/gradients.rs"]
mod gradients;
#[path = "surrogate/penalty.rs"]
mod penalty;
#[path = "surrogate/search.rs"]
mod search;

use kalibre_core::{Sample, Surrogate, TrainingSet};
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::surrogate::{ThermalGraph, ThermalGraphSettings};
use kalibre_dc::ParamLayout;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

fn graph(hall: &Hall, mode: AlphaMode, settings: ThermalGraphSettings) -> ThermalGraph {
    let layout = ParamLayout::with_mode(hall, mode, &[]).unwrap();
    ThermalGraph::new(hall, layout, settings).unwrap()
}

/// The paper's initial design in the unit box (lower, upper, midpoint of every
/// parameter), each with `copies` Gaussian-jittered copies (sd 0.05 in unit coordinates).
fn design(g: &ThermalGraph, copies: usize, seed: u64) -> Vec<Vec<f64>> {
    let space = g.layout().space();
    let d = space.dim();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.05).unwrap();
    let mut out = Vec::new();
    for base in [0.0, 1.0, 0.5] {
        out.push(space.from_unit(&vec![base; d]).unwrap());
        for _ in 1..copies {
            let u: Vec<f64> = (0..d)
                .map(|_| (base + noise.sample(&mut rng)).clamp(0.0, 1.0))
                .collect();
            out.push(space.from_unit(&u).unwrap());
        }
    }
    out
}

fn samples(truth: &ThermalGraph, scenarios: &[OperatingState], params: &[Vec<f64>]) -> Vec<Sample> {
    let mut out = Vec::new();
    for (s, scen) in scenarios.iter().enumerate() {
        for p in params {
            out.push(Sample {
                snapshot: s,
                params: p.clone(),
                outputs: truth.predict(scen, p),
                weight: 1.0,
            });
        }
    }
    out
}

/// A graph with known weights: the least-squares fit (no Adam) to physically shaped
/// outputs, `T = a X_cold + b` plus, in the hot aisle, `g X_hot + d` with `g` close to
/// `K / mean power` (so that a server's rise is about `1.76 / alpha` K), which the graph
/// represents exactly.
fn planted(hall: &Hall, mode: AlphaMode, scenarios: &[OperatingState], seed: u64) -> ThermalGraph {
    let mut g = graph(
        hall,
        mode,
        ThermalGraphSettings::default()
            .with_epochs(0)
            .with_ridge(0.0),
    );
    let n = g.sensor_count();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x5eed);
    let coef: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            [
                rng.random_range(0.8..1.2),
                rng.random_range(-1.0..1.0),
                1.757 / 300.0 * rng.random_range(0.6..1.0),
                rng.random_range(-1.0..1.0),
            ]
        })
        .collect();
    let d = design(&g, 4, seed);
    let mut train = Vec::new();
    for (si, scen) in scenarios.iter().enumerate() {
        for p in &d {
            let (xc, xh) = g.hidden(scen, p).unwrap();
            let outputs = (0..n)
                .map(|k| {
                    let c = coef[k];
                    let cold = c[0] * xc[k] + c[1];
                    if g.hot_mask()[k] {
                        cold + c[2] * xh[k] + c[3]
                    } else {
                        cold
                    }
                })
                .collect();
            train.push(Sample {
                snapshot: si,
                params: p.clone(),
                outputs,
                weight: 1.0,
            });
        }
    }
    g.fit(
        TrainingSet {
            scenarios,
            samples: &train,
        },
        0,
    )
    .unwrap();
    g
}

fn random_unit(d: usize, rng: &mut Xoshiro256PlusPlus) -> Vec<f64> {
    (0..d).map(|_| rng.random_range(0.05..0.95)).collect()
}
