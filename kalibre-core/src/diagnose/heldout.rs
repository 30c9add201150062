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

/// Row indices grouped by key (a snapshot label, an output name), groups in order of
/// first appearance, rows in order within each.
pub(crate) fn group_rows<'a>(keys: impl IntoIterator<Item = &'a str>) -> Vec<Vec<usize>> {
    let mut names: Vec<&str> = Vec::new();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (i, key) in keys.into_iter().enumerate() {
        match names.iter().position(|n| *n == key) {
            Some(g) => groups[g].push(i),
            None => {
                names.push(key);
                groups.push(vec![i]);
            }
        }
    }
    groups
}

/// The folds: each a list of held-out row indices.
pub(crate) fn folds(
    rows: &[RowInfo],
    output_folds: usize,
) -> Result<(HeldOutScheme, Vec<Vec<usize>>)> {
    let by_snapshot = group_rows(rows.iter().map(|r| r.snapshot.as_str()));
    if by_snapshot.len() >= 2 {
        return Ok((HeldOutScheme::Snapshots, by_snapshot));
    }
    let by_output = group_rows(rows.iter().map(|r| r.output.as_str()));
    if by_output.len() < 2 {
        return Err(Error::Mismatch(
            "the held-out check needs at least two snapshots or two outputs".into(),
        ));
    }
    let k = output_folds.min(by_output.len());
    let f = (0..k)
        .map(|f| {
            let mut fold: Vec<usize> = by_output
                .iter()
                .skip(f)
                .step_by(k)
                .flatten()
                .copied()
                .collect();
            fold.sort_unstable();
            fold
        })
        .collect();
    Ok((HeldOutScheme::Outputs, f))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_grouped_by_key_in_order_of_first_appearance() {
        let g = group_rows(["a", "b", "a", "c", "b"]);
        assert_eq!(g, vec![vec![0, 2], vec![1, 4], vec![3]]);
    }

    #[test]
    fn one_snapshot_deals_outputs_to_folds_in_turn() {
        let rows: Vec<RowInfo> = ["x", "y", "z", "x"]
            .iter()
            .map(|o| RowInfo {
                output: o.to_string(),
                group: "cold".into(),
                snapshot: "t0".into(),
            })
            .collect();
        let (scheme, f) = folds(&rows, 2).unwrap();
        assert_eq!(scheme, HeldOutScheme::Outputs);
        assert_eq!(f, vec![vec![0, 2, 3], vec![1]]);
    }
}
