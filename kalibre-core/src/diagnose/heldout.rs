//! The held-out check: refit on all rows but one fold, predict the fold.

use serde::{Deserialize, Serialize};

use super::input::RowInfo;
use super::linalg::lstsq;
use crate::{Error, Result};

/// How rows were held out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeldOutScheme {
    /// Leave one snapshot out (two or more snapshots).
    Snapshots,
    /// K folds over outputs, an output's rows in every snapshot held out together
    /// (one snapshot). Outputs go to folds in turn, in order of first appearance, so
    /// neighbouring sensors land in different folds.
    Outputs,
}

/// The folds: each a list of held-out row indices.
pub(crate) fn folds(
    rows: &[RowInfo],
    output_folds: usize,
) -> Result<(HeldOutScheme, Vec<Vec<usize>>)> {
    let mut labels: Vec<&str> = Vec::new();
    for r in rows {
        if !labels.contains(&r.snapshot.as_str()) {
            labels.push(&r.snapshot);
        }
    }
    if labels.len() >= 2 {
        let f = labels
            .iter()
            .map(|l| {
                (0..rows.len())
                    .filter(|&i| rows[i].snapshot == *l)
                    .collect()
            })
            .collect();
        return Ok((HeldOutScheme::Snapshots, f));
    }
    let mut outputs: Vec<&str> = Vec::new();
    for r in rows {
        if !outputs.contains(&r.output.as_str()) {
            outputs.push(&r.output);
        }
    }
    if outputs.len() < 2 {
        return Err(Error::Mismatch(
            "the held-out check needs at least two snapshots or two outputs".into(),
        ));
    }
    let k = output_folds.min(outputs.len());
    let fold_of = |name: &str| outputs.iter().position(|o| *o == name).unwrap_or(0) % k;
    let f = (0..k)
        .map(|f| {
            (0..rows.len())
                .filter(|&i| fold_of(&rows[i].output) == f)
                .collect()
        })
        .collect();
    Ok((HeldOutScheme::Outputs, f))
}

/// Sum of squared held-out residuals over all folds when `cols` are refit (with `ridge`)
/// on the other rows: `sum_fold ||r_f + A_f x_(-f)||^2`.
pub(crate) fn held_out_sse(
    cols: &[Vec<f64>],
    ridge: &[f64],
    r: &[f64],
    folds: &[Vec<usize>],
) -> f64 {
    let n = r.len();
    let mut sse = 0.0;
    let mut held = vec![false; n];
    for fold in folds {
        held.iter_mut().for_each(|h| *h = false);
        fold.iter().for_each(|&i| held[i] = true);
        let train: Vec<usize> = (0..n).filter(|&i| !held[i]).collect();
        let sub: Vec<Vec<f64>> = cols
            .iter()
            .map(|c| train.iter().map(|&i| c[i]).collect())
            .collect();
        let refs: Vec<&[f64]> = sub.iter().map(Vec::as_slice).collect();
        let b: Vec<f64> = train.iter().map(|&i| -r[i]).collect();
        let x = lstsq(&refs, &b, ridge).x;
        for &i in fold {
            let e = r[i] + cols.iter().zip(&x).map(|(c, xj)| c[i] * xj).sum::<f64>();
            sse += e * e;
        }
    }
    sse
}
