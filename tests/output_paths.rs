//! Where results are written: never over an input, a report or a run journal, never one
//! output over another, never a file renamed over a device or FIFO; output that cannot be
//! written is an error with exit code 1, not a panic. And a synthetic hall never hides an
//! effect of size 0.

mod cli_support;

use std::path::Path;
use std::process::Stdio;

use cli_support::{assert_input_error, data, diagnose_cmd, kalibre, run, stderr, tmp};

/// `kalibre simulate` of the development hall with `extra` flags.
fn simulate(extra: &[&std::ffi::OsStr]) -> std::process::Output {
    run(kalibre()
        .args(["simulate", "--hall"])
        .arg(data("of-dev-clean/hall.json"))
        .arg("--snapshots")
        .arg(data("of-dev-clean/snapshots.csv"))
        .args(extra))
}

fn os(p: &Path) -> &std::ffi::OsStr {
    p.as_os_str()
}

#[test]
fn outputs_never_replace_inputs_journals_or_each_other() {
    let dir = tmp("output-paths");
    let (pred, servers) = (dir.join("pred.csv"), dir.join("servers.csv"));
    let o = simulate(&["--out".as_ref(), os(&pred), "--servers".as_ref(), os(&pred)]);
    assert_input_error(&o, "--servers");
    assert!(
        stderr(&o).contains("is also the --out file"),
        "{}",
        stderr(&o)
    );
    let o = simulate(&[
        "--out".as_ref(),
        os(&pred),
        "--servers".as_ref(),
        os(&servers),
        "--heat-sources".as_ref(),
        os(&dir.join(".").join("servers.csv")),
    ]);
    assert_input_error(&o, "is also the --servers file");
    assert!(!pred.exists() && !servers.exists());

    // A calibration's report as --params: its journal beside it is not an output.
    let cal = dir.join("cal");
    std::fs::create_dir_all(&cal).unwrap();
    let journal = cal.join("runs.jsonl");
    std::fs::write(&journal, "{}\n").unwrap();
    let params = cal.join("report.json");
    std::fs::write(&params, "{}").unwrap();
    let o = simulate(&[
        "--params".as_ref(),
        os(&params),
        "--out".as_ref(),
        os(&pred),
        "--servers".as_ref(),
        os(&journal),
    ]);
    assert_input_error(&o, "is the run journal beside --params");
    assert_eq!(std::fs::read_to_string(&journal).unwrap(), "{}\n");

    // diagnose --write-hall onto any of its inputs, checked before anything is read.
    let snaps = dir.join("snapshots.csv");
    std::fs::copy(data("of-dev-clean/snapshots.csv"), &snaps).unwrap();
    let hall = data("of-dev-clean/hall.json");
    for (target, what) in [
        (snaps.as_path(), "is the --snapshots file"),
        (hall.as_path(), "is the --hall file"),
        (params.as_path(), "is the calibration's report"),
        (journal.as_path(), "is the calibration's run journal"),
    ] {
        let o = run(diagnose_cmd(&hall, &snaps, &cal)
            .arg("--write-hall")
            .arg(target));
        assert_input_error(&o, what);
    }
    assert_eq!(std::fs::read_to_string(&journal).unwrap(), "{}\n");

    // --vtk's files: one named as an input, as --out, or --vtk at --out's path.
    let vtk = dir.join("vtk");
    std::fs::create_dir_all(&vtk).unwrap();
    let hall_in_vtk = vtk.join("t0.vtk");
    std::fs::copy(&hall, &hall_in_vtk).unwrap();
    let vtk_at = |out: &Path, vtk: &Path, hall: &Path| {
        run(
            cli_support::on_files("simulate", hall, &data("of-dev-clean/snapshots.csv"))
                .arg("--out")
                .arg(out)
                .arg("--vtk")
                .arg(vtk),
        )
    };
    let o = vtk_at(&pred, &vtk, &hall_in_vtk);
    assert_input_error(&o, "--vtk's t0.vtk");
    assert_input_error(&o, "is the --hall file");
    let o = vtk_at(&vtk.join("t1.vtk"), &vtk, &hall);
    assert_input_error(&o, "is also the --out file");
    let o = vtk_at(&pred, &pred, &hall);
    assert_input_error(&o, "--vtk");
    assert_input_error(&o, "is also the --out file");
    assert!(!pred.exists() && !vtk.join("t1.vtk").exists());
    let text = std::fs::read_to_string(&hall).unwrap();
    assert_eq!(std::fs::read_to_string(&hall_in_vtk).unwrap(), text);

    // calibrate --out holding an input under an output's name.
    let out = dir.join("cal-out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::copy(&hall, out.join("report.json")).unwrap();
    let o = run(cli_support::on_files(
        "calibrate",
        &out.join("report.json"),
        &data("of-dev-clean/snapshots.csv"),
    )
    .arg("--out")
    .arg(&out));
    assert_input_error(&o, "--out's report.json");
    assert_input_error(&o, "is the --hall file");
    assert_eq!(
        std::fs::read_to_string(out.join("report.json")).unwrap(),
        text
    );
}

/// `--out` a FIFO, or stdout: the predictions go through it, and a FIFO stays one
/// (renamed over, a device such as /dev/null would have become a file for every process).
#[cfg(unix)]
#[test]
fn a_fifo_out_is_written_into_not_replaced() {
    let dir = tmp("fifo-out");
    let fifo = dir.join("pred.fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    let o = simulate(&["--out".as_ref(), os(&fifo)]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Checked before waiting on the reader, which a replaced FIFO would leave blocked.
    assert!(!std::fs::metadata(&fifo).unwrap().is_file());
    let text = reader.join().unwrap();
    assert!(text.starts_with("snapshot,kind,id,value\n"), "{text}");
    assert_eq!(text.lines().count(), 1 + 3 * 24);
    // `--out /dev/stdout` with stdout a pipe: the link leads to `pipe:[N]`, no path, and
    // the predictions used to fail there after the solves.
    #[cfg(target_os = "linux")]
    {
        let o = simulate(&["--out".as_ref(), "/dev/stdout".as_ref()]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(String::from_utf8_lossy(&o.stdout), text);
    }
}

/// Output to a full device: a one-line error and exit code 1, not a panic (101); an input
/// error whose message cannot be written keeps its exit code 2.
#[cfg(target_os = "linux")]
#[test]
fn a_full_stdout_or_stderr_is_an_error_not_a_panic() {
    let full = || {
        Stdio::from(
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap(),
        )
    };
    let dir = tmp("full");
    let o = kalibre()
        .args(["synth", "--out"])
        .arg(dir.join("s"))
        .stdout(full())
        .output()
        .unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("kalibre: error: failed printing to stdout"),
        "{err}"
    );
    let o = kalibre()
        .args(["simulate", "--hall"])
        .arg(dir.join("missing.json"))
        .args(["--snapshots", "s.csv", "--out", "p.csv"])
        .stderr(full())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
}

/// Each output whole or not at all, the side tables before the predictions: a table that
/// cannot be written (a full device) leaves --out as it was, not new predictions beside
/// an old table.
#[test]
fn a_side_table_that_cannot_be_written_leaves_the_predictions_as_they_were() {
    let dir = tmp("full-table");
    let pred = dir.join("pred.csv");
    std::fs::write(&pred, "old\n").unwrap();
    for flag in ["--servers", "--heat-sources"] {
        let o = simulate(&[
            "--out".as_ref(),
            os(&pred),
            flag.as_ref(),
            "/dev/full".as_ref(),
        ]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{flag}: {err}");
        assert!(err.contains("/dev/full"), "{flag}: {err}");
        assert_eq!(std::fs::read_to_string(&pred).unwrap(), "old\n", "{flag}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_hidden_effect_of_size_zero_or_not_a_number_is_refused() {
    let dir = tmp("inert");
    for (effect, needle) in [
        (
            "crac_supply_offset",
            "offset_c is 0 (its default), which hides nothing",
        ),
        (
            "bypass:behind_rack=A03,fraction=0",
            "fraction is 0, which hides nothing",
        ),
        // Not a number: refused as such, not taken for the default 0.
        (
            "crac_supply_offset:offset_c=abc",
            "field `offset_c`: expected a finite number, got \"abc\"",
        ),
    ] {
        let o = run(kalibre()
            .args(["synth", "--effect", effect, "--out"])
            .arg(dir.join("s")));
        assert_input_error(&o, needle);
    }
    assert!(!dir.join("s").exists());
}

/// An output file path that cannot take a file (a directory, `.`, a directory that
/// cannot be made or written in) is an input error before the solves; it used to fail with exit 1
/// after them. A missing directory is made.
#[test]
fn an_output_path_that_cannot_take_a_file_is_refused_first() {
    let dir = tmp("output-file-paths");
    let blocked = dir.join("a-file");
    std::fs::write(&blocked, "not a directory").unwrap();
    let under_file = blocked.join("pred.csv");
    let pred = dir.join("pred.csv");
    for (flag, path, why) in [
        ("--out", dir.as_path(), "is a directory"),
        ("--out", Path::new("."), "is a directory"),
        ("--out", under_file.as_path(), "a-file cannot be made"),
        ("--servers", under_file.as_path(), "a-file cannot be made"),
        // A directory no one may write in, root included (so the test holds as root).
        (
            "--out",
            Path::new("/proc/kalibre-pred.csv"),
            "no file can be written in its directory",
        ),
    ] {
        let mut extra = vec!["--out".as_ref(), os(&pred)];
        if flag == "--out" {
            extra.clear();
        }
        extra.extend([flag.as_ref(), path.as_os_str()]);
        let o = simulate(&extra);
        assert_input_error(&o, &format!("{flag} {}: ", path.display()));
        assert_input_error(&o, why);
    }
    assert!(!pred.exists());
    // A missing directory is made, for each output file.
    let fresh = dir.join("new").join("deeper");
    let o = simulate(&[
        "--out".as_ref(),
        os(&fresh.join("pred.csv")),
        "--servers".as_ref(),
        os(&dir.join("new2").join("servers.csv")),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(fresh.join("pred.csv").is_file() && dir.join("new2/servers.csv").is_file());
}

/// `diagnose --write-hall /dev/stdout` with stdout redirected to a file: the hall renamed
/// over that file dropped the diagnosis printed there. Refused first.
#[cfg(target_os = "linux")]
#[test]
fn write_hall_onto_the_file_stdout_writes_to_is_refused() {
    let dir = tmp("write-hall-stdout");
    let printed = dir.join("printed.txt");
    let o = diagnose_cmd(
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
        &dir.join("no-calibration"),
    )
    .args(["--json", "--write-hall", "/dev/stdout"])
    .stdout(std::fs::File::create(&printed).unwrap())
    .stderr(Stdio::piped())
    .output()
    .unwrap();
    assert_input_error(&o, "--write-hall /dev/stdout: is the file stdout writes to");
}
