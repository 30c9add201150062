//! Which parameters the measurements pin down: a linearised (Gauss-Newton) standard
//! deviation per parameter at the best run, so that a report does not claim a value the
//! data cannot tell apart from its neighbours.
//!
//! The Jacobian of the outputs is the last fitted surrogate's at the best run, by central
//! differences in the unit box. (Not the output-corrected one: its linear term spreads
//! the discrepancy between runs over every coordinate they differ in, so a parameter the
//! model ignores would pick up a slope.) With
//! `J` over every measured output of every snapshot, residual variance
//! `s2 = |r|^2 / max(m - d, 1)` at the best run (noise and model error alike, so the
//! figure is conservative) and `F = J^T J / s2 + I` (the box as a prior: one standard
//! deviation per range), a parameter's standard deviation is `sqrt((F^-1)_ii)` in the
//! unit box, mapped to physical units by the scale's slope. A
//! parameter the outputs do not move, or one whose effect another parameter's can
//! replace, gets a large one. The search's regulariser (a domain prior such as the
//! rise penalty) is left out: the question is what the data say.

use serde::{Deserialize, Serialize};

use super::state::BestPoint;
use crate::search::{cholesky, cholesky_solve};
use crate::{Observations, ParamSpace, Surrogate};

/// A parameter counts as identified when one standard deviation is at most this fraction
/// of its value (or, for a value of zero, of its range).
pub const IDENTIFIED_REL_STD: f64 = 0.1;
/// Above this many parameters the uncertainty is not estimated (a dense `d x d` inverse).
pub const UNCERTAINTY_MAX_PARAMS: usize = 256;
/// One standard deviation (unit box) above which a parameter counts as free: the data
/// narrow it to less than half of what the box alone allows.
const FREE_STD_UNIT: f64 = 0.5;
/// Central-difference step in the unit box.
const STEP_UNIT: f64 = 1e-3;

/// How well the measurements determine one parameter at the best run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamUncertainty {
    /// Parameter name.
    pub name: String,
    /// Best value.
    pub value: f64,
    /// One standard deviation (physical units, linearised); none when the data leave the
    /// parameter free over more than half its range.
    pub std: Option<f64>,
    /// `std / |value|`; none when `std` is none or the value is zero.
    pub rel_std: Option<f64>,
    /// `rel_std` at most [`IDENTIFIED_REL_STD`] (for a zero value: `std` at most that
    /// fraction of the range).
    pub identified: bool,
}

/// The uncertainty of every parameter at `best`; empty when the Jacobian is not finite.
pub(crate) fn estimate<Su: Surrogate>(
    surrogate: &Su,
    obs: &Observations<Su::Scenario>,
    space: &ParamSpace,
    best: &BestPoint,
) -> Vec<ParamUncertainty> {
    let d = space.dim();
    let predict = |unit: &[f64]| -> Option<Vec<f64>> {
        let params = space.from_unit(unit).ok()?;
        let mut out = Vec::new();
        for snap in obs.snapshots() {
            let pred = surrogate.predict(&snap.scenario, &params);
            for (o, m) in snap.measured.iter().enumerate() {
                if m.is_some() {
                    out.push(*pred.get(o)?);
                }
            }
        }
        Some(out)
    };
    let mut residual = Vec::new();
    for (snap, outputs) in obs.snapshots().iter().zip(&best.outputs) {
        for (m, y) in snap.measured.iter().zip(outputs) {
            if let Some(m) = m {
                residual.push(y - m);
            }
        }
    }
    let m = residual.len();
    // Columns of J, one per parameter.
    let mut jac: Vec<Vec<f64>> = Vec::with_capacity(d);
    for i in 0..d {
        let (mut lo, mut hi) = (best.unit.clone(), best.unit.clone());
        lo[i] = (lo[i] - STEP_UNIT).max(0.0);
        hi[i] = (hi[i] + STEP_UNIT).min(1.0);
        let (Some(plo), Some(phi)) = (predict(&lo), predict(&hi)) else {
            return Vec::new();
        };
        let h = hi[i] - lo[i];
        let col: Vec<f64> = phi.iter().zip(&plo).map(|(a, b)| (a - b) / h).collect();
        if col.len() != m || col.iter().any(|v| !v.is_finite()) {
            return Vec::new();
        }
        jac.push(col);
    }
    let s2 = (residual.iter().map(|r| r * r).sum::<f64>() / m.saturating_sub(d).max(1) as f64)
        .max(1e-24); // a perfect fit: every parameter the outputs move is pinned down
    let mut fisher = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let v = jac[i].iter().zip(&jac[j]).map(|(a, b)| a * b).sum::<f64>() / s2;
            fisher[i * d + j] = v;
            fisher[j * d + i] = v;
        }
    }
    // The box as a prior (one standard deviation = the whole range) keeps the inverse
    // defined where the data say nothing; there a parameter's standard deviation comes
    // out near its range, elsewhere the data dominate.
    for i in 0..d {
        fisher[i * d + i] += 1.0;
    }
    let Some(chol) = cholesky(&fisher, d) else {
        return Vec::new();
    };
    let dphys = space.dphys_dunit(&best.unit);
    let names = space.names();
    (0..d)
        .map(|i| {
            let mut e = vec![0.0; d];
            e[i] = 1.0;
            let var_unit = cholesky_solve(&chol, d, &e)[i];
            let std_unit = var_unit.sqrt();
            let value = best.params[i];
            let std = (std_unit.is_finite() && std_unit <= FREE_STD_UNIT)
                .then(|| std_unit * dphys[i].abs());
            let rel_std = std.filter(|_| value != 0.0).map(|s| s / value.abs());
            let identified = match (rel_std, std) {
                (Some(r), _) => r <= IDENTIFIED_REL_STD,
                (None, Some(_)) => std_unit <= IDENTIFIED_REL_STD,
                _ => false,
            };
            ParamUncertainty {
                name: names[i].clone(),
                value,
                std,
                rel_std,
                identified,
            }
        })
        .collect()
}
