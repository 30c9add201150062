//! The held-out check's folds: refit on all rows but one fold, predict the fold (the
//! refit and its score are the likelihood's, `robust.rs`).

use serde::{Deserialize, Serialize};

use super::input::RowInfo;
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
