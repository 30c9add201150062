//! Why the journal's runs failed, and those at a bound of the box. The summary names the
//! most common reason, so that a timeout or a crash is seen without reading the journal.
//! A model that cannot run at a corner (OpenFOAM misses its energy balance where servers
//! draw many times the supply) fails there on every resume, since a resume runs failed
//! points again: "fix what failed" then means narrowing that bound where the parameters
//! are given (hall.json, or model.toml's `[[params]]`), or resuming with
//! `--replay-failed`, and the summary says so.

use std::collections::BTreeMap;
use std::path::Path;

use kalibre_core::ParamSpace;

/// The longest reason the summary quotes.
const REASON_CHARS: usize = 160;

/// Of the failed runs of the model of `fingerprints` (its own and those earlier versions
/// gave it) in `journal`: the most common reason,
/// and those at a bound of `space` (how many, and the bound most of them share), as
/// clauses for the summary's note. `None` when the journal holds no failed run of it.
/// `bounds_in` names where the bounds are given (`hall.json`); `replayed`: this
/// calibration replayed the failures (`--replay-failed`) rather than run them.
pub(super) fn clause(
    journal: &Path,
    fingerprints: &[String],
    space: &ParamSpace,
    bounds_in: &str,
    replayed: bool,
) -> Option<String> {
    let text = std::fs::read_to_string(journal).ok()?;
    let names = space.names();
    let mut reasons: BTreeMap<String, usize> = BTreeMap::new();
    let mut failed = 0usize;
    let mut at_bound = 0usize;
    // (parameter, side) -> (runs there, its value)
    let mut bounds: BTreeMap<(usize, &str), (usize, f64)> = BTreeMap::new();
    for line in text.lines() {
        let Ok(run) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let ours = run["fingerprint"]
            .as_str()
            .is_some_and(|f| fingerprints.iter().any(|fp| fp == f));
        if run["status"] != "failed" || !ours {
            continue;
        }
        let same_names = run["param_names"].as_array().is_some_and(|n| {
            n.iter()
                .map(|v| v.as_str())
                .eq(names.iter().map(|s| Some(s.as_str())))
        });
        let Some(params) = run["params"].as_array().filter(|_| same_names) else {
            continue;
        };
        failed += 1;
        if let Ok(e) = serde_json::from_value::<kalibre_core::ModelError>(run["error"].clone()) {
            let reason: String = e.to_string().chars().take(REASON_CHARS).collect();
            *reasons.entry(reason).or_default() += 1;
        }
        let mut here = false;
        for (i, (p, v)) in space.params().iter().zip(params).enumerate() {
            let Some(v) = v.as_f64() else { continue };
            // A log scale's round trip leaves 2.9999999999999996 for a bound of 3.
            let near = |b: f64| (v - b).abs() <= 1e-9 * b.abs().max(1.0);
            let side = if p.is_fixed() {
                continue;
            } else if near(p.upper) {
                ("upper", p.upper)
            } else if near(p.lower) {
                ("lower", p.lower)
            } else {
                continue;
            };
            here = true;
            bounds.entry((i, side.0)).or_insert((0, side.1)).0 += 1;
        }
        at_bound += usize::from(here);
    }
    // The most common reason; of equals, the first in the reasons' alphabetical order.
    let common = reasons
        .iter()
        .max_by(|(ra, na), (rb, nb)| na.cmp(nb).then(rb.cmp(ra)))
        .map(|(reason, &n)| {
            let of = match (n, failed) {
                (1, 1) => "the one failed run".to_string(),
                (n, f) if n == f => format!("all {f} failed runs"),
                (n, f) => format!("{n} of the {f} failed runs"),
            };
            format!("{of} in the journal: {reason}")
        });
    let Some(most) = bounds.values().map(|(n, _)| *n).max() else {
        return common;
    };
    // Every bound that many of them share (at a corner of the box, all of its bounds).
    let shared: Vec<String> = bounds
        .iter()
        .filter(|(_, (n, _))| *n == most)
        .map(|((i, side), (_, value))| {
            format!("{} = {} ({side})", names[*i], kalibre_core::number(*value))
        })
        .collect();
    let which = if at_bound == failed {
        format!("all {failed} failed runs in the journal")
    } else {
        format!("{at_bound} of the {failed} failed runs in the journal")
    };
    let listed = match shared.len() {
        0..=3 => shared.join(", "),
        n => format!("{} and {} more", shared[..3].join(", "), n - 3),
    };
    let remedy = if replayed {
        format!("narrow that bound in {bounds_in} (this resume replayed them, --replay-failed)")
    } else {
        format!(
            "narrow that bound in {bounds_in}, as a resume runs failed points again (or \
             resume with --replay-failed)"
        )
    };
    let at = format!(
        "{which} sit at a bound, {most} of them at {listed}; if the model cannot run there, \
         {remedy}"
    );
    Some(match common {
        Some(common) => format!("{common}; {at}"),
        None => at,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibre_core::Scale;

    #[test]
    fn names_the_bound_the_failed_runs_share_and_only_failed_runs_of_this_model() {
        let space = ParamSpace::new()
            .with("a", 0.1, 3.0, 1.0, Scale::Log)
            .unwrap()
            .with("b", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap();
        let line = |status: &str, fp: &str, params: [f64; 2]| {
            format!(
                "{{\"status\":\"{status}\",\"fingerprint\":\"{fp}\",\"param_names\":[\"a\",\"b\"],\
                 \"params\":[{},{}],\"error\":{{\"kind\":\"timeout\",\"seconds\":3.0}}}}\n",
                params[0], params[1]
            )
        };
        let journal = std::env::temp_dir().join(format!(
            "kalibre-failed-at-bounds-{}.jsonl",
            std::process::id()
        ));
        let write = |lines: &[String]| std::fs::write(&journal, lines.concat()).unwrap();
        let m = ["m".to_string()];
        write(&[
            line("failed", "m", [2.9999999999999996, 0.4]),
            line("failed", "m", [1.0, 0.4]),
            line("ok", "m", [3.0, 0.4]),
            line("failed", "other", [0.1, 0.0]),
        ]);
        assert_eq!(
            clause(&journal, &m, &space, "hall.json", false).as_deref(),
            Some(
                "all 2 failed runs in the journal: model run timed out after 3 s; 1 of the 2 \
                 failed runs in the journal sit at a bound, 1 of them at a = 3 (upper); if the \
                 model cannot run there, narrow that bound in hall.json, as a resume runs \
                 failed points again (or resume with --replay-failed)"
            )
        );
        assert!(
            clause(&journal, &m, &space, "model.toml's [[params]]", true)
                .unwrap()
                .ends_with(
                    "narrow that bound in model.toml's [[params]] (this resume replayed them, \
                 --replay-failed)"
                )
        );
        // The runs of a model's legacy fingerprint are its runs.
        let renamed = ["m2".to_string(), "m".to_string()];
        assert_eq!(
            clause(&journal, &renamed, &space, "hall.json", false),
            clause(&journal, &m, &space, "hall.json", false)
        );
        write(&[line("failed", "m", [1.0, 0.4])]);
        assert_eq!(
            clause(&journal, &m, &space, "hall.json", false).as_deref(),
            Some("the one failed run in the journal: model run timed out after 3 s")
        );
        write(&[line("ok", "m", [1.0, 0.4])]);
        assert_eq!(clause(&journal, &m, &space, "hall.json", false), None);
        std::fs::remove_file(&journal).unwrap();
    }
}
