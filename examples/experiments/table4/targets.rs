//! The targets on one hall: Kalibre best after 10 iterations and fastest to its
//! lowest MAE, and the ES and MLP needing 5x and 2x its model runs to reach 1.0 C.

use serde::{Deserialize, Serialize};

use super::{Approach, ApproachRow};

/// Whether the targets hold on one hall (none: undefined, e.g. no Kalibre row).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Targets {
    /// Kalibre has the lowest mean MAE after 10 iterations among the rows present.
    pub best_after_10: Option<bool>,
    /// Kalibre needs the fewest mean model runs to its lowest MAE among the rows present.
    pub fewest_runs_to_lowest: Option<bool>,
    /// ES model runs to 1.0 C over Kalibre's (a lower bound when ES never got there).
    pub es_over_kalibre_runs_to_1c: Option<f64>,
    /// MLP model runs to 1.0 C over Kalibre's (a lower bound when it never got there).
    pub mlp_over_kalibre_runs_to_1c: Option<f64>,
    /// ES ratio at least 5.
    pub es_ratio_met: Option<bool>,
    /// MLP ratio at least 2.
    pub mlp_ratio_met: Option<bool>,
    /// 95 % bootstrap interval of the ES ratio over seeds ([`super::super::ratio_interval`]).
    #[serde(default)]
    pub es_ratio_interval: Option<(f64, f64)>,
    /// 95 % bootstrap interval of the MLP ratio over seeds.
    #[serde(default)]
    pub mlp_ratio_interval: Option<(f64, f64)>,
}

/// The targets over the rows present: undefined where Kalibre's row (or the compared
/// row) is missing.
pub(super) fn targets(rows: &[ApproachRow]) -> Targets {
    let find = |a: Approach| {
        rows.iter()
            .find(|r| Approach::parse(&r.approach) == Some(a))
    };
    let Some(k) = find(Approach::Kalibre) else {
        return Targets::default();
    };
    let others: Vec<&ApproachRow> = rows.iter().filter(|r| !std::ptr::eq(*r, k)).collect();
    let compared = !others.is_empty();
    let best_after_10 = compared.then(|| {
        others
            .iter()
            .all(|o| k.mae_after_10_c.mean < o.mae_after_10_c.mean)
    });
    let fewest_runs_to_lowest = compared.then(|| {
        others
            .iter()
            .all(|o| k.model_runs_to_lowest.mean < o.model_runs_to_lowest.mean)
    });
    // A ratio is only defined when Kalibre reached 1.0 C on every seed.
    let kal_runs = (k.reached_1c == k.runs.len()).then(|| k.runs_to_1c_bound().0);
    let ratio = |a: Approach| {
        let o = find(a)?;
        kal_runs.map(|kr| o.runs_to_1c_bound().0 / kr)
    };
    let interval = |a: Approach| {
        let o = find(a)?;
        kal_runs?;
        super::super::ratio_interval(&o.runs_to_1c_per_seed(), &k.runs_to_1c_per_seed())
    };
    let es = ratio(Approach::Es);
    let mlp = ratio(Approach::Mlp);
    Targets {
        best_after_10,
        fewest_runs_to_lowest,
        es_over_kalibre_runs_to_1c: es,
        mlp_over_kalibre_runs_to_1c: mlp,
        es_ratio_met: es.map(|r| r >= 5.0),
        mlp_ratio_met: mlp.map(|r| r >= 2.0),
        es_ratio_interval: interval(Approach::Es),
        mlp_ratio_interval: interval(Approach::Mlp),
    }
}
