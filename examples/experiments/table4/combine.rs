//! `--combine`: merging `table4.json` files by hall and by approach.

use serde::Deserialize;

use super::{targets, Approach, HallTable};
use crate::experiments::Result;

/// Reads the halls of `table4.json` files written by separate invocations (one hall
/// each, or some approaches each, run side by side) and merges them by hall and by
/// approach: a row is taken from whichever file has it, a later file's row replaces an
/// earlier one's, and the targets are recomputed on the merged rows. Files that
/// disagree on a hall's size, initial MAE or model-at-truth MAE measured different
/// things and are refused.
pub fn combine(files: &[std::path::PathBuf]) -> Result<Vec<HallTable>> {
    #[derive(Deserialize)]
    struct Doc {
        halls: Vec<HallTable>,
    }
    let mut out: Vec<(HallTable, std::path::PathBuf)> = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(f).map_err(|e| format!("{}: {e}", f.display()))?;
        let doc: Doc = serde_json::from_str(&text)
            .map_err(|e| format!("{}: not a table4.json ({e})", f.display()))?;
        for h in doc.halls {
            for r in &h.rows {
                if Approach::parse(&r.approach).is_none() || r.runs.is_empty() {
                    return Err(format!(
                        "{}: hall {}: row `{}` is not a known approach with runs",
                        f.display(),
                        h.preset,
                        r.approach
                    )
                    .into());
                }
            }
            match out.iter_mut().find(|(o, _)| o.preset == h.preset) {
                None => out.push((h, f.clone())),
                Some((o, first)) => {
                    same_measurements(o, &h).map_err(|why| {
                        format!(
                            "cannot merge hall {} of {} with that of {}: {why}",
                            h.preset,
                            first.display(),
                            f.display()
                        )
                    })?;
                    merge_rows(o, h);
                }
            }
        }
    }
    Ok(out
        .into_iter()
        .map(|(mut h, _)| {
            h.rows
                .sort_by_key(|r| Approach::parse(&r.approach).expect("checked on reading"));
            h.seeds = h
                .rows
                .iter()
                .filter(|r| r.runs.iter().any(|run| run.seed.is_some()))
                .map(|r| r.runs.len())
                .max()
                .unwrap_or(h.seeds);
            h.targets = targets(&h.rows);
            h
        })
        .collect())
}

/// Why two tables of one hall are not on the same measurements and model, if they are not.
fn same_measurements(a: &HallTable, b: &HallTable) -> std::result::Result<(), String> {
    if a.paper_loop != b.paper_loop {
        return Err("one ran the paper's loop and the other kalibre's".into());
    }
    if a.size != b.size {
        return Err(format!(
            "sizes (servers, sensors, parameters, snapshots) differ: {:?} vs {:?}",
            a.size, b.size
        ));
    }
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * (1.0 + x.abs().max(y.abs()));
    if !close(a.initial_mae_c, b.initial_mae_c) {
        return Err(format!(
            "initial MAE differs: {} C vs {} C (different measurements or model)",
            a.initial_mae_c, b.initial_mae_c
        ));
    }
    if let (Some(x), Some(y)) = (a.model_at_truth_mae_c, b.model_at_truth_mae_c) {
        if !close(x, y) {
            return Err(format!(
                "model-at-truth MAE differs: {x} C vs {y} C (different measurements or model)"
            ));
        }
    }
    Ok(())
}

/// Moves `b`'s rows into `a` (replacing `a`'s row of the same approach) with their budgets.
fn merge_rows(a: &mut HallTable, b: HallTable) {
    a.model_at_truth_mae_c = a.model_at_truth_mae_c.or(b.model_at_truth_mae_c);
    a.noise_only_mae_c = a.noise_only_mae_c.or(b.noise_only_mae_c);
    for row in b.rows {
        let kind = Approach::parse(&row.approach).expect("checked on reading");
        kind.copy_budget(&b.budgets, &mut a.budgets);
        a.rows
            .retain(|r| Approach::parse(&r.approach) != Some(kind));
        a.rows.push(row);
    }
}
