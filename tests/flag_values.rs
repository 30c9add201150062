//! Flag values far outside what they mean (a cell size of 1e-300 m, an inlet limit of
//! 1e300 C, a grid check that checks nothing, fans slowed past any prediction) are
//! refused as input errors (exit 2) that name the flag at fault and print the value
//! readably, not as hundreds of digits; so are flags that only act through another that
//! is off.

mod cli_support;
use cli_support::*;

/// No run of more than 20 digits: a value such as 1e-300 is printed with an exponent.
fn assert_readable(o: &std::process::Output) {
    let err = stderr(o);
    let longest = err
        .split(|c: char| !c.is_ascii_digit())
        .map(str::len)
        .max()
        .unwrap_or(0);
    assert!(longest <= 20, "a {longest}-digit number in: {err}");
}

fn simulate(dir: &std::path::Path, extra: &[&str]) -> std::process::Output {
    run(on_dataset("simulate", "of-dev-clean")
        .arg("--out")
        .arg(dir.join("pred.csv"))
        .args(extra))
}

#[test]
fn simulate_refuses_grids_and_limits_that_mean_nothing() {
    let dir = tmp("flag-values");
    for (extra, needle) in [
        (
            &["--grid-check", "1e-300"][..],
            "--grid-check: 1e-300 gives cells of",
        ),
        (
            &["--grid-check", "0.9999"][..],
            "--grid-check: 0.9999 gives cells of 0.2000 m: the model's own cells",
        ),
        (
            &["--grid-check", "0.5,0.5"][..],
            "--grid-check: 0.5 is given twice",
        ),
        (
            &["--grid-m", "1e-300"][..],
            "--grid-m: cells of 1e-300 m give",
        ),
        (
            &["--inlet-limit-c", "1e300"][..],
            "--inlet-limit-c: 1e300 C is not an air temperature",
        ),
        (
            &["--inlet-limit-c", "-1e300"][..],
            "--inlet-limit-c: -1e300 C is not an air temperature",
        ),
        (
            &["--fan-speed-scale", "1e300"][..],
            "--fan-speed-scale 1e300: CRAC `crac-1` in snapshot `t0` would run at 9e299",
        ),
    ] {
        let o = simulate(&dir, extra);
        assert_input_error(&o, needle);
        assert_readable(&o);
    }
    // Fans nearly stopped: air past anything the model can predict is the what-if's
    // fault, not a failed model (exit 1), and is refused before any solve.
    let o = simulate(&dir, &["--fan-speed-scale", "1e-5"]);
    assert_input_error(
        &o,
        "what if fan speeds x1e-5: snapshot `t0` would run its return air 1.21e6 K above its supply",
    );
    assert_readable(&o);
    assert!(!dir.join("pred.csv").exists());
}

#[test]
fn calibrate_refuses_a_cell_size_too_fine_to_build_by_its_flag() {
    let dir = tmp("flag-values-grid");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--grid-m", "1e-300", "--out"])
        .arg(dir.join("cal")));
    assert_input_error(&o, "--grid-m: cells of 1e-300 m give");
    assert_readable(&o);
    assert!(!dir.join("cal/runs.jsonl").exists());
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--nu=-1e-300", "--out"])
        .arg(dir.join("cal")));
    assert_input_error(&o, "--nu: expected a finite number >= 1");
    assert!(stderr(&o).contains("got -1e-300"), "{}", stderr(&o));
    assert_readable(&o);
}

/// A flag that only acts through another, given where that other is off, would be
/// ignored without a word: it is refused instead (clap's usage error, or ours), before
/// any output.
#[test]
fn flags_that_only_act_through_another_are_refused_where_it_is_off() {
    let dir = tmp("flag-values-pairs");
    let cal = dir.join("cal");
    for (extra, needle) in [
        (
            &["--no-grid-weighting", "--no-grid-check"][..],
            "'--no-grid-weighting' cannot be used with '--no-grid-check'",
        ),
        (
            &[
                "--linear-correction",
                "true",
                "--output-correction",
                "false",
            ][..],
            "--linear-correction true: the linear term corrects the output correction",
        ),
    ] {
        let o = run(on_dataset("calibrate", "of-dev-clean")
            .arg("--out")
            .arg(&cal)
            .args(extra));
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{}", stderr(&o));
        assert!(!cal.exists(), "no output for {extra:?}");
    }
    for (extra, needle) in [
        (
            &["--sensor-bias-rival", "6", "--no-single-output-check"][..],
            "'--sensor-bias-rival <BIC>' cannot be used with '--no-single-output-check'",
        ),
        (
            &["--refit-iterations", "2"][..],
            "the following required arguments were not provided: --refit <K>",
        ),
    ] {
        let o = run(diagnose_cmd(
            &data("of-dev-clean/hall.json"),
            &data("of-dev-clean/snapshots.csv"),
            &cal,
        )
        .args(extra));
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{}", stderr(&o));
    }
}

/// The command line's own refusals (clap's: an unknown subcommand or flag, a missing or
/// repeated argument, a value of the wrong type or not among the choices) are one line
/// like every other error, keeping clap's suggestion and the usage; help is not an error.
#[test]
fn command_line_refusals_are_one_line_and_help_is_not_an_error() {
    for (args, needle) in [
        (
            &["calibrat"][..],
            "a similar subcommand exists: 'calibrate'",
        ),
        (
            &["diagnose", "--refit-iterations", "2"][..],
            "not provided: --calibration <CALIBRATION>, --refit <K>",
        ),
        (
            &["calibrate", "--hall", "a", "--hall", "b"][..],
            "'--hall <HALL>' cannot be used multiple times (usage: kalibre calibrate",
        ),
        (
            &["simulate", "--grid-m", "abc"][..],
            "invalid value 'abc' for '--grid-m",
        ),
        (
            &["calibrate", "--likelihood", "cauchy"][..],
            "'--likelihood <LIKELIHOOD>' [possible values: student-t, gaussian]",
        ),
        (
            &["demo", "--no-such-flag"][..],
            "unexpected argument '--no-such-flag'",
        ),
    ] {
        let o = run(kalibre().args(args));
        assert_input_error(&o, needle);
    }
    for args in [&["--help"][..], &["calibrate", "--help"], &["--version"]] {
        let o = run(kalibre().args(args));
        assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
        assert!(!o.stdout.is_empty() && o.stderr.is_empty(), "{args:?}");
    }
}
