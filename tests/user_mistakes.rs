//! What a first-time user runs into (a walkthrough of the README on the development
//! data): the wrong file given for a flag, figures from a model that was never
//! calibrated, a misspelt rack, the calibration's summary, and the diagnosis's closing
//! advice.

mod cli_support;
use cli_support::*;

#[test]
fn a_csv_given_as_the_hall_and_a_report_given_as_the_calibration_say_so() {
    let o = run(on_files(
        "simulate",
        &data("of-dev-clean/snapshots.csv"),
        &data("of-dev-clean/snapshots.csv"),
    )
    .arg("--out")
    .arg(tmp("mistakes-csv").join("pred.csv")));
    assert_input_error(&o, "looks like CSV (a snapshots file?), not a hall's JSON");

    // A calibration's report.json for --calibration, which takes its directory.
    let report = tmp("mistakes-report").join("report.json");
    std::fs::write(&report, "{}").unwrap();
    let o = run(&mut diagnose_cmd(
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
        &report,
    ));
    assert_input_error(&o, "report.json: is a file; give the directory");
}

#[test]
fn simulate_says_when_its_intake_figures_are_the_uncalibrated_models() {
    let dir = tmp("mistakes-uncalibrated");
    let note = "at the hall's initial parameters, not calibrated";
    let o = run(on_dataset("simulate", "of-dev-clean")
        .arg("--out")
        .arg(dir.join("pred.csv")));
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let at = stdout.find(note).expect("the note");
    assert!(
        at < stdout.find("t0: ").expect("the intake line"),
        "{stdout}"
    );

    let params = dir.join("params.json");
    std::fs::write(
        &params,
        r#"{ "alpha/web": 0.13, "alpha/db": 0.17, "alpha/gpu": 0.12 }"#,
    )
    .unwrap();
    let o = run(on_dataset("simulate", "of-dev-clean")
        .arg("--params")
        .arg(&params)
        .arg("--out")
        .arg(dir.join("pred2.csv")));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!String::from_utf8_lossy(&o.stdout).contains(note));
}

#[test]
fn a_misspelt_rack_lists_the_halls_racks() {
    let o = run(kalibre()
        .args(["synth", "--preset", "demo", "--seed", "1", "--effect"])
        .arg("rack_recirculation:rack=A3,fraction=0.3")
        .arg("--out")
        .arg(tmp("mistakes-rack").join("s")));
    assert_input_error(
        &o,
        "no rack `A3` in the hall (its racks: A01, A02, A03, A04, ...",
    );
}

/// The named effect is said in plain words, the sensors no candidate explains are
/// listed with what their residuals are left after, and the advice to calibrate under the Student-t likelihood is given only to a
/// calibration that did not.
#[test]
fn the_diagnosis_advises_the_student_t_likelihood_only_where_it_was_not_used() {
    let dir = tmp("mistakes-advice");
    let hall = data("of-dev-blanking/hall.json");
    let snaps = data("of-dev-blanking/snapshots.csv");
    for (likelihood, advice) in [
        ("gaussian", "to calibrate again with the suggested effect"),
        (
            "student-t",
            "the calibration already weighed them down (Student-t",
        ),
    ] {
        let cal = dir.join(likelihood);
        let o = run(on_files("calibrate", &hall, &snaps)
            .args(["--likelihood", likelihood, "--threads", "1", "--out"])
            .arg(&cal));
        assert!(o.status.success(), "{}", stderr(&o));
        // The summary in words: the polish's records number on past the loop's 10
        // iterations (this best is the polish's), and why it stopped.
        let summary = String::from_utf8_lossy(&o.stdout);
        assert!(
            summary.contains("(found in the polish, after the loop's 10 iterations)"),
            "{summary}"
        );
        assert!(summary.contains("iteration budget used"), "{summary}");
        let o = run(diagnose_cmd(&hall, &snaps, &cal).args(["--threads", "1"]));
        assert!(o.status.success(), "{}", stderr(&o));
        let stdout = String::from_utf8_lossy(&o.stdout);
        // The kind's name is the model's; the line under it says what to look for.
        assert!(
            stdout.contains("that is exhaust returning through the rack to its own intakes: a missing blanking panel"),
            "{stdout}"
        );
        assert!(stdout.contains("sensors no candidate explains"), "{stdout}");
        assert!(
            stdout.contains("residuals left with rack_recirculation(rack=B4) added"),
            "{stdout}"
        );
        assert!(stdout.contains(advice), "{likelihood}: {stdout}");
    }
}
