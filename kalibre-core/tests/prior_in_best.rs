//! Judging the best run with the prior (`Settings::prior_in_best`): the loop's best is the
//! run with the lowest score plus weighted prior, and the report names the lower-score
//! run it passed over; without it, the best is the lowest score and the report says
//! nothing of the prior.

mod common;

use common::*;
use kalibre_core::{Calibrator, Regularizer, Report, Settings};

/// A prior that rules out the truth (a = 1.7) and the design's midpoint (a = 2): 10 per
/// unit of `a` above 0.3.
struct ACap;
impl Regularizer for ACap {
    fn value_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
        let over = (p[0] - 0.3).max(0.0);
        (10.0 * over, vec![if over > 0.0 { 10.0 } else { 0.0 }, 0.0])
    }
}

fn calibrate(prior_in_best: bool) -> Report {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_settings(Settings {
            seed: 5,
            max_iterations: 8,
            prior_in_best,
            ..Settings::default()
        })
        .with_regularizer(&ACap, 1.0)
        .run()
        .unwrap();
    report
}

fn prior_at(r: &kalibre_core::calibrate::IterationRecord) -> f64 {
    let a = r.params.get("a").unwrap();
    ACap.value(&[a, 0.0])
}

#[test]
fn the_best_run_is_the_lowest_score_plus_prior() {
    let r = calibrate(true);
    let prior = r.best.prior.expect("the prior judges the best run");
    let a = r.best.params.get("a").unwrap();
    assert!((prior - ACap.value(&[a, 0.0])).abs() < 1e-9);
    // No complete run in the history ranks lower than the best.
    for h in r.history.iter().filter(|h| h.failed_runs == 0) {
        let mae = h.mae_c.unwrap();
        assert!(
            r.best.mae_c + prior <= mae + prior_at(h) + 1e-12,
            "iteration {}: {mae} + {} beats the best {} + {prior}",
            h.iteration,
            prior_at(h),
            r.best.mae_c
        );
    }
    // The truth lies beyond the cap, so a run nearer it has a lower MAE: passed over.
    let lowest = r
        .history
        .iter()
        .filter_map(|h| h.mae_c)
        .fold(f64::INFINITY, f64::min);
    if lowest < r.best.mae_c {
        let p = r
            .best
            .passed_over
            .as_ref()
            .expect("a lower MAE was passed over");
        assert!(p.score <= lowest + 1e-12);
        assert!(p.score + p.prior > r.best.mae_c + prior);
    }
    // It round-trips through JSON with the new keys.
    let json = serde_json::to_string(&r).unwrap();
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back.best, r.best);
}

#[test]
fn without_it_the_best_run_is_the_lowest_score() {
    let r = calibrate(false);
    assert!(r.best.prior.is_none() && r.best.passed_over.is_none());
    for h in r.history.iter().filter_map(|h| h.mae_c) {
        assert!(r.best.mae_c <= h + 1e-12);
    }
    let json = serde_json::to_string(&r).unwrap();
    assert!(!json.contains("passed_over") && !json.contains("\"prior\""));
}

#[test]
fn with_it_a_lower_error_the_prior_rules_out_is_passed_over() {
    let (with, without) = (calibrate(true), calibrate(false));
    let a = |r: &Report| r.best.params.get("a").unwrap();
    // Without it the best run is a design run the prior rules out (the midpoint, a = 2),
    // and the search, which minimises misfit plus prior, never beats its MAE.
    assert!(
        ACap.value(&[a(&without), 0.0]) > 1.0,
        "without: a = {}",
        a(&without)
    );
    // With it the best run keeps within the cap, and the report names the one it passed.
    assert!(
        ACap.value(&[a(&with), 0.0]) < 1e-6,
        "with: a = {}",
        a(&with)
    );
    let p = with
        .best
        .passed_over
        .as_ref()
        .expect("the design run was passed over");
    assert!((p.score - without.best.mae_c).abs() < 1e-12);
    assert!(p.score < with.best.mae_c && p.prior > 1.0);
}
