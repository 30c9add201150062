//! A user's surrogate or prior that breaks the loop's contract (a prediction of another
//! length, a NaN, a gradient of another length) stops the calibration with an error
//! that says so, rather than a search that reads every point as bad and ends quietly.

mod common;

use common::*;
use kalibre_core::{Calibrator, FitSummary, Regularizer, Surrogate, TrainingSet};

/// The quadratic surface with its prediction or gradient broken after fitting.
#[derive(Clone, Copy)]
enum Break {
    ShortPrediction,
    NanPrediction,
    EmptyGradient,
}

struct Broken {
    inner: QuadSurface,
    how: Break,
}

impl Surrogate for Broken {
    type Scenario = Scen;
    fn fit(&mut self, data: TrainingSet<'_, Scen>, seed: u64) -> kalibre_core::Result<FitSummary> {
        self.inner.fit(data, seed)
    }
    fn predict(&self, scenario: &Scen, params: &[f64]) -> Vec<f64> {
        let mut p = self.inner.predict(scenario, params);
        match self.how {
            Break::ShortPrediction => {
                p.pop();
            }
            Break::NanPrediction => p[0] = f64::NAN,
            Break::EmptyGradient => {}
        }
        p
    }
    fn vjp(&self, scenario: &Scen, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        match self.how {
            Break::EmptyGradient => Vec::new(),
            _ => self.inner.vjp(scenario, params, cotangent),
        }
    }
}

#[test]
fn a_surrogate_that_breaks_the_contract_stops_the_loop_by_name() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let cases = [
        (Break::ShortPrediction, "predicts 3 values for 4 outputs"),
        (Break::NanPrediction, "predicts NaN for output"),
        (Break::EmptyGradient, "gives a gradient of 0 values, not 2"),
    ];
    for (how, want) in cases {
        let surrogate = Broken {
            inner: QuadSurface::default(),
            how,
        };
        let e = Calibrator::new(&model, surrogate, &obs, &space)
            .with_seed(1)
            .with_max_iterations(3)
            .run()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("the surrogate, fitted at iteration 1,") && e.contains(want),
            "{want}: {e}"
        );
    }
}

struct NanPrior;
impl Regularizer for NanPrior {
    fn value_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
        (f64::NAN, vec![0.0; p.len()])
    }
}

#[test]
fn a_prior_that_gives_nan_stops_the_loop_by_name() {
    let (model, obs, space) = (Poly::new(), observations(), space());
    let e = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_seed(1)
        .with_max_iterations(3)
        .with_regularizer(&NanPrior, 1.0)
        .run()
        .unwrap_err()
        .to_string();
    assert!(e.contains("the prior (regulariser) gives NaN"), "{e}");
}
