//! Diagnosis: which missing parameters would explain what a calibrated model still gets
//! wrong?
//!
//! From the residuals `r` (model minus measurement) of a calibrated model over all
//! snapshots, the Jacobian `J` of those outputs with respect to the calibrated
//! parameters, and candidate hypotheses (each a Jacobian block `H` for parameters the
//! model does not have, linearised at 0, the effect absent), every hypothesis is refit
//! jointly with the current parameters, linearised: `r + J dp + H dq` is fitted under
//! a Student-t likelihood (by default, `nu` 4, by iteratively reweighted least squares;
//! a few outputs the model misses for reasons no hypothesis names then count little) or
//! a Gaussian one (least squares, `min ||r + J dp + H dq||^2 (+ ridge on dq)`), and
//! scored:
//!
//! - **explained fraction**: `1 - RSS_h / RSS_0`, with `RSS_0` the refit of `dp` alone
//!   (so what recalibrating the current parameters could still do is not credited);
//!   under a Student-t both sums weighted as the hypothesis's fit weighs the rows;
//! - **predicted MAE**: mean `|r + J dp + H dq|`, the error after adding it (to first order);
//! - **BIC change**: `-2 ln L + k ln n`, `k` the rank `H` adds to `J`: under a Gaussian
//!   `RSS/sigma^2` with a known noise sigma, else `n ln(RSS/n)`; under a Student-t
//!   `(nu + 1) sum ln(1 + e^2 / (nu s^2))`, plus `n ln s^2` when the scale is estimated;
//! - **held-out improvement**: the fraction of the held-out deviance (squared error under
//!   a Gaussian) removed when both fits are made without the held-out rows (leave one
//!   snapshot out with two or more snapshots, else K folds over outputs);
//! - **inert** when no parameter, moved to the far end of its range, changes the outputs
//!   by [`DiagnoseSettings::inert_snr`] noise sigmas;
//! - **identifiable** unless the hypothesis is (nearly) in the span of `J`, its own
//!   columns are (nearly) dependent, or another hypothesis spans the same directions;
//! - **significant** when the BIC falls by at least the threshold, the held-out error
//!   falls by at least the threshold, the predicted MAE is below the current parameters'
//!   own refit (least squares can trade a few large residuals for many small ones), the
//!   fitted values lie within the parameters' ranges
//!   (a negative leak is no explanation), it is neither inert nor in the span of `J`, nor
//!   refuted by the caller's own model runs ([`Hypothesis::refuted`]);
//!   it passes the **single-output check** (with any one output left out, the others
//!   still prefer it: BIC change below 0, so no one sensor carries it alone);
//!   among alternatives collinear with each other only the best is significant (the
//!   lowest BIC, or within 6 of it the most modest fitted change relative to its range);
//! - **undecided** (with [`DiagnoseSettings::ambiguity_check`], on by default): when
//!   another significant hypothesis of a different footprint (not collinear, and its fit
//!   changes other readings: the cosine between the two fits' explained changes below
//!   0.9) has a BIC within 6 of the best's, the evidence between them is short of
//!   "strong", so none is significant and each lists the others in
//!   [`HypothesisResult::ambiguous_with`].
//!
//! A known model uncertainty per row ([`Residuals::with_uncertainty`], e.g. the model's
//! own grid error) weighs each row by `sigma / sqrt(sigma^2 + u^2)` in every fit and test,
//! so that no hypothesis earns credit for what the model's numerics alone could produce.
//! A model-form uncertainty `m` ([`Residuals::with_model_form`], what another plausible
//! physics reads otherwise) adds `c m^2` to that variance, `c` in `[0, 1]` the share the
//! residuals bear out (maximum likelihood, [`Diagnosis::model_form_share`]): where the
//! model reproduces the data, another physics' reading is no uncertainty of it.
//!
//! Results are sorted best first: significant ones, then by BIC change.
//!
//! ```
//! use kalibre_core::diagnose::{diagnose, DiagnoseSettings, Hypothesis, HypothesisParam, Residuals, RowInfo};
//! use ndarray::Array2;
//!
//! # fn main() -> kalibre_core::Result<()> {
//! // Eight sensors in two snapshots; the model has an offset, the data also a gradient.
//! let rows: Vec<RowInfo> = (0..16)
//!     .map(|i| RowInfo { output: format!("s{}", i % 8), group: "cold".into(), snapshot: format!("t{}", i / 8) })
//!     .collect();
//! let x: Vec<f64> = (0..16).map(|i| (i % 8) as f64).collect();
//! let wiggle = |i: usize| 0.01 * if (i * 7) % 3 == 0 { 1.0 } else { -0.5 };
//! let r: Vec<f64> = (0..16).map(|i| -0.3 * x[i] + 1.05 + wiggle(i)).collect();
//! let res = Residuals::new(rows, r, Array2::ones((16, 1)), vec!["offset_c".into()])?;
//! let slope = Hypothesis::new("slope", vec![HypothesisParam::bounded("slope_c", 0.0, 1.0)], Array2::from_shape_fn((16, 1), |(i, _)| x[i]));
//! let d = diagnose(&res, &[slope], &DiagnoseSettings::new().with_noise_sigma(0.01))?;
//! assert!(d.hypotheses[0].significant);
//! assert!((d.hypotheses[0].fitted.get("slope_c").unwrap() - 0.3).abs() < 0.01);
//! # Ok(())
//! # }
//! ```

mod candidate;
mod heldout;
mod identify;
mod input;
mod jackknife;
pub(crate) mod linalg;
mod linearise;
mod outcome;
mod refit;
pub(crate) mod robust;
mod runs;
mod settings;
mod weights;

pub(crate) use candidate::group_candidates;
pub use candidate::{CandidateEffect, CandidateParam};
pub use heldout::HeldOutScheme;
pub use input::{measured_rows, Hypothesis, HypothesisParam, Residuals, RowInfo};
pub use linearise::{linearise, LineariseSettings, Linearised};
pub use outcome::{Diagnosis, HypothesisResult, UnexplainedOutput, DIAGNOSIS_SCHEMA};
pub use refit::{refit_leading, Refit, RefitSettings, RefitStep, Refitted};
pub use runs::{run_fitted, Calibrated, FittedRun, PointRun};
pub use settings::DiagnoseSettings;

use std::borrow::Cow;

use crate::calibrate::NamedValues;
use crate::{Error, Result};
use linalg::orthonormal_basis;
use robust::Likelihood;

/// Among collinear alternatives, how much lower a BIC must be to beat a more modest one:
/// 6, the end of "positive" evidence on the Kass-Raftery scale. Alternatives the data
/// cannot tell apart trade small BIC differences with the noise (on `demo`, one CRAC's
/// -3.9 C offset against all CRACs' -1 C: 1.8 or 2.4 lower by the likelihood), so only
/// strong evidence should prefer the bigger change.
const MODESTY_WINDOW_BIC: f64 = 6.0;

/// How far above the best significant hypothesis's BIC another may lie and still be
/// reported as a close alternative: 6, as `MODESTY_WINDOW_BIC`; below it the evidence
/// between the two is at most "positive" on the Kass-Raftery scale, not "strong".
pub const CLOSE_ALTERNATIVE_BIC: f64 = MODESTY_WINDOW_BIC;

/// Two fits whose explained changes have at least this cosine (an angle below 26
/// degrees) explain one footprint, and the ambiguity check does not count them as
/// rivals. A bypass behind the next rack measured 0.93 on `demo`; rivals that explain
/// different readings, 0.02-0.7 (`docs/diagnosis.md`, "Session 30").
const ALIKE_EXPLANATION_COS: f64 = 0.9;

/// An output is reported as unexplained when its residuals, after the best explanation,
/// are this many scales of the likelihood off (RMS over its rows). A Student-t with 4
/// degrees of freedom puts a residual there about once in 25 rows, so an output that
/// far off in every snapshot is no noise; such rows weigh 0.38 against 1.25 at none.
pub const UNEXPLAINED_SCALES: f64 = 3.0;

fn columns(m: &ndarray::Array2<f64>) -> Vec<Vec<f64>> {
    m.columns().into_iter().map(|c| c.to_vec()).collect()
}

fn sum_sq(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum()
}

/// Mean absolute value (0 of nothing).
pub(super) fn mean_abs(v: &[f64]) -> f64 {
    v.iter().map(|x| x.abs()).sum::<f64>() / v.len().max(1) as f64
}

/// Ranks `hypotheses` as explanations of what `res` leaves unexplained.
pub fn diagnose(
    res: &Residuals,
    hypotheses: &[Hypothesis],
    settings: &DiagnoseSettings,
) -> Result<Diagnosis> {
    settings.check()?;
    for (i, h) in hypotheses.iter().enumerate() {
        if hypotheses[..i].iter().any(|o| o.name == h.name) {
            return Err(Error::Mismatch(format!(
                "hypothesis `{}` appears twice",
                h.name
            )));
        }
        h.check(res)?;
    }
    let raw = res.residuals();
    let n = raw.len();
    let raw_jcols = columns(res.jacobian());
    let p = raw_jcols.len();
    // Row weights: 1 without a model uncertainty; with one, `sigma / sqrt(sigma^2 +
    // u^2 + c m^2)`, `sigma` the given noise or its maximum-likelihood estimate, `u` the
    // numerical uncertainty, `m` the model-form one and `c` the share of its variance
    // the residuals bear out. Every fit, BIC and held-out check below works on weighted
    // rows; MAEs are reported unweighted.
    let (weight_sigma, weights, model_form_share): (f64, Vec<f64>, Option<f64>) =
        match (res.uncertainty(), res.model_form()) {
            (None, None) => (0.0, vec![1.0; n], None),
            (u, m) => {
                let w = weights::row_weights(raw, &raw_jcols, u, m, settings.noise_sigma);
                (w.sigma, w.weights, w.model_form_share)
            }
        };
    // The weights outputs are listed as unexplained by: the numerical uncertainty's
    // alone, so that a far-off output the other physics covers is still shown.
    let listing_weights: Option<Vec<f64>> = res.model_form().map(|_| {
        (0..n)
            .map(|i| {
                let u = res.uncertainty().map_or(0.0, |u| u[i]);
                if weight_sigma > 0.0 {
                    weight_sigma / weight_sigma.hypot(u)
                } else {
                    1.0
                }
            })
            .collect()
    });
    let weigh = |v: &[f64]| -> Vec<f64> { v.iter().zip(&weights).map(|(x, w)| x * w).collect() };
    let unweigh = |v: &[f64]| -> Vec<f64> { v.iter().zip(&weights).map(|(x, w)| x / w).collect() };
    let r_weighted = weigh(raw);
    let r = r_weighted.as_slice();
    let jcols: Vec<Vec<f64>> = raw_jcols.iter().map(|c| weigh(c)).collect();
    let lik = Likelihood::new(settings.robust_nu);
    let given_scale = settings.noise_sigma.map(|s| lik.scale_of_sigma(s));
    let base = lik.fit(&jcols, r, &vec![0.0; p], given_scale, 0.0);
    let e0 = &base.e;
    let rss0 = sum_sq(e0);
    let (sigma, estimated) = match settings.noise_sigma {
        Some(s) => (s, false),
        None => {
            if n <= base.rank || rss0 == 0.0 {
                // Too few measured values for the calibrated parameters: the user's data,
                // not a fault of the ranking.
                let why = if n <= base.rank {
                    // Parameters that move the readings alike take one degree of
                    // freedom between them: the rank is what counts.
                    let moving = match base.rank < jcols.len() {
                        true => format!(
                            ", which move them in only {} independent directions,",
                            base.rank
                        ),
                        false => String::new(),
                    };
                    format!(
                        "{n} measured values for {} calibrated parameters{moving} leave no \
                         degree of freedom",
                        jcols.len()
                    )
                } else {
                    format!("the calibrated parameters, refit, fit all {n} measured values exactly")
                };
                return Err(Error::Mismatch(format!(
                    "cannot estimate the noise: {why}: measure more values (outputs or \
                     scenarios) than there are parameters, or give the measurements' noise \
                     if it is known (`kalibre diagnose --noise`; in the library \
                     `DiagnoseSettings::noise_sigma`)"
                )));
            }
            // Under a Gaussian `sqrt(RSS_0 / (n - rank))`; under a Student-t the same
            // degrees-of-freedom correction of the standard deviation its scale stands for.
            let dof = (n as f64 / (n - base.rank) as f64).sqrt();
            (lik.sigma_of_scale(base.scale) * dof, true)
        }
    };
    let scale = lik.scale_of_sigma(sigma);
    // Floor of an estimated scale: keeps an exact fit finite (it still scores as far
    // better).
    let floor = if estimated { 1e-6 * base.scale } else { 0.0 };
    let ln_n = (n as f64).ln();
    let bic0 = base.deviance;
    // The explained fraction: of the sum of squares, or under a Student-t of the sum of
    // squares weighted as the hypothesis's own fit weighs the rows (what it treats as
    // outliers counts as little there as here).
    let explained = |e: &[f64]| -> f64 {
        let (mut left, mut before) = (0.0, 0.0);
        for (eh, e0) in e.iter().zip(e0) {
            let w = lik.weight(*eh, scale);
            left += w * eh * eh;
            before += w * e0 * e0;
        }
        if before > 0.0 {
            (1.0 - left / before).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let refit_mae = mean_abs(&unweigh(e0));
    let (scheme, folds) = heldout::folds(res.rows(), settings.output_folds)?;
    // Under a Gaussian the held-out deviance at scale 1 is the held-out sum of squares.
    let held_scale = if lik.is_robust() { scale } else { 1.0 };
    let held_out =
        |cols: &[Vec<f64>], ridge: &[f64]| lik.held_out(cols, ridge, r, &folds, held_scale);
    let held0 = held_out(&jcols, &vec![0.0; p]);
    let output_names: Vec<&str> = res.rows().iter().map(|r| r.output.as_str()).collect();
    let by_output = heldout::group_rows(output_names.iter().copied());

    let qj = orthonormal_basis(&jcols, 1e-8);
    let hcols: Vec<Vec<Vec<f64>>> = hypotheses
        .iter()
        .map(|h| columns(&h.jacobian).iter().map(|c| weigh(c)).collect())
        .collect();
    let perps: Vec<identify::Perp> = hcols.iter().map(|c| identify::perp(&qj, c)).collect();
    let alone: Vec<bool> = perps
        .iter()
        .map(|q| q.independence >= settings.min_independence)
        .collect();
    let mut collinear: Vec<Vec<String>> = vec![Vec::new(); hypotheses.len()];
    for a in 0..hypotheses.len() {
        for b in a + 1..hypotheses.len() {
            if !(alone[a] && alone[b]) {
                continue;
            }
            if let Some(d) = identify::span_distance(&perps[a].basis, &perps[b].basis) {
                if d < settings.min_independence {
                    collinear[a].push(hypotheses[b].name.clone());
                    collinear[b].push(hypotheses[a].name.clone());
                }
            }
        }
    }

    let mut results = Vec::with_capacity(hypotheses.len());
    // Each fit's residuals and likelihood scale, for what the best one leaves unexplained.
    let mut fits_left: Vec<(Vec<f64>, f64)> = Vec::with_capacity(hypotheses.len());

    let mut modesty: Vec<f64> = Vec::new();
    for (i, h) in hypotheses.iter().enumerate() {
        let mut cols = jcols.clone();
        cols.extend(hcols[i].iter().cloned());
        let mut ridge = vec![0.0; p];
        ridge.extend(
            h.params
                .iter()
                .map(|q| settings.prior_weight * (sigma / q.reach()).powi(2)),
        );
        let sol = lik.fit(&cols, r, &ridge, given_scale, floor);
        let e = &sol.e;
        let added_rank = sol.rank.saturating_sub(base.rank);
        let held = held_out(&cols, &ridge);
        let held_out_improvement = if held0 > 0.0 { 1.0 - held / held0 } else { 0.0 };
        let movement_sigma = hcols[i]
            .iter()
            .zip(&h.params)
            .map(|(c, q)| sum_sq(c).sqrt() * q.reach() / sigma)
            .fold(0.0, f64::max);
        let inert = movement_sigma < settings.inert_snr;
        let identifiable = alone[i] && collinear[i].is_empty();
        let delta_bic = sol.deviance + added_rank as f64 * ln_n - bic0;
        // Collinearity with another hypothesis does not disqualify here: the best of a
        // group of indistinguishable alternatives is chosen below.
        let dq = &sol.x[p..];
        let in_range = dq
            .iter()
            .zip(&h.params)
            .all(|(v, q)| *v >= q.lower && *v <= q.upper);
        // Least squares may buy a lower RSS with a worse MAE (a few large residuals
        // traded for many small ones): a suggestion must lower the error users see.
        let predicted_mae = mean_abs(&unweigh(e));
        let mut significant = delta_bic <= -settings.bic_threshold
            && predicted_mae < refit_mae
            && held_out_improvement >= settings.min_held_out_improvement
            && !inert
            && alone[i]
            && in_range
            && !h.refuted;
        let mut carried_by = None;
        let mut sensor_bias_delta_bic = None;
        let single_output_delta_bic = if significant && settings.single_output_check {
            let (worst, worst_output) = jackknife::worst_delta_bic(
                &lik,
                &jcols,
                &hcols[i],
                &ridge,
                r,
                &by_output,
                given_scale,
                floor,
            );
            significant = worst < 0.0;
            if !significant {
                // Reported whenever the check stops a hypothesis: how a fault of that
                // sensor compares. It decides only with the rival setting.
                if let Some(o) = worst_output {
                    let against_bias = delta_bic
                        - jackknife::sensor_bias_delta_bic(
                            &lik,
                            &jcols,
                            &base,
                            r,
                            &by_output[o],
                            &weights,
                            given_scale,
                            floor,
                        );
                    sensor_bias_delta_bic = Some(against_bias);
                    significant = settings
                        .sensor_bias_rival_bic
                        .is_some_and(|margin| against_bias <= -margin);
                }
            }
            if !significant {
                carried_by = worst_output
                    .and_then(|o| by_output[o].first())
                    .map(|&row| output_names[row].to_string());
            }
            Some(worst)
        } else {
            None
        };
        let names: Vec<String> = h.params.iter().map(|q| q.name.clone()).collect();
        modesty.push(
            dq.iter()
                .zip(&h.params)
                .map(|(v, q)| (v / q.reach()).abs())
                .fold(0.0, f64::max),
        );
        results.push(HypothesisResult {
            name: h.name.clone(),
            explained_fraction: explained(e),
            predicted_mae,
            delta_bic,
            held_out_improvement,
            significant,
            refuted: h.refuted,
            inert,
            identifiable,
            independence: perps[i].independence,
            movement_sigma,
            collinear_with: std::mem::take(&mut collinear[i]),
            added_rank,
            fitted: NamedValues::new(&names, dq),
            in_range,
            ranges: h.params.iter().map(|q| [q.lower, q.upper]).collect(),
            current_change: NamedValues::new(res.params(), &sol.x[..p]),
            single_output_delta_bic,
            sensor_bias_delta_bic,
            carried_by,
            ambiguous_with: Vec::new(),
        });
        fits_left.push((sol.e, sol.scale));
    }
    // Among alternatives the data cannot tell apart (collinear, BIC within 6 of the
    // group's best), only the most modest one (smallest fitted change relative to its
    // range) stays significant; the others are listed in its `collinear_with`.
    let keep: Vec<bool> = (0..results.len())
        .map(|i| {
            let a = &results[i];
            !a.significant
                || !results.iter().enumerate().any(|(j, b)| {
                    j != i
                        && b.significant
                        && a.collinear_with.contains(&b.name)
                        && b.delta_bic <= a.delta_bic + MODESTY_WINDOW_BIC
                        && (modesty[j], &b.name) < (modesty[i], &a.name)
                        && a.delta_bic <= b.delta_bic + MODESTY_WINDOW_BIC
                        || (j != i
                            && b.significant
                            && a.collinear_with.contains(&b.name)
                            && b.delta_bic < a.delta_bic - MODESTY_WINDOW_BIC)
                })
        })
        .collect();
    for (r, k) in results.iter_mut().zip(keep) {
        r.significant &= k;
    }
    if settings.ambiguity_check {
        // A hypothesis nested in another (or containing it) is the same explanation; so
        // is one whose fit changes the same readings the same way (another label for
        // one footprint, as a bypass behind the next rack).
        let same_explanation = |a: usize, b: usize| {
            let (pa, pb) = (&perps[a].basis, &perps[b].basis);
            identify::spans_within(pa, pb, settings.min_independence)
                || identify::spans_within(pb, pa, settings.min_independence)
                || explanation_cosine(e0, &fits_left[a].0, &fits_left[b].0) >= ALIKE_EXPLANATION_COS
        };
        undecided_when_ambiguous(&mut results, same_explanation);
    }
    // What the best significant hypothesis (else the current parameters) leaves.
    let best = (0..results.len())
        .filter(|&i| results[i].significant)
        .min_by(|&a, &b| results[a].delta_bic.total_cmp(&results[b].delta_bic));
    // Its own scale when estimated: the current parameters' includes what it explains.
    let (left, left_scale) = match best {
        Some(i) if estimated => (fits_left[i].0.as_slice(), fits_left[i].1),
        Some(i) => (fits_left[i].0.as_slice(), scale),
        None => (e0.as_slice(), scale),
    };
    // Re-weighed by the listing weights when those differ from the fits'.
    let (left, listing): (Cow<[f64]>, &[f64]) = match &listing_weights {
        None => (Cow::Borrowed(left), &weights),
        Some(listing) => (
            left.iter()
                .zip(&weights)
                .zip(listing)
                .map(|((e, w), l)| e / w * l)
                .collect(),
            listing,
        ),
    };
    let unexplained = unexplained_outputs(
        &by_output,
        &output_names,
        &left,
        listing,
        left_scale,
        res.model_form(),
    );
    results.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(a.delta_bic.total_cmp(&b.delta_bic))
            .then_with(|| a.name.cmp(&b.name))
    });
    Ok(Diagnosis {
        schema: DIAGNOSIS_SCHEMA.into(),
        mae: mean_abs(raw),
        refit_mae,
        refit_change: NamedValues::new(res.params(), &base.x),
        noise_sigma: sigma,
        noise_sigma_estimated: estimated,
        held_out: scheme,
        held_out_folds: folds.len(),
        // Deviance per row back on the residuals' scale (under a Student-t, small
        // residuals count as under a Gaussian of that scale).
        held_out_rmse: held_scale * (held0 / n as f64).sqrt(),
        hypotheses: results,
        unexplained,
        model_form_share,
    })
}

/// The cosine between what two fits explain: the current parameters' refit's residuals
/// `e0` less each fit's residuals `left_a`, `left_b` (1: the same change of the same
/// readings; 0: changes of different readings).
fn explanation_cosine(e0: &[f64], left_a: &[f64], left_b: &[f64]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for ((e, a), b) in e0.iter().zip(left_a).zip(left_b) {
        let (da, db) = (e - a, e - b);
        ab += da * db;
        aa += da * da;
        bb += db * db;
    }
    if aa > 0.0 && bb > 0.0 {
        ab / (aa * bb).sqrt()
    } else {
        0.0
    }
}

/// When another significant explanation, neither collinear with the best nor nested
/// with it, nor changing the same readings alike (another footprint), fits within
/// [`CLOSE_ALTERNATIVE_BIC`] of it, the data cannot say which one is missing: every
/// significant hypothesis is left undecided (not significant), each listing the others
/// of that close set in `ambiguous_with`. `results` are in the hypotheses' order;
/// `same_explanation(i, j)` says whether the two are one footprint.
fn undecided_when_ambiguous(
    results: &mut [HypothesisResult],
    same_explanation: impl Fn(usize, usize) -> bool,
) {
    let Some(best) = (0..results.len())
        .filter(|&i| results[i].significant)
        .min_by(|&a, &b| results[a].delta_bic.total_cmp(&results[b].delta_bic))
    else {
        return;
    };
    let b = &results[best];
    let close: Vec<String> = results
        .iter()
        .enumerate()
        .filter(|(j, h)| {
            h.significant
                && *j != best
                && h.delta_bic < b.delta_bic + CLOSE_ALTERNATIVE_BIC
                && !b.collinear_with.contains(&h.name)
                && !same_explanation(best, *j)
        })
        .map(|(_, h)| h.name.clone())
        .collect();
    if close.is_empty() {
        return;
    }
    let mut set = vec![b.name.clone()];
    set.extend(close);
    for h in results.iter_mut().filter(|h| h.significant) {
        h.significant = false;
        h.ambiguous_with = set.iter().filter(|n| **n != h.name).cloned().collect();
    }
}

/// Outputs whose weighted residuals `e` are more than [`UNEXPLAINED_SCALES`] times
/// `scale` off (RMS over their rows), worst first, with their mean unweighted residual
/// and, given a model-form uncertainty per row, its RMS over their rows.
fn unexplained_outputs(
    by_output: &[Vec<usize>],
    names: &[&str],
    e: &[f64],
    weights: &[f64],
    scale: f64,
    model_form: Option<&[f64]>,
) -> Vec<UnexplainedOutput> {
    let mut out: Vec<UnexplainedOutput> = by_output
        .iter()
        .map(|rows| {
            let m = rows.len() as f64;
            let ms = rows.iter().map(|&i| (e[i] / scale).powi(2)).sum::<f64>() / m;
            UnexplainedOutput {
                output: names[rows[0]].to_string(),
                mean_residual: rows.iter().map(|&i| e[i] / weights[i]).sum::<f64>() / m,
                rms_scales: ms.sqrt(),
                model_form_c: model_form
                    .map(|u| (rows.iter().map(|&i| u[i] * u[i]).sum::<f64>() / m).sqrt()),
            }
        })
        .filter(|u| u.rms_scales > UNEXPLAINED_SCALES)
        .collect();
    out.sort_by(|a, b| {
        b.rms_scales
            .total_cmp(&a.rms_scales)
            .then_with(|| a.output.cmp(&b.output))
    });
    out
}
