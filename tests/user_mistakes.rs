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
        "no rack `A3` in the hall (its racks: A01, A02, A03, A04, A05, A06, ... (24 in all))",
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
        let summary = String::from_utf8_lossy(&o.stdout).into_owned();
        let o = run(diagnose_cmd(&hall, &snaps, &cal).args(["--threads", "1"]));
        assert!(o.status.success(), "{}", stderr(&o));
        let stdout = String::from_utf8_lossy(&o.stdout);
        for (text, needle) in [
            (
                &summary[..],
                "(found in the polish, after the loop's 10 iterations)",
            ),
            (&summary[..], "iteration budget used"),
            // The kind's name is the model's; the line under it says what to look for.
            (
                &stdout[..],
                "that is exhaust returning through the rack to its own intakes: a missing \
                 blanking panel",
            ),
            (&stdout[..], "sensors no candidate explains"),
            (
                &stdout[..],
                "residuals left with rack_recirculation(rack=B4) added",
            ),
        ] {
            assert!(
                text.contains(needle),
                "{likelihood}: `{needle}` not in {text}"
            );
        }
        assert!(stdout.contains(advice), "{likelihood}: {stdout}");
    }
}

/// A prior that binds at the best parameters names the alpha, its servers, the rise it
/// gives and the range, not only a count (the CRAC-offset data, calibrated without the
/// offset, want rises past 12 K, so a 5-12 K range binds).
#[test]
fn a_binding_rise_prior_names_the_alpha_and_the_rise() {
    let o = run(on_dataset("calibrate", "of-dev-crac-offset")
        .args(["--threads", "1", "--rise-range", "5,12", "--out"])
        .arg(tmp("mistakes-prior").join("cal")));
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let note = stdout
        .lines()
        .find(|l| l.contains("the temperature-rise prior binds"))
        .unwrap_or_else(|| panic!("no prior note in {stdout}"));
    assert!(note.contains("alpha/gpu = "), "{note}");
    assert!(note.contains("above the 5-12 K range"), "{note}");
    assert!(note.contains("widen --rise-range"), "{note}");
}

/// A calibration into an `--out` that holds the report of one against other
/// measurements says it replaces that report; a repeated one (the same measurements)
/// says nothing.
#[test]
fn a_calibration_replacing_one_of_other_measurements_says_so() {
    let out = tmp("mistakes-replaced").join("cal");
    let note = "is a calibration against other measurements";
    let mut stderrs = Vec::new();
    for dataset in ["of-dev-clean", "of-dev-blanking", "of-dev-blanking"] {
        let o = run(on_dataset("calibrate", dataset)
            .args(["--threads", "1", "--quiet", "--out"])
            .arg(&out));
        assert!(o.status.success(), "{}", stderr(&o));
        stderrs.push(stderr(&o));
    }
    assert!(!stderrs[0].contains(note), "{}", stderrs[0]);
    assert!(stderrs[1].contains(note), "{}", stderrs[1]);
    assert!(
        stderrs[1].contains("snapshot `t0`, sensor `"),
        "{}",
        stderrs[1]
    );
    assert!(!stderrs[2].contains(note), "{}", stderrs[2]);
}
