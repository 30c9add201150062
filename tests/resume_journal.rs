//! Resuming from `--out`'s run journal. A resumed calibration with a smaller budget than
//! the one that wrote the journal stops before some journaled runs: its `report.json`
//! says which it left and the best point among them, and stderr warns when that point
//! beats the new best (it used to replace a better answer without a word: 0.221 C by
//! 1.115 C in the fuzz case). A journal of another model is refused naming what differs,
//! down to the hall's changed fields.

mod cli_support;
use cli_support::*;

use std::path::Path;

/// Calibrates of-dev-clean into `out` with `extra` flags; `report.json` and stderr.
fn calibrate(out: &Path, extra: &[&str]) -> (serde_json::Value, String) {
    let o = calibrate_output(out, extra);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    (serde_json::from_str(&text).unwrap(), stderr(&o))
}

fn calibrate_output(out: &Path, extra: &[&str]) -> std::process::Output {
    calibrate_hall_output(&data("of-dev-clean/hall.json"), out, extra)
}

/// As [`calibrate_output`], of the hall in `hall` (with of-dev-clean's snapshots).
fn calibrate_hall_output(hall: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    run(kalibre()
        .args(["calibrate", "--hall"])
        .arg(hall)
        .arg("--snapshots")
        .arg(data("of-dev-clean/snapshots.csv"))
        .args([
            "--polish",
            "0",
            "--no-grid-check",
            "--quiet",
            "--threads",
            "1",
        ])
        .args(extra)
        .arg("--out")
        .arg(out))
}

#[test]
fn a_smaller_budget_names_the_better_runs_it_did_not_reach() {
    let out = tmp("resume-budget");
    let (long, _) = calibrate(&out, &["--iterations", "3"]);
    let long_best = long["best"]["mae_c"].as_f64().unwrap();
    let long_runs = long["runs"]["total"].as_u64().unwrap();
    assert!(long.get("unreached").is_none(), "{}", long["unreached"]);

    // The same flags again: every run is replayed, none left.
    let (again, warned) = calibrate(&out, &["--iterations", "3"]);
    assert_eq!(again["runs"]["cached"].as_u64(), Some(long_runs));
    assert!(again.get("unreached").is_none(), "{}", again["unreached"]);
    assert!(!warned.contains("were not used"), "{warned}");

    // Only the initial design (4 points x 3 snapshots): the loop's runs are left.
    let (short, warned) = calibrate(&out, &["--iterations", "3", "--max-runs", "12"]);
    assert_eq!(short["runs"]["cached"].as_u64(), Some(12));
    assert_eq!(short["stop_reason"], "model_run_budget");
    let unreached = &short["unreached"];
    assert_eq!(
        unreached["runs"].as_u64(),
        Some(long_runs - 12),
        "{unreached}"
    );
    let short_best = short["best"]["mae_c"].as_f64().unwrap();
    assert!(
        long_best < short_best,
        "the loop found nothing better than its design: {long_best} vs {short_best}"
    );
    // The journal's best is among the runs left, scored as the long run scored it.
    assert_eq!(unreached["best"]["mae_c"].as_f64(), Some(long_best));
    let named = format!("{long_best:.3} C, better than its best, {short_best:.3} C");
    assert!(warned.contains(&named), "{warned}");
    assert!(warned.contains("were not used"), "{warned}");
}

#[test]
fn a_journal_of_another_model_is_refused_naming_what_differs() {
    let out = tmp("journal-other");
    calibrate(&out, &["--iterations", "1"]);
    for (flags, why) in [
        (
            // Finer: 0.3 m would also move the racks off their 0.2 m grid, and say so.
            &["--grid-m", "0.1"][..],
            "its runs are --grid-m 0.2, this calibration's 0.1",
        ),
        (
            &["--alpha", "per-server"][..],
            "its runs are --alpha per-type, this calibration's per-server",
        ),
    ] {
        let o = calibrate_output(&out, &[&["--iterations", "1"], flags].concat());
        assert_input_error(&o, "holds 15 runs of another model: ");
        assert_input_error(&o, why);
    }
    let o = calibrate_output(&out, &["--iterations", "1", "--alpha", "per-server"]);
    assert_input_error(&o, "this calibration has parameters they lack: alpha/");
    // One line of another model among this one's (copied in from another journal): the
    // refusal says where it is.
    let journal = out.join("runs.jsonl");
    let mut lines: Vec<String> = std::fs::read_to_string(&journal)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    let mut run: serde_json::Value = serde_json::from_str(&lines[6]).unwrap();
    run["fingerprint"] = "0123456789abcdef".into();
    lines[6] = run.to_string();
    std::fs::write(&journal, lines.join("\n") + "\n").unwrap();
    let o = calibrate_output(&out, &["--iterations", "1"]);
    assert_input_error(&o, "holds 1 runs of another model (the first on line 7): ");
}

/// A hall edited after its runs were made: `calibrate` and `diagnose` name the fields
/// that changed (against `--out`'s copy of the hall the runs were made on); a new name
/// alone is not the model's and resumes.
#[test]
fn an_edited_hall_is_refused_naming_the_changed_fields() {
    let out = tmp("journal-edited-hall");
    calibrate(&out, &["--iterations", "1"]);
    let kept: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("runs-hall.json")).unwrap())
            .unwrap();
    let given: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("of-dev-clean/hall.json")).unwrap())
            .unwrap();
    assert_eq!(
        kept, given,
        "runs-hall.json is the hall the runs were made on"
    );

    let edited = tmp("journal-edited-hall-input").join("hall.json");
    std::fs::create_dir_all(edited.parent().unwrap()).unwrap();
    let write = |hall: &serde_json::Value| {
        std::fs::write(&edited, serde_json::to_string_pretty(hall).unwrap()).unwrap()
    };
    let mut renamed = given.clone();
    renamed["name"] = "another name".into();
    write(&renamed);
    let resumed = calibrate_hall_output(&edited, &out, &["--iterations", "1"]);
    assert_eq!(resumed.status.code(), Some(0), "{}", stderr(&resumed));

    let mut moved = given.clone();
    moved["cracs"][0]["rated_flow_m3_s"] = 3.25.into();
    let sensor = moved["sensors"][2]["id"].as_str().unwrap().to_string();
    moved["sensors"][2]["position_m"][2] = 0.55.into();
    write(&moved);
    let o = calibrate_hall_output(&edited, &out, &["--iterations", "1"]);
    assert_input_error(&o, "changed since its runs (they were made on ");
    assert_input_error(&o, "/cracs/0/rated_flow_m3_s (crac-1): ");
    assert_input_error(&o, &format!("/sensors/2/position_m ({sensor}): "));
    assert_input_error(&o, ",0.55]");
    let d = run(
        diagnose_cmd(&edited, &data("of-dev-clean/snapshots.csv"), &out).args(["--threads", "1"]),
    );
    assert_input_error(&d, "/model/fingerprint: runs of another model");
    assert_input_error(&d, "/cracs/0/rated_flow_m3_s (crac-1): ");
}

/// of-dev-clean's hall.json with `edit` applied, written to a fresh file `name`.
fn edited_hall(name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> std::path::PathBuf {
    let mut hall: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("of-dev-clean/hall.json")).unwrap())
            .unwrap();
    edit(&mut hall);
    let path = tmp(name).join("hall.json");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, serde_json::to_string_pretty(&hall).unwrap()).unwrap();
    path
}

/// `diagnose` of of-dev-clean against the calibration in `out`, which must succeed.
fn diagnoses_the_clean_hall(out: &Path) {
    let d = run(diagnose_cmd(
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
        out,
    )
    .args(["--threads", "1"]));
    assert_eq!(d.status.code(), Some(0), "{}", stderr(&d));
}

fn report(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

/// A bound or an initial value changes where the calibration searches, not what a run
/// computes: the journal's runs are this model's and are read (a walkthrough found
/// `holds 159 runs of another model: ... alpha_cfm_per_w/max (web): 3.0 -> 1.0`, every
/// OpenFOAM run lost). A physical field edited beside a bound is refused, naming it
/// alone.
#[test]
fn an_edited_bound_or_initial_value_keeps_the_journals_runs() {
    let out = tmp("journal-bounds");
    let (first, _) = calibrate(&out, &["--iterations", "1"]);
    let first_runs = first["runs"]["total"].as_u64().unwrap();
    let fingerprint = first["model"]["fingerprint"].clone();

    let started = edited_hall("journal-bounds-initial", |h| {
        h["server_types"][0]["alpha_cfm_per_w"]["initial"] = 0.5.into();
    });
    let narrower = edited_hall("journal-bounds-max", |h| {
        h["server_types"][0]["alpha_cfm_per_w"]["max"] = 1.0.into();
    });
    let mut journaled = first_runs;
    for hall in [&started, &narrower] {
        let o = calibrate_hall_output(hall, &out, &["--iterations", "1"]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let again = report(&out);
        let journal = &again["journal"];
        assert_eq!(journal["loaded"].as_u64(), Some(journaled), "{journal}");
        assert_eq!(journal["other_fingerprint"].as_u64(), Some(0), "{journal}");
        assert_eq!(again["model"]["fingerprint"], fingerprint);
        journaled += again["runs"]["new"].as_u64().unwrap();
    }
    // New runs were made (another start, another box), under the same fingerprint.
    assert!(journaled > first_runs);

    // `diagnose` takes the report written under other bounds as this model's.
    diagnoses_the_clean_hall(&out);

    let cooler = edited_hall("journal-bounds-flow", |h| {
        h["server_types"][0]["alpha_cfm_per_w"]["max"] = 1.0.into();
        h["cracs"][0]["rated_flow_m3_s"] = 3.25.into();
    });
    let o = calibrate_hall_output(&cooler, &out, &["--iterations", "1"]);
    assert_input_error(&o, "runs of another model: ");
    assert_input_error(&o, "/cracs/0/rated_flow_m3_s (crac-1): ");
    assert!(!stderr(&o).contains("alpha_cfm_per_w"), "{}", stderr(&o));
}

/// A `--out` written before bounds and initial values left the fingerprint: its runs
/// and its report carry the fingerprint the old computation gave, which the model still
/// owns (`kalibre-dc-sim/3:c6490c6057133148` for of-dev-clean on the default grid, as
/// the old version wrote it).
#[test]
fn a_journal_and_report_of_the_previous_fingerprint_are_this_models() {
    use kalibre_core::Model;
    let hall = kalibre_dc::hall::Hall::load(&data("of-dev-clean/hall.json")).unwrap();
    let model = kalibre_dc::HallModel::new(&hall, kalibre_dc::sim::SimConfig::default()).unwrap();
    let legacy = "kalibre-dc-sim/3:c6490c6057133148";
    assert_eq!(model.legacy_fingerprints(), vec![legacy.to_string()]);

    let out = tmp("journal-legacy");
    let (first, _) = calibrate(&out, &["--iterations", "1"]);
    let ours = model.fingerprint();
    assert_eq!(first["model"]["fingerprint"].as_str(), Some(ours.as_str()));
    let runs = first["runs"]["total"].as_u64().unwrap();
    // As the previous version left it.
    let old = |name: &str| {
        let path = out.join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains(&ours));
        std::fs::write(&path, text.replace(&ours, legacy)).unwrap();
    };
    old("runs.jsonl");
    old("report.json");

    diagnoses_the_clean_hall(&out);

    let (again, _) = calibrate(&out, &["--iterations", "1"]);
    assert_eq!(
        again["runs"]["cached"].as_u64(),
        Some(runs),
        "{}",
        again["runs"]
    );
    assert_eq!(again["runs"]["new"].as_u64(), Some(0));
    assert_eq!(again["journal"]["other_fingerprint"].as_u64(), Some(0));
    assert_eq!(again["model"]["fingerprint"].as_str(), Some(ours.as_str()));
}
