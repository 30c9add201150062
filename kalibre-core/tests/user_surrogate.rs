//! A user's surrogate or prior that breaks the loop's contract (a prediction of another
//! length, a NaN, a gradient of another length) stops the calibration with an error
//! that says so, rather than a search that reads every point as bad and ends quietly.

mod common;

use common::*;
use kalibre_core::{
    Calibrator, FitSummary, Hybrid, Objective, Regularizer, Searcher, Surrogate,
    SurrogateObjective, TrainingSet,
};

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

/// The model itself, 1 above it at every output, where `a <= 2`; beyond, the measured
/// values exactly but one output short: a point there fits perfectly only if the missing
/// output is dropped.
struct ShortBeyond;

impl Surrogate for ShortBeyond {
    type Scenario = Scen;
    fn fit(&mut self, _: TrainingSet<'_, Scen>, _: u64) -> kalibre_core::Result<FitSummary> {
        Ok(FitSummary::default())
    }
    fn predict(&self, scenario: &Scen, params: &[f64]) -> Vec<f64> {
        if params[0] > 2.0 {
            let mut p = poly_outputs(scenario.load, &TRUTH);
            p.pop();
            return p;
        }
        let p = poly_outputs(scenario.load, params);
        p.into_iter().map(|v| v + 1.0).collect()
    }
    fn vjp(&self, scenario: &Scen, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        let (l, a, b) = (scenario.load, params[0], params[1]);
        if a > 2.0 {
            return vec![0.0; 2];
        }
        let (da, db) = ([l, b, -1.0, a], [1.0, a, 2.0 * l * b, 0.0]);
        let dot = |d: [f64; 4]| d.iter().zip(cotangent).map(|(d, c)| d * c).sum();
        vec![dot(da), dot(db)]
    }
}

/// The search reads a prediction one output short as a bad point (as a NaN), never as a
/// perfect fit of the outputs it has.
#[test]
fn a_short_prediction_is_a_bad_point_for_the_search() {
    let (obs, space) = (observations(), space());
    let objective = SurrogateObjective::new(&ShortBeyond, &obs, &space);
    // a = 3, b = 1.2: beyond, where the prediction is short.
    let beyond = space.to_unit(&[3.0, 1.2]).unwrap();
    assert!(
        objective.cost(&beyond).is_nan(),
        "{}",
        objective.cost(&beyond)
    );
    let (cost, grad) = objective.cost_and_gradient(&beyond);
    assert!(cost.is_nan() && grad.len() == 2, "{cost} {grad:?}");
    assert!(objective.data_mse(&[3.0, 1.2]).is_nan());
    // Within, every output is 1 off: cost 1.
    let within = space.to_unit(&TRUTH).unwrap();
    assert!((objective.cost(&within) - 1.0).abs() < 1e-12);
    // Started beyond, the search ends within (where the offset costs something; a
    // perfect fit beyond cost 0 before).
    let found = Hybrid::default().search(&objective, &beyond, 3).unwrap();
    let (a, cost) = (
        space.from_unit(&found.best_unit).unwrap()[0],
        found.best_cost,
    );
    assert!(
        a <= 2.0 && cost.is_finite() && cost > 0.0,
        "a {a}, cost {cost}"
    );
}
