//! `calibrate --max-wall-s` reaches inside a step: a search of a million Adam steps used
//! to run 30 s past a 2 s budget (54 s past 3 s with two million), because the budget was
//! looked at only between the loop's steps.

mod cli_support;
use cli_support::*;

#[test]
fn the_wall_budget_cuts_a_long_search_and_the_report_says_so() {
    let out = tmp("wall-budget");
    let started = std::time::Instant::now();
    let o = run(kalibre()
        .args(["calibrate", "--hall"])
        .arg(data("of-dev-clean/hall.json"))
        .arg("--snapshots")
        .arg(data("of-dev-clean/snapshots.csv"))
        .args([
            "--adam-steps",
            "1000000",
            "--max-wall-s",
            "2",
            "--no-grid-check",
            "--quiet",
        ])
        .arg("--out")
        .arg(&out));
    let took = started.elapsed().as_secs_f64();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["stop_reason"], "wall_clock_budget");
    // The design's 12 runs, and none at the cut search's proposal.
    assert_eq!(report["runs"]["total"], 12, "{}", report["runs"]);
    assert!(took < 60.0, "{took:.1} s against a 2 s budget");
}
