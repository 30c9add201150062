//! Thermal graph speed at `hall-a` size (2,240 servers, 62 sensors, 8 CRACs, one
//! snapshot, 48 augmented training samples) with alpha per server: surrogate fit, the
//! search objective, and one full iteration (fit + the hybrid DE + Adam search), on the
//! specialised `ThermalGraphObjective` and on the generic `SurrogateObjective` that the
//! calibration loop searches.
//! Prints the per-iteration figure against the 15 ms target.

#[path = "../tests/surrogate_fixture/mod.rs"]
mod surrogate_fixture;

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use kalibre_core::search::{DifferentialEvolution, Hybrid, Objective, Searcher};
use kalibre_core::{
    Observations, OutputInfo, Sample, Snapshot, Surrogate, SurrogateObjective, TrainingSet,
};
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::surrogate::*;
use kalibre_dc::ParamLayout;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

/// `sum (x - 0.3)^2`: measures a searcher's own work at a given dimension.
struct Quadratic(usize);

impl Objective for Quadratic {
    fn dim(&self) -> usize {
        self.0
    }
    fn cost(&self, x: &[f64]) -> f64 {
        x.iter().map(|v| (v - 0.3) * (v - 0.3)).sum()
    }
    fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
        (self.cost(x), x.iter().map(|v| 2.0 * (v - 0.3)).collect())
    }
}

struct Setup {
    hall: Hall,
    scenarios: Vec<OperatingState>,
    samples: Vec<Sample>,
    obs: Observations<OperatingState>,
}

fn new_graph(hall: &Hall) -> ThermalGraph {
    let layout = ParamLayout::with_mode(hall, AlphaMode::PerServer, &[]).unwrap();
    ThermalGraph::new(hall, layout, ThermalGraphSettings::default()).unwrap()
}

fn setup() -> Setup {
    let hall = surrogate_fixture::hall(surrogate_fixture::HALL_A, AlphaMode::PerServer);
    let scenarios = vec![surrogate_fixture::state(&hall, "t0", 1)];
    let g = new_graph(&hall);
    let space = g.layout().space().clone();
    let d = space.dim();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
    let noise = Normal::new(0.0, 0.05).unwrap();
    // Physically shaped outputs: the CRAC mix plus about 1.76 / alpha K in the hot aisle.
    let outputs = |p: &[f64]| {
        let (xc, xh) = g.hidden(&scenarios[0], p).unwrap();
        let hot = g.hot_mask();
        (0..xc.len())
            .map(|k| xc[k] + if hot[k] { 1.757 / 300.0 * xh[k] } else { 0.0 })
            .collect::<Vec<f64>>()
    };
    let mut samples = Vec::new();
    for base in [0.0f64, 1.0, 0.5] {
        for c in 0..16 {
            let u: Vec<f64> = (0..d)
                .map(|_| {
                    if c == 0 {
                        base
                    } else {
                        (base + noise.sample(&mut rng)).clamp(0.0, 1.0)
                    }
                })
                .collect();
            let p = space.from_unit(&u).unwrap();
            samples.push(Sample {
                snapshot: 0,
                outputs: outputs(&p),
                params: p,
                weight: 1.0,
            });
        }
    }
    let truth: Vec<f64> = (0..d).map(|_| rng.random_range(0.1..0.25)).collect();
    let obs = Observations::new(
        hall.sensors
            .iter()
            .map(|s| OutputInfo {
                name: s.id.clone(),
                group: s.aisle.as_str().into(),
            })
            .collect(),
        vec![Snapshot {
            label: "t0".into(),
            scenario: scenarios[0].clone(),
            measured: outputs(&truth)
                .into_iter()
                .map(|v| Some(v + rng.random_range(-0.2..0.2)))
                .collect(),
        }],
    )
    .unwrap();
    Setup {
        hall,
        scenarios,
        samples,
        obs,
    }
}

/// The search objective an iteration builds on the fitted graph.
#[derive(Clone, Copy)]
enum Path {
    /// The specialised `ThermalGraphObjective`.
    Specialised,
    /// The generic `SurrogateObjective`, the one the calibration loop searches (through
    /// `Surrogate::predict`/`vjp` and the penalty as a `Regularizer`).
    Loop,
}

/// One loop iteration's surrogate work: refit the graph (built once per calibration, as
/// the loop does), build the search objective on it, search.
fn iteration(
    s: &Setup,
    g: &mut ThermalGraph,
    pen: &TemperatureRisePenalty,
    searcher: &dyn Searcher,
    path: Path,
) -> (f64, usize) {
    g.fit(
        TrainingSet {
            scenarios: &s.scenarios,
            samples: &s.samples,
        },
        0,
    )
    .unwrap();
    let g: &ThermalGraph = g;
    let space = g.layout().space();
    let start = space.to_unit(&space.initial()).unwrap();
    let out = match path {
        Path::Specialised => {
            let obj = ThermalGraphObjective::new(g, &s.obs)
                .unwrap()
                .with_penalty(pen);
            searcher.search(&obj, &start, 7)
        }
        Path::Loop => {
            let obj = SurrogateObjective::new(g, &s.obs, space).with_regularizer(pen, 1.0);
            searcher.search(&obj, &start, 7)
        }
    }
    .unwrap();
    (out.best_cost, out.evaluations)
}

/// Median wall time (ms) over `reps` runs.
fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut wall: Vec<f64> = (0..reps)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    wall.sort_by(f64::total_cmp);
    wall[reps / 2]
}

fn print_figures(s: &Setup) {
    let mut g = new_graph(&s.hall);
    let fit_ms = median_ms(11, || {
        g.fit(
            TrainingSet {
                scenarios: &s.scenarios,
                samples: &s.samples,
            },
            0,
        )
        .unwrap();
    });
    let pen = TemperatureRisePenalty::new(
        &s.hall,
        g.layout(),
        &s.scenarios,
        PenaltySettings::default(),
    )
    .unwrap();
    let obj = ThermalGraphObjective::new(&g, &s.obs)
        .unwrap()
        .with_penalty(&pen);
    let space = g.layout().space();
    let u = space.to_unit(&space.initial()).unwrap();
    let evals_ms = median_ms(5, || {
        for _ in 0..1000 {
            black_box(obj.cost(black_box(&u)));
        }
        for _ in 0..100 {
            black_box(obj.cost_and_gradient(black_box(&u)));
        }
    });
    let generic = SurrogateObjective::new(&g, &s.obs, space).with_regularizer(&pen, 1.0);
    let generic_ms = median_ms(3, || {
        for _ in 0..1000 {
            black_box(generic.cost(black_box(&u)));
        }
        for _ in 0..100 {
            black_box(generic.cost_and_gradient(black_box(&u)));
        }
    });
    let hybrid = Hybrid::default();
    let full_de = Hybrid::default().with_de(
        DifferentialEvolution::default()
            .to_builder()
            .with_give_up_after(None)
            .build()
            .unwrap(),
    );
    let mut ev = (0, 0);
    let mut g2 = new_graph(&s.hall);
    let it_ms = median_ms(7, || {
        ev.0 = iteration(s, &mut g2, &pen, &hybrid, Path::Specialised).1
    });
    let it_full_ms = median_ms(5, || {
        ev.1 = iteration(s, &mut g2, &pen, &full_de, Path::Specialised).1
    });
    let mut ev_generic = (0, 0);
    let it_generic_ms = median_ms(7, || {
        ev_generic.0 = iteration(s, &mut g2, &pen, &hybrid, Path::Loop).1
    });
    let it_generic_full_ms = median_ms(5, || {
        ev_generic.1 = iteration(s, &mut g2, &pen, &full_de, Path::Loop).1
    });
    println!(
        "thermal graph at hall-a size, alpha per server ({} parameters), one snapshot, 48 samples",
        space.dim()
    );
    println!(
        "  adjacency nnz: Wss {}, Wcs {}; objective rows merged entries {}",
        g.adjacency().ss.nnz(),
        g.adjacency().cs.nnz(),
        obj.nnz()
    );
    // The searchers' own cost: the same searches on a trivial objective of equal size.
    let quad = Quadratic(space.dim());
    let mut qe = (0, 0);
    let q_ms = median_ms(7, || {
        qe.0 = hybrid.search(&quad, &u, 7).unwrap().evaluations
    });
    let q_full_ms = median_ms(5, || {
        qe.1 = full_de.search(&quad, &u, 7).unwrap().evaluations
    });
    let show = |what: &str, wall: f64| {
        println!("  {what:<68} {wall:8.3} ms");
    };
    println!(
        "  (median wall time of repeated runs; load average {})",
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .split_whitespace()
            .next()
            .unwrap_or("?")
    );
    show("fit (150 epochs, fixed adjacency)", fit_ms);
    show(
        "1000 costs + 100 gradients (specialised objective)",
        evals_ms,
    );
    show(
        "1000 costs + 100 gradients (generic SurrogateObjective)",
        generic_ms,
    );
    show(
        &format!(
            "iteration: fit + default hybrid search ({} evaluations)",
            ev.0
        ),
        it_ms,
    );
    show(
        &format!(
            "iteration: fit + hybrid, all 100 DE generations ({} evals)",
            ev.1
        ),
        it_full_ms,
    );
    show(
        &format!(
            "loop's path (generic objective): fit + default hybrid ({} evals)",
            ev_generic.0
        ),
        it_generic_ms,
    );
    show(
        &format!(
            "loop's path (generic objective): fit + all 100 DE generations ({} evals)",
            ev_generic.1
        ),
        it_generic_full_ms,
    );
    show(
        &format!(
            "searcher alone, default hybrid, trivial objective ({} evals)",
            qe.0
        ),
        q_ms,
    );
    show(
        &format!(
            "searcher alone, all 100 DE generations, trivial objective ({} evals)",
            qe.1
        ),
        q_full_ms,
    );
    println!("  target: 15 ms per iteration");
}

fn bench(c: &mut Criterion) {
    let s = setup();
    print_figures(&s);
    let mut group = c.benchmark_group("thermal_graph_hall_a_per_server");
    group.sample_size(10);
    group.bench_function("fit", |b| {
        let mut g = new_graph(&s.hall);
        b.iter(|| {
            g.fit(
                TrainingSet {
                    scenarios: &s.scenarios,
                    samples: &s.samples,
                },
                0,
            )
            .unwrap()
        })
    });
    let hybrid = Hybrid::default();
    let mut g = new_graph(&s.hall);
    let pen = TemperatureRisePenalty::new(
        &s.hall,
        g.layout(),
        &s.scenarios,
        PenaltySettings::default(),
    )
    .unwrap();
    group.bench_function("iteration_fit_and_hybrid_search", |b| {
        b.iter(|| iteration(&s, &mut g, &pen, &hybrid, Path::Specialised))
    });
    group.bench_function("iteration_generic_objective", |b| {
        b.iter(|| iteration(&s, &mut g, &pen, &hybrid, Path::Loop))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
