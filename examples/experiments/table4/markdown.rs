//! Table 4 as markdown.

use super::{Approach, HallTable};

/// The tables as markdown.
pub fn markdown(tables: &[HallTable]) -> String {
    let mut s = String::from(
        "| hall | approach | seeds | MAE after 10 it. (C) | lowest MAE (C) | iteration of lowest | model runs to lowest | model runs to 1.0 C | wall s |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for t in tables {
        for r in &t.rows {
            let reach = match &r.model_runs_to_1c {
                Some(st) if r.reached_1c == r.runs.len() => st.show(0),
                Some(st) => format!("{} ({}/{} seeds)", st.show(0), r.reached_1c, r.runs.len()),
                None => format!("not reached (> {})", r.runs_to_1c_bound().0 as usize),
            };
            // A budget under 10 iterations ends before the column's iteration 10: its
            // value is the last one, and says so.
            let ran = r
                .runs
                .iter()
                .filter_map(|x| x.history.last().map(|p| p.0))
                .max()
                .unwrap_or(0);
            let after_10 = match ran {
                n if n < 10 => format!("{} (ran {n} it.)", r.mae_after_10_c.show(2)),
                _ => r.mae_after_10_c.show(2),
            };
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                t.preset,
                r.approach,
                r.runs.len(),
                after_10,
                r.lowest_mae_c.show(2),
                r.iterations_to_lowest.show(1),
                r.model_runs_to_lowest.show(0),
                reach,
                r.wall_s.show(0)
            ));
        }
    }
    s.push('\n');
    for t in tables {
        let g = &t.targets;
        let has = |a: Approach| {
            t.rows
                .iter()
                .any(|r| Approach::parse(&r.approach) == Some(a))
        };
        let kalibre = has(Approach::Kalibre);
        let met = |m: Option<bool>| match m {
            Some(true) => "met".to_string(),
            Some(false) => "NOT met".into(),
            None if !kalibre => "n/a (no Kalibre row)".into(),
            None => "n/a (no other row)".into(),
        };
        let ratio = |a: Approach,
                     r: Option<f64>,
                     m: Option<bool>,
                     interval: Option<(f64, f64)>,
                     need: f64| match (r, m) {
            (Some(r), Some(m)) => format!(
                "{r:.1}x{} (need >= {need}x: {})",
                interval.map_or(", no interval (one seed)".to_string(), |(lo, hi)| format!(
                    ", 95 % bootstrap interval over seeds {lo:.1}-{hi:.1}x"
                )),
                if m { "met" } else { "NOT met" }
            ),
            _ if !kalibre || !has(a) => {
                format!("n/a (no {} row)", if kalibre { a.key() } else { "Kalibre" })
            }
            _ => "undefined (Kalibre did not reach 1.0 C on every seed)".into(),
        };
        let missing: Vec<&str> = Approach::ALL
            .into_iter()
            .filter(|&a| !has(a))
            .map(Approach::key)
            .collect();
        s.push_str(&format!(
            "- {}{}: initial MAE {:.2} C; model at truth {}; Kalibre best after 10 iterations: {}; fewest model runs to lowest: {}; ES/Kalibre runs to 1.0 C: {}; MLP/Kalibre: {}{}\n",
            t.preset,
            if t.paper_loop {
                " (loop rows in the paper's loop)"
            } else {
                ""
            },
            t.initial_mae_c,
            t.model_at_truth_mae_c.map_or("n/a".into(), |v| format!("{v:.2} C")),
            met(g.best_after_10),
            met(g.fewest_runs_to_lowest),
            ratio(
                Approach::Es,
                g.es_over_kalibre_runs_to_1c,
                g.es_ratio_met,
                g.es_ratio_interval,
                5.0
            ),
            ratio(
                Approach::Mlp,
                g.mlp_over_kalibre_runs_to_1c,
                g.mlp_ratio_met,
                g.mlp_ratio_interval,
                2.0
            ),
            if missing.is_empty() {
                String::new()
            } else {
                format!(" (rows not run: {})", missing.join(", "))
            },
        ));
        s.push_str(&format!("  - budgets: {}\n", budgets(t, &has)));
    }
    s
}

/// The iteration budget of each row the table has (a combined table's rows keep the
/// budgets they ran with), so that a "lowest MAE" can be read against its budget.
fn budgets(t: &HallTable, has: &dyn Fn(Approach) -> bool) -> String {
    let b = &t.budgets;
    let mut parts = Vec::new();
    if has(Approach::Kalibre) {
        parts.push(format!("Kalibre {} iterations", b.kalibre));
    }
    if has(Approach::Mlp) {
        let seeds = b
            .mlp_seeds
            .map_or(String::new(), |n| format!(" (first {n} seeds)"));
        parts.push(format!("MLP {} iterations{seeds}", b.mlp));
    }
    if has(Approach::Es) {
        parts.push(format!("(1+1)-ES {} mutations", b.es));
    }
    if has(Approach::Manual) {
        parts.push(format!("manual {} iterations", b.manual));
    }
    parts.join(", ")
}
