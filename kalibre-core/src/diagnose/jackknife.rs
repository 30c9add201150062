//! The single-output check: no one output may carry a hypothesis alone.
//!
//! A model can miss one sensor by degrees for reasons no hypothesis names: its own
//! physics there (a recirculation the solver does not resolve), a misplaced or faulty
//! sensor. A hypothesis with a parameter that acts near that sensor can then buy a large
//! BIC gain from that sensor alone, at a parameter value far from anything the other
//! sensors support. Leaving out every output in turn (all its snapshots), the other
//! outputs must still prefer the hypothesis, its complexity penalty paid (BIC change
//! below 0); the worst of these BIC changes is reported. A local effect seen by two
//! sensors passes (measured on OpenFOAM data: a missing blanking panel, -1.2 to -4.0
//! with either of its two sensors left out); a parameter fitted to one sensor the model
//! misses gets only its penalty from the others (+2 to +4 there).

use super::robust::{Fit, Likelihood};

/// The problem without some rows.
fn without(cols: &[Vec<f64>], r: &[f64], out: &[usize]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let keep: Vec<usize> = (0..r.len()).filter(|i| !out.contains(i)).collect();
    let c = cols
        .iter()
        .map(|c| keep.iter().map(|&i| c[i]).collect())
        .collect();
    (c, keep.iter().map(|&i| r[i]).collect())
}

/// The largest BIC change (hypothesis against the current parameters alone, both refit)
/// over the problems with one output's rows left out, and the index (into `by_output`)
/// of the output left out there; `(+inf, None)` with fewer than two outputs.
#[allow(clippy::too_many_arguments)]
pub(crate) fn worst_delta_bic(
    lik: &Likelihood,
    jcols: &[Vec<f64>],
    hcols: &[Vec<f64>],
    ridge: &[f64],
    r: &[f64],
    by_output: &[Vec<usize>],
    scale: Option<f64>,
    floor: f64,
) -> (f64, Option<usize>) {
    if by_output.len() < 2 {
        return (f64::INFINITY, None);
    }
    let p = jcols.len();
    let mut all = jcols.to_vec();
    all.extend(hcols.iter().cloned());
    let mut worst = (f64::NEG_INFINITY, None);
    for (o, out) in by_output.iter().enumerate() {
        let (j, rr) = without(jcols, r, out);
        let (a, _) = without(&all, r, out);
        let base = lik.fit(&j, &rr, &ridge[..p], scale, floor);
        let fit = lik.fit(&a, &rr, ridge, scale, floor);
        let k = fit.rank.saturating_sub(base.rank);
        let d = fit.deviance + k as f64 * (rr.len() as f64).ln() - base.deviance;
        if d > worst.0 {
            worst = (d, Some(o));
        }
    }
    worst
}

/// The BIC change of a constant bias at one output (`rows`, all its snapshots; `weights`
/// the rows' weights, so that the bias is constant in output units), refit with the
/// current parameters, against `base`, their refit alone: the rival of a hypothesis that
/// rests on that output. A faulty sensor or the model's own error there reads as such a
/// bias; an effect's warming follows its cause from snapshot to snapshot and reaches
/// other sensors a little, so the data can prefer it to the bias even when no other
/// output carries it alone.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sensor_bias_delta_bic(
    lik: &Likelihood,
    jcols: &[Vec<f64>],
    base: &Fit,
    r: &[f64],
    rows: &[usize],
    weights: &[f64],
    scale: Option<f64>,
    floor: f64,
) -> f64 {
    let mut bias = vec![0.0; r.len()];
    for &i in rows {
        bias[i] = weights[i];
    }
    let mut cols = jcols.to_vec();
    cols.push(bias);
    // The current parameters are not ridged (as in every fit of the diagnosis), nor is
    // the bias: it is the sensor's own offset, of any size.
    let fit = lik.fit(&cols, r, &vec![0.0; cols.len()], scale, floor);
    let added_rank = fit.rank.saturating_sub(base.rank);
    fit.deviance + added_rank as f64 * (r.len() as f64).ln() - base.deviance
}

#[cfg(test)]
mod tests {
    use super::super::heldout::group_rows;
    use super::*;

    #[test]
    fn a_hypothesis_carried_by_one_output_fails_and_a_shared_one_passes() {
        // 10 outputs x 3 snapshots, a little noise; output 4 is off by 3 in every
        // snapshot. `spike` acts on output 4 only; `shared` on every output, and the
        // data carry 1 of it.
        let n = 30;
        let output = |i: usize| i % 10;
        let noise = |i: usize| 0.05 * (((i * 7919) % 13) as f64 / 6.0 - 1.0);
        let spike: Vec<f64> = (0..n)
            .map(|i| if output(i) == 4 { 1.0 } else { 0.0 })
            .collect();
        let shared: Vec<f64> = (0..n).map(|i| 1.0 + 0.1 * output(i) as f64).collect();
        let r: Vec<f64> = (0..n)
            .map(|i| noise(i) - 3.0 * spike[i] - 1.0 * shared[i])
            .collect();
        let names: Vec<String> = (0..n).map(|i| format!("s{}", output(i))).collect();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let by = group_rows(refs);
        let lik = Likelihood::new(Some(4.0));
        let worst =
            |h: &[f64]| worst_delta_bic(&lik, &[], &[h.to_vec()], &[0.0], &r, &by, Some(0.05), 0.0);
        let (spike_worst, spike_carrier) = worst(&spike);
        assert!(spike_worst >= 0.0, "spike: {spike_worst}");
        // Output 4, the one the spike rests on, is the one whose absence undoes it.
        assert_eq!(spike_carrier, Some(4));
        let (shared_worst, _) = worst(&shared);
        assert!(shared_worst < -50.0, "shared: {shared_worst}");
    }

    #[test]
    fn a_bias_rival_tells_a_constant_fault_from_an_effect_that_follows_its_cause() {
        // 10 outputs x 3 snapshots. The effect acts on output 4 in proportion to a
        // cause that changes between snapshots (1, 2, 3) and a little on output 5.
        let n = 30;
        let output = |i: usize| i % 10;
        let snapshot = |i: usize| i / 10;
        let noise = |i: usize| 0.05 * (((i * 7919) % 13) as f64 / 6.0 - 1.0);
        let effect: Vec<f64> = (0..n)
            .map(|i| match output(i) {
                4 => 1.0 + snapshot(i) as f64,
                5 => 0.05,
                _ => 0.0,
            })
            .collect();
        let names: Vec<String> = (0..n).map(|i| format!("s{}", output(i))).collect();
        let by = group_rows(names.iter().map(String::as_str));
        let lik = Likelihood::new(Some(4.0));
        let weights = vec![1.0; n];
        let against_bias = |r: &[f64]| {
            let base = lik.fit(&[], r, &[], Some(0.05), 0.0);
            let fit = lik.fit(std::slice::from_ref(&effect), r, &[0.0], Some(0.05), 0.0);
            let effect_delta = fit.deviance + fit.rank as f64 * (n as f64).ln() - base.deviance;
            let bias_delta =
                sensor_bias_delta_bic(&lik, &[], &base, r, &by[4], &weights, Some(0.05), 0.0);
            effect_delta - bias_delta
        };
        // Data with the effect: it beats a bias of output 4 by far.
        let with_effect: Vec<f64> = (0..n).map(|i| noise(i) - 1.5 * effect[i]).collect();
        let effect_margin = against_bias(&with_effect);
        assert!(
            effect_margin < -50.0,
            "effect against bias: {effect_margin}"
        );
        // Output 4 off by 3 in every snapshot (a faulty sensor): the bias wins.
        let faulty: Vec<f64> = (0..n)
            .map(|i| noise(i) - if output(i) == 4 { 3.0 } else { 0.0 })
            .collect();
        let fault_margin = against_bias(&faulty);
        assert!(
            fault_margin > 10.0,
            "effect against bias on a fault: {fault_margin}"
        );
    }
}
