//! Which parameters the measurements pin down: a linearised (Gauss-Newton) standard
//! deviation per parameter at the best run, so that a report does not claim a value the
//! data cannot tell apart from its neighbours.
//!
//! The Jacobian of the outputs at the best run is the model's own where its runs measure
//! it (the polish's finite differences, or a local fit of the loop's runs), else the last
//! fitted surrogate's ([`super::slopes`]; not the output-corrected surrogate: its linear
//! term spreads the discrepancy between runs over every coordinate they differ in, so a
//! parameter the model ignores would pick up a slope). With
//! `J` over every measured output of every snapshot, residual variance
//! `s2 = |r|^2 / max(m - d, 1)` at the best run (noise and model error alike, so the
//! figure is conservative) and `F = J^T J / s2 + I` (the box as a prior: one standard
//! deviation per range), a parameter's standard deviation is `sqrt((F^-1)_ii)` in the
//! unit box, mapped to physical units by the scale's slope. A
//! parameter the outputs do not move, or one whose effect another parameter's can
//! replace, gets a large one. The search's regulariser (a domain prior such as the
//! rise penalty) is left out: the question is what the data say.
//!
//! The residual variance counts each output's residuals over the snapshots as fewer
//! independent ones when they repeat (Kish's design effect, [`Repetition`]): a model
//! error at a sensor recurs in every snapshot, and three snapshots of it are not three
//! measurements.
//!
//! A small spread is only half of a claim: the best run must also sit where the data
//! point. The Gauss-Newton step from the best run, `-F^-1 J^T r / s2` (the `shift`), says
//! how far the linearised data would move each parameter; a loop stopped before it
//! converged leaves a shift of several standard deviations along the directions it had
//! not finished, and such a parameter is not called identified however narrow its spread.
//!
//! Under a Student-t likelihood (`Settings::robust_nu`) the scale is the t's, fitted to
//! the best run's residuals, `F = k J^T J / s^2 + I` with `k = (nu + 1) / (nu + 3)` (the
//! t's Fisher information about a location), and each residual pulls the shift with its
//! IRLS weight, `J^T (w r) / s^2`.
//!
//! The model's numerics ([`super::numerical`]): each numerical variant's change of the
//! outputs `delta` moves the parameters by `-F^-1 J^T (w delta) / s2`, as a change of
//! the residuals would. The largest such move over the variants is the parameter's
//! `numerical` uncertainty; a parameter is identified only when its spread and that
//! move, combined in quadrature, stay within [`IDENTIFIED_REL_STD`].

use serde::{Deserialize, Serialize};

use super::numerical::{output_change, Numerics};
use super::robust::{measured_rows, residuals, RobustFit};
use super::state::BestPoint;
use crate::linalg::{cholesky, cholesky_solve};
use crate::{Observations, ParamSpace};

/// A parameter counts as identified when one standard deviation is at most this fraction
/// of its value (or, for a value of zero, of its range).
pub const IDENTIFIED_REL_STD: f64 = 0.1;
/// Above this many parameters the uncertainty is not estimated (a dense `d x d` inverse).
pub const UNCERTAINTY_MAX_PARAMS: usize = 256;
/// One standard deviation (unit box) above which a parameter counts as free: the data
/// narrow it to less than half of what the box alone allows.
const FREE_STD_UNIT: f64 = 0.5;
/// A parameter whose Gauss-Newton shift exceeds this many standard deviations is not at
/// the data's optimum, so its value is not claimed.
pub const CONVERGED_SHIFT_STDS: f64 = 2.0;
/// A shift within this share of the value is settled whatever the spread: a noise-free
/// fit's spread can be smaller than the model's own numerical precision, and a shift at
/// that precision says nothing about convergence.
pub const SETTLED_REL_SHIFT: f64 = 1e-4;

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
    /// How far the linearised measurements would move the value from the best run
    /// (physical units, signed; the Gauss-Newton step). Missing in older reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shift: Option<f64>,
    /// The largest move of the value that the model's numerical variants cause
    /// (physical units, absolute; `calibrate::numerical`); none without variants.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub numerical: Option<f64>,
    /// `rel_std` combined in quadrature with `numerical / |value|` at most
    /// [`IDENTIFIED_REL_STD`] (for a zero value: in fractions of the range) and the shift
    /// at most [`CONVERGED_SHIFT_STDS`] standard deviations.
    pub identified: bool,
}

impl ParamUncertainty {
    /// `shift / |value|`: how far, relative to the value, the data would move it; none
    /// without a shift or for a value of zero.
    pub fn rel_shift(&self) -> Option<f64> {
        self.shift
            .filter(|_| self.value != 0.0)
            .map(|d| d / self.value.abs())
    }

    /// `numerical / |value|`: the numerics' move relative to the value; none without
    /// variants or for a value of zero.
    pub fn rel_numerical(&self) -> Option<f64> {
        self.numerical
            .filter(|_| self.value != 0.0)
            .map(|n| n / self.value.abs())
    }

    /// Whether the best run sits where the linearised data point: the shift within
    /// [`CONVERGED_SHIFT_STDS`] standard deviations, or within [`SETTLED_REL_SHIFT`] of
    /// the value (false without a spread or a shift).
    pub fn settled(&self) -> bool {
        match (self.shift, self.std) {
            (Some(d), Some(sd)) => {
                d.abs() <= CONVERGED_SHIFT_STDS * sd
                    || d.abs() <= SETTLED_REL_SHIFT * self.value.abs()
            }
            _ => false,
        }
    }
}

/// The uncertainty of every parameter (but those fixed by equal bounds) at `best` from
/// the Jacobian's columns `jac` (one per parameter, rows as the residuals, unit box;
/// [`super::slopes`]), the residual variance scaled by `design_effect`
/// ([`Repetition::design_effect`]), with the moves that the numerical variants' outputs
/// `variant_outputs` (each per snapshot, as `best.outputs`) cause; empty when the
/// columns do not match the residuals or are not finite.
pub(crate) fn estimate<S>(
    jac: &[Vec<f64>],
    obs: &Observations<S>,
    space: &ParamSpace,
    best: &BestPoint,
    robust_nu: Option<f64>,
    design_effect: f64,
    numerics: Numerics<'_>,
) -> Vec<ParamUncertainty> {
    let Numerics {
        variant_outputs,
        weights: numerical_weights,
    } = numerics;
    let d = space.dim();
    // Model minus measurement (negation is exact: `y - m` bit for bit).
    let residual: Vec<f64> = residuals(obs, &best.outputs).iter().map(|r| -r).collect();
    let m = residual.len();
    if jac.len() != d
        || jac
            .iter()
            .any(|c| c.len() != m || c.iter().any(|v| !v.is_finite()))
    {
        return Vec::new();
    }
    // Under a Student-t: the information per row is `(nu + 1) / (nu + 3)` over its scale
    // squared, and each residual pulls with its IRLS weight.
    let robust = robust_nu.and_then(|nu| RobustFit::new(nu, &residual));
    // How strongly each row pulls: 1 under least squares, the IRLS weight over the
    // t's information factor under a Student-t.
    // With numerical weighting, each row's weight (generalised least squares: its
    // variance is `s^2 / w`) multiplies its pull and its information.
    let numerical_w: Vec<f64> = numerical_weights
        .filter(|w| w.len() == m)
        .map_or_else(|| vec![1.0; m], <[f64]>::to_vec);
    let row_pull: Vec<f64> = match &robust {
        None => numerical_w.clone(),
        Some(f) => residual
            .iter()
            .zip(&numerical_w)
            .map(|(r, w)| w * f.weight(*r) / f.information_factor())
            .collect(),
    };
    let s2_row = match &robust {
        None => (residual
            .iter()
            .zip(&numerical_w)
            .map(|(r, w)| w * r * r)
            .sum::<f64>()
            / m.saturating_sub(d).max(1) as f64)
            .max(1e-24), // a perfect fit: every parameter the outputs move is pinned down
        Some(f) => f.scale * f.scale / f.information_factor(),
    };
    // Residuals of one output over the snapshots are not independent when the model
    // errs there the same way each time: count them as fewer (the design effect).
    let s2 = s2_row * design_effect;
    let mut fisher = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let v = jac[i]
                .iter()
                .zip(&jac[j])
                .zip(&numerical_w)
                .map(|((a, b), w)| w * a * b)
                .sum::<f64>()
                / s2;
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
    // `F^-1 J^T (w v) / s2`: how far a change `v` of the residuals moves the parameters
    // (unit box, up to sign).
    let step_for = |v: &[f64]| -> Vec<f64> {
        let g: Vec<f64> = jac
            .iter()
            .map(|col| {
                col.iter()
                    .zip(v)
                    .zip(&row_pull)
                    .map(|((j, x), w)| j * w * x)
                    .sum::<f64>()
                    / s2
            })
            .collect();
        cholesky_solve(&chol, d, &g)
    };
    // The Gauss-Newton step toward where the linearised data point.
    let shift_unit = step_for(&residual);
    // Each variant's change of the outputs moves the parameters as a change of the
    // residuals would; the largest move (unit box) per parameter counts.
    let mut numerical_unit: Option<Vec<f64>> = None;
    for outputs in variant_outputs {
        let change = output_change(obs, outputs, &best.outputs);
        if change.len() != m || change.iter().any(|c| !c.is_finite()) {
            continue;
        }
        let step = step_for(&change);
        let acc = numerical_unit.get_or_insert_with(|| vec![0.0; d]);
        for (a, s) in acc.iter_mut().zip(&step) {
            *a = a.max(s.abs());
        }
    }
    let dphys = space.dphys_dunit(&best.unit);
    let names = space.names();
    // A parameter fixed by equal bounds is given, not estimated: no spread to claim.
    (0..d)
        .filter(|&i| !space.params()[i].is_fixed())
        .map(|i| {
            let mut e = vec![0.0; d];
            e[i] = 1.0;
            let var_unit = cholesky_solve(&chol, d, &e)[i];
            let std_unit = var_unit.sqrt();
            let value = best.params[i];
            let std = (std_unit.is_finite() && std_unit <= FREE_STD_UNIT)
                .then(|| std_unit * dphys[i].abs());
            let rel_std = std.filter(|_| value != 0.0).map(|s| s / value.abs());
            let shift = -shift_unit[i] * dphys[i];
            let num_unit = numerical_unit.as_ref().map_or(0.0, |n| n[i]);
            let numerical = numerical_unit
                .as_ref()
                .map(|n| n[i] * dphys[i].abs())
                .filter(|n| n.is_finite());
            let rel_num = if value != 0.0 {
                numerical.map_or(0.0, |n| n / value.abs())
            } else {
                num_unit
            };
            let narrow = match (rel_std, std) {
                (Some(r), _) => r.hypot(rel_num) <= IDENTIFIED_REL_STD,
                (None, Some(_)) => std_unit.hypot(num_unit) <= IDENTIFIED_REL_STD,
                _ => false,
            };
            let mut u = ParamUncertainty {
                name: names[i].clone(),
                value,
                std,
                rel_std,
                shift: shift.is_finite().then_some(shift),
                numerical,
                identified: false,
            };
            u.identified = narrow && u.settled();
            u
        })
        .collect()
}

/// Above this intra-class correlation most of the best run's residual repeats at the
/// same outputs in every snapshot: a model error the parameters cannot absorb, which
/// biases them beyond their spreads. Reports say so.
pub const REPEATED_RESIDUAL_ICC: f64 = 0.5;

/// How much of a residual repeats at the same outputs over the snapshots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Repetition {
    /// One-way ANOVA intra-class correlation of the residuals grouped by output, in [0, 1].
    pub icc: f64,
    /// The ANOVA's mean group size (the snapshots per output).
    pub n0: f64,
}

impl Repetition {
    /// Kish's design effect `1 + (n0 - 1) icc`: 1 for independent residuals (noise), up to
    /// the number of snapshots when each output's residual repeats in every snapshot (a
    /// model error the parameters cannot remove), so that the spread is not claimed as if
    /// every snapshot were a fresh measurement of it.
    pub fn design_effect(&self) -> f64 {
        1.0 + (self.n0 - 1.0).max(0.0) * self.icc
    }
}

/// The repetition of the residuals of `outputs` (per snapshot) grouped by output; `None`
/// with fewer than two outputs, no output measured twice, or no spread.
pub(crate) fn repetition<S>(obs: &Observations<S>, outputs: &[Vec<f64>]) -> Option<Repetition> {
    let mut groups: Vec<Vec<f64>> = vec![Vec::new(); obs.outputs().len()];
    let mut residual = Vec::new();
    for (o, m, p) in measured_rows(obs, outputs) {
        groups[o].push(m - p);
        residual.push(m - p);
    }
    groups.retain(|g| !g.is_empty());
    let n = residual.len() as f64;
    let c = groups.len() as f64;
    if groups.len() < 2 || n <= c {
        return None;
    }
    let grand = residual.iter().sum::<f64>() / n;
    let (mut ssb, mut ssw, mut sum_n2) = (0.0, 0.0, 0.0);
    for g in &groups {
        let k = g.len() as f64;
        let mean = g.iter().sum::<f64>() / k;
        ssb += k * (mean - grand).powi(2);
        ssw += g.iter().map(|r| (r - mean).powi(2)).sum::<f64>();
        sum_n2 += k * k;
    }
    let (msb, msw) = (ssb / (c - 1.0), ssw / (n - c));
    let n0 = (n - sum_n2 / n) / (c - 1.0);
    let denom = msb + (n0 - 1.0) * msw;
    if denom.is_nan() || denom <= 0.0 {
        return None;
    }
    Some(Repetition {
        icc: ((msb - msw) / denom).clamp(0.0, 1.0),
        n0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FitSummary, OutputInfo, Scale, Snapshot, Surrogate, TrainingSet};

    /// The numerics of variants alone (no row weights).
    fn only(variant_outputs: &[Vec<Vec<f64>>]) -> Numerics<'_> {
        Numerics {
            variant_outputs,
            weights: None,
        }
    }

    /// `y_k = sum_i J_ki * u_i` in the unit box: a surrogate whose slopes are the model's.
    struct Linear {
        jac: Vec<[f64; 2]>,
    }

    impl Surrogate for Linear {
        type Scenario = ();
        fn fit(&mut self, _: TrainingSet<'_, ()>, _: u64) -> crate::Result<FitSummary> {
            unreachable!("not trained in these tests")
        }
        fn predict(&self, _: &(), params: &[f64]) -> Vec<f64> {
            // The space below is the unit box, so params are unit coordinates.
            self.jac
                .iter()
                .map(|j| j[0] * params[0] + j[1] * params[1])
                .collect()
        }
        fn vjp(&self, _: &(), _: &[f64], _: &[f64]) -> Vec<f64> {
            unreachable!("the estimate differentiates by central differences")
        }
    }

    /// 40 outputs that both parameters move, measured at `truth` with +-0.01 of noise.
    fn setup(truth: [f64; 2]) -> (Linear, Observations<()>, ParamSpace) {
        let jac: Vec<[f64; 2]> = (0..40)
            .map(|k| {
                let t = k as f64 / 40.0;
                [1.0 + t, 2.0 - 1.5 * t]
            })
            .collect();
        let surrogate = Linear { jac };
        let noise = |k: usize| if k.is_multiple_of(2) { 0.01 } else { -0.01 };
        let measured = surrogate
            .predict(&(), &truth)
            .iter()
            .enumerate()
            .map(|(k, y)| Some(y + noise(k)))
            .collect();
        let outputs = (0..40)
            .map(|k| OutputInfo {
                name: format!("s{k}"),
                group: "all".into(),
            })
            .collect();
        let obs = Observations::new(
            outputs,
            vec![Snapshot {
                label: "t0".into(),
                scenario: (),
                measured,
            }],
        )
        .unwrap();
        let space = ParamSpace::new()
            .with("p", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap()
            .with("q", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap();
        (surrogate, obs, space)
    }

    /// The surrogate's slopes and a best run at `unit`.
    fn linearised_at(
        s: &Linear,
        obs: &Observations<()>,
        space: &ParamSpace,
        unit: [f64; 2],
    ) -> (Vec<Vec<f64>>, BestPoint) {
        let jac = super::super::slopes::surrogate_slopes(s, obs, space, &unit).unwrap();
        let best = BestPoint {
            iteration: 1,
            unit: unit.to_vec(),
            params: unit.to_vec(),
            score: 0.0,
            rank: 0.0,
            validation: Default::default(),
            outputs: vec![s.predict(&(), &unit)],
        };
        (jac, best)
    }

    /// The estimate from the surrogate's slopes with the best run at `unit`.
    fn estimate_at(
        s: &Linear,
        obs: &Observations<()>,
        space: &ParamSpace,
        unit: [f64; 2],
    ) -> Vec<ParamUncertainty> {
        let (jac, best) = linearised_at(s, obs, space, unit);
        estimate(&jac, obs, space, &best, None, 1.0, Numerics::default())
    }

    #[test]
    fn a_best_run_at_the_data_optimum_is_claimed_with_a_small_shift() {
        let (s, obs, space) = setup([0.6, 0.4]);
        let u = estimate_at(&s, &obs, &space, [0.6, 0.4]);
        assert_eq!(u.len(), 2);
        for p in &u {
            let (std, shift) = (p.std.unwrap(), p.shift.unwrap());
            assert!(p.identified, "{p:?}");
            assert!(shift.abs() <= std, "{p:?}");
        }
    }

    #[test]
    fn a_shift_at_the_models_precision_is_settled_whatever_the_spread() {
        // A noise-free fit: the spread is 2e-6 of the value and the shift 6e-6, three
        // spreads but far below any precision the value is quoted to.
        let (s, obs, space) = setup([0.6, 0.4]);
        let mut p = estimate_at(&s, &obs, &space, [0.6, 0.4]).remove(0);
        p.std = Some(2e-6 * p.value);
        p.shift = Some(6e-6 * p.value);
        assert!(p.settled(), "{p:?}");
        p.shift = Some(2e-3 * p.value);
        assert!(!p.settled(), "{p:?}");
    }

    #[test]
    fn a_best_run_short_of_the_data_optimum_is_not_claimed_and_the_shift_points_there() {
        // Best run 0.1 short in p: the residual is no longer noise, yet the outputs still
        // pin p down to a few percent.
        let (s, obs, space) = setup([0.6, 0.4]);
        let u = estimate_at(&s, &obs, &space, [0.5, 0.4]);
        let p = &u[0];
        assert!(p.rel_std.unwrap() <= IDENTIFIED_REL_STD, "{p:?}");
        assert!(!p.identified, "{p:?}");
        // The Gauss-Newton step of a linear model lands on the optimum (up to the weak
        // box prior and the noise).
        assert!((p.value + p.shift.unwrap() - 0.6).abs() < 0.01, "{p:?}");
        assert!(p.shift.unwrap().abs() > CONVERGED_SHIFT_STDS * p.std.unwrap());
    }

    #[test]
    fn a_variant_that_moves_the_outputs_along_a_parameter_moves_it_by_that_much() {
        // A variant of the model (a finer grid, say) whose outputs at the best run are the
        // model's at p + 0.05: the numerics move p by 0.05 and q by nothing.
        let (s, obs, space) = setup([0.6, 0.4]);
        let unit = [0.6, 0.4];
        let (jac, best) = linearised_at(&s, &obs, &space, unit);
        let moved = |dp: f64| vec![s.predict(&(), &[unit[0] + dp, unit[1]])];
        let with_variants = |variant_outputs: &[Vec<Vec<f64>>]| {
            estimate(&jac, &obs, &space, &best, None, 1.0, only(variant_outputs))
        };
        let u = with_variants(&[moved(0.05)]);
        let (p, q) = (&u[0], &u[1]);
        assert!((p.numerical.unwrap() - 0.05).abs() < 0.002, "{p:?}");
        assert!(q.numerical.unwrap() < 0.002, "{q:?}");
        // 0.05 of 0.6 is 8%: with its narrow spread p stays within 10%. Its statistics
        // and its spread are those without the variant.
        let plain = estimate(&jac, &obs, &space, &best, None, 1.0, Numerics::default());
        assert!(p.identified && q.identified, "{u:?}");
        assert_eq!((p.std, p.shift), (plain[0].std, plain[0].shift));
        assert_eq!(plain[0].numerical, None);
        // The largest of two variants counts, and 0.09 of 0.6 (15%) is not claimed.
        let u = with_variants(&[moved(0.05), moved(-0.09)]);
        assert!((u[0].numerical.unwrap() - 0.09).abs() < 0.003, "{:?}", u[0]);
        assert!(!u[0].identified && u[1].identified, "{u:?}");
        // A variant whose outputs do not match the measured rows is left out.
        let u = with_variants(&[vec![vec![0.0; 3]]]);
        assert_eq!(u[0].numerical, None);
    }

    /// Four outputs measured 0 over three snapshots, and predictions per snapshot that
    /// leave the given residual per (snapshot, output).
    fn three_snapshots(
        residual: impl Fn(usize, usize) -> f64,
    ) -> (Observations<()>, Vec<Vec<f64>>) {
        let outputs = (0..4)
            .map(|k| OutputInfo {
                name: format!("s{k}"),
                group: "all".into(),
            })
            .collect();
        let snaps = (0..3)
            .map(|t| Snapshot {
                label: format!("t{t}"),
                scenario: (),
                measured: vec![Some(0.0); 4],
            })
            .collect();
        let predicted = (0..3)
            .map(|t| (0..4).map(|o| -residual(t, o)).collect())
            .collect();
        (Observations::new(outputs, snaps).unwrap(), predicted)
    }

    fn design_effect(obs: &Observations<()>, r: &[Vec<f64>]) -> f64 {
        repetition(obs, r).map_or(1.0, |x| x.design_effect())
    }

    #[test]
    fn the_design_effect_counts_a_repeated_residual_once_and_noise_in_full() {
        // The same residual at an output in every snapshot: three rows, one measurement.
        let (obs, r) = three_snapshots(|_, o| [0.5, -1.0, 2.0, 0.1][o]);
        assert!((design_effect(&obs, &r) - 3.0).abs() < 1e-12);
        assert_eq!(repetition(&obs, &r), Some(Repetition { icc: 1.0, n0: 3.0 }));
        // Residuals that average out within each output: independent rows.
        let (obs, r) = three_snapshots(|t, o| [1.0, -1.0, 0.0][t] * (1.0 + o as f64));
        assert_eq!(design_effect(&obs, &r), 1.0);
        // Half and half: in between.
        let (obs, r) = three_snapshots(|t, o| [0.5, -1.0, 2.0, 0.1][o] + [0.3, -0.3, 0.0][t]);
        let deff = design_effect(&obs, &r);
        assert!(deff > 1.0 && deff < 3.0, "{deff}");
        // One snapshot: nothing repeats.
        let (_, obs, _) = setup([0.6, 0.4]);
        let one = [vec![0.3; 40]];
        assert_eq!(design_effect(&obs, &one), 1.0);
        assert!(repetition(&obs, &one).is_none());
    }
}
