//! Where the uncertainty's slopes come from: the model's own, when its runs measure them,
//! else the last fitted surrogate's.
//!
//! The surrogate's slopes are only as good as its form. On a model whose outputs the
//! surrogate cannot follow (a thermal graph trained on OpenFOAM runs) they can be several
//! times too flat, and a parameter the model's runs pin down to a few percent came out at
//! +/-100-280 %. The model's runs say it directly, in order of preference:
//! 1. the polish stage's finite-difference Jacobian, when it was taken at (or next to) the
//!    best run;
//! 2. a local linear fit of the loop's runs around the best run, when enough of them lie
//!    near it and spread in every direction;
//! 3. otherwise the surrogate's, by central differences.

use serde::{Deserialize, Serialize};

use super::robust::measured_rows;
use super::state::{BestPoint, State};
use crate::linalg::{cholesky, cholesky_solve};
use crate::{Observations, ParamSpace, Surrogate};

/// The polish's Jacobian stands for the best run's when taken this close to it (max norm,
/// unit box): two of its finite-difference steps.
const POLISH_SLOPES_MAX_DISTANCE: f64 = 0.02;
/// Width of the Gaussian weight of a run in the local fit (max-norm distance from the
/// best run, unit box): the loop's default trust region.
const LOCAL_FIT_WIDTH: f64 = 0.1;
/// The runs near the best must spread at least this much (weighted standard deviation,
/// unit box) in every direction, a tenth of the width, or the fit's slopes are noise.
const LOCAL_FIT_MIN_SPREAD: f64 = 0.01;
/// Central-difference step of the surrogate's slopes, unit box.
const SURROGATE_STEP_UNIT: f64 = 1e-3;

/// Which slopes the report's uncertainty was computed with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UncertaintySlopes {
    /// The polish stage's finite differences of the model, next to the best run.
    ModelFiniteDifferences,
    /// A weighted linear fit of the model's runs around the best run.
    ModelRuns,
    /// The last fitted surrogate's, by central differences.
    Surrogate,
}

impl UncertaintySlopes {
    /// A short description for reports and the CLI.
    pub fn describe(self) -> &'static str {
        match self {
            UncertaintySlopes::ModelFiniteDifferences => {
                "the model's finite differences (the polish steps)"
            }
            UncertaintySlopes::ModelRuns => "a local linear fit of the model's runs",
            UncertaintySlopes::Surrogate => "the surrogate's slopes",
        }
    }
}

/// The model linearised by finite differences at `unit`: one column per parameter, the
/// change of every measured output per unit-box step (rows as [`measured_rows`]).
pub(crate) struct ModelJacobian {
    pub unit: Vec<f64>,
    pub columns: Vec<Vec<f64>>,
    /// Every difference ran (a failed one leaves a zero column, not a slope).
    pub complete: bool,
}

/// The Jacobian's columns at `best` and where they come from; `None` when none is finite.
pub(crate) fn slopes_at<Su: Surrogate>(
    best: &BestPoint,
    polish: Option<&ModelJacobian>,
    state: &State,
    surrogate: &Su,
    obs: &Observations<Su::Scenario>,
    space: &ParamSpace,
) -> Option<(Vec<Vec<f64>>, UncertaintySlopes)> {
    if let Some(j) = polish
        .filter(|j| j.complete && max_distance(&j.unit, &best.unit) <= POLISH_SLOPES_MAX_DISTANCE)
    {
        return Some((j.columns.clone(), UncertaintySlopes::ModelFiniteDifferences));
    }
    if let Some(cols) = local_fit(state, obs, &best.unit) {
        return Some((cols, UncertaintySlopes::ModelRuns));
    }
    surrogate_slopes(surrogate, obs, space, &best.unit).map(|c| (c, UncertaintySlopes::Surrogate))
}

fn max_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Weighted least squares of every measured output on `[1, u - u_best]` over the runs
/// that ran at every snapshot, each weighed `exp(-d^2 / 2 w^2)` by its max-norm distance
/// `d` from the best run. `None` unless the weighted runs count at least `2 (dim + 1)`
/// (Kish's effective number) and spread at least [`LOCAL_FIT_MIN_SPREAD`] in every
/// direction.
pub(crate) fn local_fit<S>(
    state: &State,
    obs: &Observations<S>,
    best_unit: &[f64],
) -> Option<Vec<Vec<f64>>> {
    let d = best_unit.len();
    let k = d + 1;
    let points: Vec<(Vec<f64>, f64, Vec<f64>)> = state
        .ok_units
        .iter()
        .zip(&state.ok_runs)
        .map(|(u, (_, outputs))| {
            let du: Vec<f64> = u.iter().zip(best_unit).map(|(a, b)| a - b).collect();
            let dist = du.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let w = (-0.5 * (dist / LOCAL_FIT_WIDTH).powi(2)).exp();
            (
                du,
                w,
                measured_rows(obs, outputs)
                    .map(|(_, _, y)| y)
                    .collect::<Vec<f64>>(),
            )
        })
        .filter(|(_, w, _)| *w > 1e-12)
        .collect();
    let (sw, sw2) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (_, w, _)| (a + w, b + w * w));
    if sw <= 0.0 || sw * sw / sw2 < 2.0 * k as f64 {
        return None;
    }
    // Spread: the weighted covariance of the offsets minus s^2 I must stay positive
    // definite (its smallest eigenvalue above s^2).
    let mean: Vec<f64> = (0..d)
        .map(|i| points.iter().map(|(du, w, _)| w * du[i]).sum::<f64>() / sw)
        .collect();
    let mut cov = vec![0.0; d * d];
    for (du, w, _) in &points {
        for i in 0..d {
            for j in 0..=i {
                cov[i * d + j] += w * (du[i] - mean[i]) * (du[j] - mean[j]) / sw;
            }
        }
    }
    for i in 0..d {
        for j in 0..i {
            cov[j * d + i] = cov[i * d + j];
        }
        cov[i * d + i] -= LOCAL_FIT_MIN_SPREAD * LOCAL_FIT_MIN_SPREAD;
    }
    cholesky(&cov, d)?;
    // Normal equations of the weighted fit, one right-hand side per output row.
    let rows = points.first()?.2.len();
    let mut xtx = vec![0.0; k * k];
    let mut xty = vec![vec![0.0; rows]; k];
    for (du, w, y) in &points {
        if y.len() != rows {
            return None;
        }
        let x: Vec<f64> = std::iter::once(1.0).chain(du.iter().copied()).collect();
        for a in 0..k {
            for b in 0..k {
                xtx[a * k + b] += w * x[a] * x[b];
            }
            for (acc, v) in xty[a].iter_mut().zip(y) {
                *acc += w * x[a] * v;
            }
        }
    }
    let chol = cholesky(&xtx, k)?;
    let mut columns = vec![vec![0.0; rows]; d];
    for r in 0..rows {
        let rhs: Vec<f64> = (0..k).map(|a| xty[a][r]).collect();
        let beta = cholesky_solve(&chol, k, &rhs);
        for i in 0..d {
            columns[i][r] = beta[i + 1];
        }
    }
    columns
        .iter()
        .all(|c| c.iter().all(|v| v.is_finite()))
        .then_some(columns)
}

/// The surrogate's Jacobian at `unit`, by central differences in the unit box.
pub(crate) fn surrogate_slopes<Su: Surrogate>(
    surrogate: &Su,
    obs: &Observations<Su::Scenario>,
    space: &ParamSpace,
    unit: &[f64],
) -> Option<Vec<Vec<f64>>> {
    let predict = |unit: &[f64]| -> Option<Vec<f64>> {
        let params = space.from_unit(unit).ok()?;
        let mut out = Vec::new();
        for snap in obs.snapshots() {
            let pred = surrogate.predict(&snap.scenario, &params);
            if pred.len() != snap.measured.len() {
                return None;
            }
            for (o, m) in snap.measured.iter().enumerate() {
                if m.is_some() {
                    out.push(*pred.get(o)?);
                }
            }
        }
        Some(out)
    };
    let mut jac = Vec::with_capacity(unit.len());
    for i in 0..unit.len() {
        let (mut lo, mut hi) = (unit.to_vec(), unit.to_vec());
        lo[i] = (lo[i] - SURROGATE_STEP_UNIT).max(0.0);
        hi[i] = (hi[i] + SURROGATE_STEP_UNIT).min(1.0);
        let (plo, phi) = (predict(&lo)?, predict(&hi)?);
        let h = hi[i] - lo[i];
        let col: Vec<f64> = phi.iter().zip(&plo).map(|(a, b)| (a - b) / h).collect();
        if col.iter().any(|v| !v.is_finite()) {
            return None;
        }
        jac.push(col);
    }
    Some(jac)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FitSummary, OutputInfo, Scale, Snapshot, TrainingSet};

    /// A surrogate that predicts the same for every parameter: zero slopes.
    struct Flat;

    impl Surrogate for Flat {
        type Scenario = ();
        fn fit(&mut self, _: TrainingSet<'_, ()>, _: u64) -> crate::Result<FitSummary> {
            unreachable!("not trained in these tests")
        }
        fn predict(&self, _: &(), _: &[f64]) -> Vec<f64> {
            vec![0.0; 4]
        }
        fn vjp(&self, _: &(), _: &[f64], _: &[f64]) -> Vec<f64> {
            unreachable!("slopes are central differences")
        }
    }

    /// Three measured outputs of one snapshot (the middle one unmeasured, so rows skip it).
    fn observations() -> Observations<()> {
        let outputs = (0..4)
            .map(|k| OutputInfo {
                name: format!("s{k}"),
                group: "all".into(),
            })
            .collect();
        Observations::new(
            outputs,
            vec![Snapshot {
                label: "t0".into(),
                scenario: (),
                measured: vec![Some(1.0), None, Some(2.0), Some(3.0)],
            }],
        )
        .unwrap()
    }

    /// A model linear in the unit box, with a curvature term `c |u|^2` on every output.
    fn model(u: &[f64], c: f64) -> Vec<f64> {
        let q = c * (u[0] * u[0] + u[1] * u[1]);
        vec![
            2.0 * u[0] - u[1] + q,
            7.0,
            0.5 * u[0] + 3.0 * u[1] + q,
            -u[0] + q,
        ]
    }

    fn state_with(points: &[[f64; 2]], c: f64) -> State<'static> {
        let mut st = State::default();
        for p in points {
            st.ok_units.push(p.to_vec());
            st.ok_runs.push((p.to_vec(), vec![model(p, c)]));
        }
        st
    }

    /// Points around `centre` on a small star and a diagonal cross: spread in both
    /// directions.
    fn cloud(centre: [f64; 2], r: f64) -> Vec<[f64; 2]> {
        let mut v = vec![centre];
        for (a, b) in [
            (1.0, 0.0),
            (-1.0, 0.0),
            (0.0, 1.0),
            (0.0, -1.0),
            (1.0, 1.0),
            (-1.0, -1.0),
            (1.0, -1.0),
            (-1.0, 1.0),
        ] {
            v.push([centre[0] + r * a, centre[1] + r * b]);
        }
        v
    }

    #[test]
    fn the_local_fit_recovers_a_linear_models_slopes_over_the_measured_rows() {
        let obs = observations();
        let st = state_with(&cloud([0.4, 0.6], 0.05), 0.0);
        let cols = local_fit(&st, &obs, &[0.4, 0.6]).expect("enough spread runs");
        let want = [[2.0, 0.5, -1.0], [-1.0, 3.0, 0.0]];
        for (c, w) in cols.iter().zip(want) {
            assert_eq!(c.len(), 3);
            for (a, b) in c.iter().zip(w) {
                assert!((a - b).abs() < 1e-9, "{cols:?}");
            }
        }
        // With curvature the symmetric cloud still gives the slopes at its centre.
        let st = state_with(&cloud([0.4, 0.6], 0.05), 3.0);
        let cols = local_fit(&st, &obs, &[0.4, 0.6]).unwrap();
        let grad_q = [2.0 * 3.0 * 0.4, 2.0 * 3.0 * 0.6];
        for (i, (c, w)) in cols.iter().zip(want).enumerate() {
            for (a, b) in c.iter().zip(w) {
                assert!((a - (b + grad_q[i])).abs() < 1e-6, "{cols:?}");
            }
        }
    }

    #[test]
    fn the_local_fit_refuses_runs_that_are_too_few_far_or_on_a_line() {
        let obs = observations();
        // Five runs: fewer than 2 (dim + 1) = 6 weighted ones.
        let few = state_with(&cloud([0.4, 0.6], 0.05)[..5], 0.0);
        assert!(local_fit(&few, &obs, &[0.4, 0.6]).is_none());
        // The same cloud far from the best run weighs next to nothing.
        let far = state_with(&cloud([0.9, 0.1], 0.05), 0.0);
        assert!(local_fit(&far, &obs, &[0.4, 0.6]).is_none());
        // Runs along one line (a search path) say nothing across it.
        let line: Vec<[f64; 2]> = (0..9)
            .map(|k| {
                let t = (k as f64 - 4.0) * 0.02;
                [0.4 + t, 0.6 + t]
            })
            .collect();
        assert!(local_fit(&state_with(&line, 0.0), &obs, &[0.4, 0.6]).is_none());
        // Spread under a hundredth of the box: too little to tell slopes from noise.
        let tight = state_with(&cloud([0.4, 0.6], 0.004), 0.0);
        assert!(local_fit(&tight, &obs, &[0.4, 0.6]).is_none());
    }

    #[test]
    fn the_models_slopes_come_first_and_the_surrogates_last() {
        let obs = observations();
        let space = ParamSpace::new()
            .with("p", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap()
            .with("q", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap();
        let best = BestPoint {
            iteration: 1,
            unit: vec![0.4, 0.6],
            params: vec![0.4, 0.6],
            score: 0.0,
            rank: 0.0,
            validation: Default::default(),
            outputs: vec![model(&[0.4, 0.6], 0.0)],
        };
        let fd = |unit: [f64; 2], complete| ModelJacobian {
            unit: unit.to_vec(),
            columns: vec![vec![1.0; 3], vec![2.0; 3]],
            complete,
        };
        let spread = state_with(&cloud([0.4, 0.6], 0.05), 0.0);
        let at = |j: Option<&ModelJacobian>, st: &State| {
            slopes_at(&best, j, st, &Flat, &obs, &space)
                .map(|(c, s)| ((c[0][0] * 1e9).round() / 1e9, s))
        };
        // The polish's Jacobian next to the best run wins over everything.
        let near = fd([0.41, 0.59], true);
        assert_eq!(
            at(Some(&near), &spread),
            Some((1.0, UncertaintySlopes::ModelFiniteDifferences))
        );
        // Taken far from it, or with a failed difference: the runs' local fit.
        for j in [fd([0.45, 0.6], true), fd([0.4, 0.6], false)] {
            assert_eq!(
                at(Some(&j), &spread),
                Some((2.0, UncertaintySlopes::ModelRuns))
            );
        }
        // Too few runs near it: the surrogate's (flat here).
        let few = state_with(&[[0.4, 0.6]], 0.0);
        assert_eq!(at(None, &few), Some((0.0, UncertaintySlopes::Surrogate)));
    }
}
