//! The same seed gives bit-identical results with 1 and with 2 threads.

mod common;

use common::*;
use kalibre_core::{Calibrator, Report};

fn calibrate_with_threads(threads: usize, seed: u64) -> Report {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (model, obs, space) = (Poly::new(), observations(), space());
        let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
            .with_seed(seed)
            .with_max_iterations(5)
            .with_max_parallel_runs(threads)
            .run()
            .unwrap();
        report
    })
}

#[test]
fn same_seed_same_bits_at_one_and_two_threads() {
    let one = calibrate_with_threads(1, 42);
    let two = calibrate_with_threads(2, 42);
    assert_eq!(best_bits(&one), best_bits(&two));
    // Everything but the timings and the thread setting itself.
    let mut two_as_one = without_timings(&two);
    two_as_one.settings.max_parallel_runs = Some(1);
    assert_eq!(without_timings(&one), two_as_one);
    let bits = |r: &Report| -> Vec<u64> {
        r.history
            .iter()
            .flat_map(|h| h.params.values())
            .chain(r.history.iter().map(|h| h.search_loss))
            .map(f64::to_bits)
            .collect()
    };
    assert_eq!(bits(&one), bits(&two));
}

/// `with_settings` keeps what the `with_*` calls set, whichever comes first: a seed given
/// before the settings is not silently reset to the settings' own.
#[test]
fn with_calls_hold_whichever_order_they_come_in() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let run = |seed_first: bool| {
        let base = Calibrator::new(&model, QuadSurface::default(), &obs, &space);
        let mut c = if seed_first {
            base.with_seed(42)
                .with_max_iterations(3)
                .with_settings(kalibre_core::Settings::recommended())
        } else {
            base.with_settings(kalibre_core::Settings::recommended())
                .with_seed(42)
                .with_max_iterations(3)
        };
        without_timings(&c.run().unwrap())
    };
    let (first, last) = (run(true), run(false));
    assert_eq!(first.settings.seed, 42);
    assert_eq!(first.settings.max_iterations, 3);
    assert_ne!(kalibre_core::Settings::recommended().seed, 42);
    assert_eq!(first, last);
}
