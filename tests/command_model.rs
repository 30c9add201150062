//! `kalibre calibrate --model command` end to end. The external command is `kalibre
//! simulate` itself, fed each snapshot and the parameters through `model.toml`'s
//! templates and read back by the regex parser, so the calibration must be the built-in
//! model's, run for run: the templates, the scenario variables, the parser and the hall's
//! parameter layout are all checked by one comparison.

mod cli_support;
use cli_support::*;

use std::fmt::Write as _;
use std::path::Path;

/// `{{name}}` in a template: the shortest text that reads back to the same number.
fn placeholder(name: &str) -> String {
    format!("{{{{{name}}}}}")
}

/// `model.toml` and its two templates in `dir`: one snapshot of the hall as a
/// `snapshots.csv`, and the parameters as `params.json`; `initial_alpha` is what the
/// file gives as every alpha's initial value.
fn write_command_model(dir: &Path, hall: &serde_json::Value, initial_alpha: f64) {
    let ids = |list: &serde_json::Value| -> Vec<String> {
        list.as_array()
            .unwrap()
            .iter()
            .map(|x| x["id"].as_str().unwrap().to_string())
            .collect()
    };
    let cracs = ids(&hall["cracs"]);
    let servers: Vec<String> = hall["racks"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| ids(&r["servers"]))
        .collect();
    let types = ids(&hall["server_types"]);
    let sensors = ids(&hall["sensors"]);

    let mut snapshot = String::from("snapshot,kind,id,value\n");
    for c in &cracs {
        for kind in ["setpoint_c", "fan_speed"] {
            let value = placeholder(&format!("{kind}/{c}"));
            writeln!(snapshot, "{},{kind},{c},{value}", placeholder("scenario")).unwrap();
        }
    }
    for s in &servers {
        let value = placeholder(&format!("power_w/{s}"));
        writeln!(snapshot, "{},power_w,{s},{value}", placeholder("scenario")).unwrap();
    }
    std::fs::write(dir.join("snapshot.csv.tmpl"), snapshot).unwrap();
    let params: Vec<String> = types
        .iter()
        .map(|t| format!("\"alpha/{t}\": {}", placeholder(&format!("alpha/{t}"))))
        .collect();
    std::fs::write(
        dir.join("params.json.tmpl"),
        format!("{{{}}}\n", params.join(", ")),
    )
    .unwrap();

    let quoted = |v: &[String]| {
        v.iter()
            .map(|s| format!("\"{s}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut toml = format!(
        "program = \"{}\"\n\
         args = [\"simulate\", \"--hall\", \"{}\", \"--snapshots\", \
         \"snapshot.csv\", \"--params\", \"params.json\", \"--out\", \"pred.csv\"]\n\
         runs_root = \"runs\"\n\
         timeout_s = 120\n\
         [[templates]]\nsource = \"snapshot.csv.tmpl\"\ndestination = \"snapshot.csv\"\n\
         [[templates]]\nsource = \"params.json.tmpl\"\ndestination = \"params.json\"\n\
         [output]\nfile = \"pred.csv\"\nparser = \"regex\"\nnames = [{}]\n\
         [output.regex]\n",
        env!("CARGO_BIN_EXE_kalibre"),
        data("of-dev-clean/hall.json").display(),
        quoted(&sensors)
    );
    for s in &sensors {
        writeln!(toml, "\"{s}\" = ',sensor_c,{s},(\\S+)'").unwrap();
    }
    for t in &types {
        let b = &hall["server_types"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["id"] == t.as_str())
            .unwrap()["alpha_cfm_per_w"];
        write!(
            toml,
            "[[params]]\nname = \"alpha/{t}\"\nlower = {}\nupper = {}\ninitial = {initial_alpha}\n",
            b["min"], b["max"]
        )
        .unwrap();
    }
    std::fs::write(dir.join("model.toml"), toml).unwrap();
}

/// The development hall's `hall.json`.
fn dev_hall() -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(data("of-dev-clean/hall.json")).unwrap()).unwrap()
}

/// Has `dir/model.toml` run its program through `sh -c script` (the program and its
/// arguments follow as `$0 "$@"`); `script` is written as in a TOML string.
fn run_under_sh(dir: &Path, script: &str) {
    let toml = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    let bin = env!("CARGO_BIN_EXE_kalibre");
    let wrapped = toml.replacen(
        &format!("program = \"{bin}\"\nargs = ["),
        &format!("program = \"sh\"\nargs = [\"-c\", \"{script}\", \"{bin}\", "),
        1,
    );
    assert_ne!(wrapped, toml, "the program line moved");
    std::fs::write(dir.join("model.toml"), wrapped).unwrap();
}

/// The best MAE and parameters of a calibration's `report.json`.
fn best(out: &Path) -> (f64, serde_json::Value, serde_json::Value) {
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    (
        report["best"]["mae_c"].as_f64().unwrap(),
        report["best"]["params"].clone(),
        report["runs"].clone(),
    )
}

#[test]
fn a_command_running_the_builtin_simulator_calibrates_as_the_builtin_model() {
    let dir = tmp("command-model");
    let hall = dev_hall();
    // Initial values other than the hall's: the search starts from the hall's, and says so.
    write_command_model(&dir, &hall, 0.3);
    let calibrate = |extra: &[&str], out: &str| {
        run(on_dataset("calibrate", "of-dev-clean")
            .args(["--iterations", "1", "--polish", "0", "--quiet", "--out"])
            .arg(dir.join(out))
            .args(extra))
    };
    let builtin = calibrate(&["--no-grid-check"], "builtin");
    assert_eq!(builtin.status.code(), Some(0), "{}", stderr(&builtin));
    let config = dir.join("model.toml");
    let command = calibrate(
        &["--model", "command", "--config", config.to_str().unwrap()],
        "command",
    );
    let err = stderr(&command);
    assert_eq!(command.status.code(), Some(0), "{err}");
    assert!(
        err.contains("kalibre: warning: ")
            && err.contains("these [[params]] give others, which are not used: alpha/web"),
        "{err}"
    );

    let (mae_builtin, params_builtin, runs_builtin) = best(&dir.join("builtin"));
    let (mae_command, params_command, runs_command) = best(&dir.join("command"));
    // The same runs in the same order: each value passes through text exactly.
    assert_eq!(runs_command, runs_builtin);
    assert_eq!(params_command, params_builtin);
    assert_eq!(mae_command, mae_builtin);
    let journal = std::fs::read_to_string(dir.join("command/runs.jsonl")).unwrap();
    assert!(!journal.contains(r#""status":"failed""#), "{journal}");

    // The calibrated command predicts as the calibrated built-in model; a command other
    // than the calibration's is said to be one.
    let simulate = |report: &str, config: &Path, out: &str| {
        let mut c = on_dataset("simulate", "of-dev-clean");
        c.arg("--params")
            .arg(dir.join(report))
            .arg("--out")
            .arg(dir.join(out));
        if out != "builtin.csv" {
            c.args(["--model", "command", "--config"]).arg(config);
        }
        run(&mut c)
    };
    let o = simulate("command/report.json", &config, "command.csv");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("note:"), "{}", stderr(&o));
    let o = simulate("builtin/report.json", &config, "builtin.csv");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    assert_eq!(read("command.csv"), read("builtin.csv"));
    let other = dir.join("other.toml");
    let toml = std::fs::read_to_string(&config).unwrap();
    std::fs::write(
        &other,
        toml.replacen("timeout_s = 120", "timeout_s = 120\nenv = { X = \"1\" }", 1),
    )
    .unwrap();
    let o = simulate("command/report.json", &other, "other.csv");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("describes another command than the one the calibration ran"),
        "{}",
        stderr(&o)
    );

    // The grid check runs the built-in simulator on finer grids: not for a command.
    let o = calibrate(
        &[
            "--model",
            "command",
            "--config",
            config.to_str().unwrap(),
            "--grid-check",
            "0.5",
        ],
        "refused",
    );
    assert_input_error(&o, "--grid-check runs the built-in simulator");
}

/// A `model.toml` that does not fit the hall is refused for what is wrong with it: a
/// `[[scenarios]]` list (even one whose variables the templates cannot render), two
/// sensors swapped in `output.names` (named where they part), and per-type `[[params]]`
/// with `--alpha per-server` (refused without first warning of per-type bounds).
#[test]
fn a_config_that_does_not_fit_the_hall_is_refused_for_its_real_fault() {
    let dir = tmp("command-misfit");
    let hall = dev_hall();
    write_command_model(&dir, &hall, 0.3);
    let good = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    let calibrate = |toml: &str, extra: &[&str]| {
        let config = dir.join("misfit.toml");
        std::fs::write(&config, toml).unwrap();
        run(on_dataset("calibrate", "of-dev-clean")
            .args(["--model", "command", "--config"])
            .arg(&config)
            .args(extra)
            .arg("--out")
            .arg(dir.join("out")))
    };
    // The templates use `setpoint_c/crac-1`, which this scenario lacks.
    let scenarios = format!("{good}[[scenarios]]\nlabel = \"t0\"\nvariables = {{ x = 1.0 }}\n");
    let o = calibrate(&scenarios, &[]);
    assert_input_error(
        &o,
        "misfit.toml: `scenarios`: [[scenarios]] are not used with a hall",
    );

    let swapped = good.replacen(
        "names = [\"c-A1-hi\", \"c-A1-lo\"",
        "names = [\"c-A1-lo\", \"c-A1-hi\"",
        1,
    );
    assert_ne!(swapped, good);
    let o = calibrate(&swapped, &[]);
    assert_input_error(
        &o,
        "output.names[0] is `c-A1-lo` where the hall has `c-A1-hi`, which comes at index 1",
    );

    // Per-server alpha: the hall's list is long, so the message says where the lists
    // part and shows a few names, not all.
    let o = calibrate(&good, &["--alpha", "per-server"]);
    assert_input_error(
        &o,
        "params must be the hall's calibrated parameters in order: params[0] is `alpha/",
    );
    assert!(stderr(&o).contains(" in all)]"), "{}", stderr(&o));
    assert!(!dir.join("out/runs.jsonl").exists());
}

/// Runs that fail (here the design's upper bounds, 2.9999999999999996 on the log scale:
/// the command exits with 3 there) are
/// journaled as failed, the loop goes on without them, and the summary says how many
/// failed, that a poor fit may be their doing, and at which bound they sit. A resume
/// with `--replay-failed` does not run them again; one without it does.
#[test]
fn failed_runs_are_counted_in_the_summary_with_what_to_do() {
    let dir = tmp("command-failing");
    let hall = dev_hall();
    write_command_model(&dir, &hall, 0.25);
    let fails = dir.join("fails.txt");
    run_under_sh(
        &dir,
        &format!(
            r#"case \"$(cat params.json)\" in *'gpu\": 2.99'*) echo x >> '{}'; exit 3;; esac; exec \"$0\" \"$@\""#,
            fails.display()
        ),
    );
    let calibrate = |extra: &[&str]| {
        run(on_dataset("calibrate", "of-dev-clean")
            .args([
                "--iterations",
                "1",
                "--polish",
                "0",
                "--quiet",
                "--model",
                "command",
            ])
            .args(extra)
            .arg("--config")
            .arg(dir.join("model.toml"))
            .arg("--out")
            .arg(dir.join("cal")))
    };
    let failures = || std::fs::read_to_string(&fails).unwrap().lines().count();
    let o = calibrate(&[]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let (_, _, runs) = best(&dir.join("cal"));
    let failed = runs["failed"].as_u64().unwrap();
    assert_eq!(failed, 3, "the upper bounds at each of 3 snapshots: {runs}");
    assert!(
        stdout.contains(&format!(
            "note: 3 of {} model runs failed (each one's reason is in runs.jsonl)",
            runs["total"]
        )),
        "{stdout}"
    );
    // Each failed at the upper bounds: the note says which bound, and to narrow it.
    // The most common reason is quoted, so that it is seen without reading the journal.
    assert!(
        stdout.contains("; all 3 failed runs in the journal: model run failed: "),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "; all 3 failed runs in the journal sit at a bound, 3 of them at alpha/web = 3 \
             (upper), alpha/db = 3 (upper), alpha/gpu = 3 (upper); if the model cannot run \
             there, narrow that bound in "
        ) && stdout.contains("hall.json, as a resume runs failed points again"),
        "{stdout}"
    );
    assert_eq!(failures(), 3);

    // Replayed: the same failures, and the command is not run at them again.
    let o = calibrate(&["--replay-failed"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(failures(), 3, "a replayed failure ran again");
    assert!(
        stderr(&o).contains("3 run(s) journaled only as failed are replayed as failures"),
        "{}",
        stderr(&o)
    );
    assert_eq!(best(&dir.join("cal")).2["failed"].as_u64(), Some(3));
    // A plain resume tries them again.
    let o = calibrate(&[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(failures(), 6);
    assert!(
        stderr(&o).contains("3 run(s) journaled only as failed were not replayed"),
        "{}",
        stderr(&o)
    );
}

/// Ctrl-C (SIGINT) or a kill (SIGTERM) of `kalibre calibrate` ends the model runs in
/// progress with it, down to the processes a run's script started: each run has its own
/// process group, which the terminal's signal does not reach, and the kernel's
/// parent-death signal reaches only the script (a solver it started ran on). A run that
/// ignores SIGTERM gets SIGKILL after its `kill_grace_s`, before kalibre ends, so that it
/// does not run on beyond the stop.
#[cfg(target_os = "linux")]
#[test]
fn ending_kalibre_ends_the_runs_in_progress() {
    for (signal, ignores_term) in [
        (libc::SIGINT, false),
        (libc::SIGTERM, false),
        (libc::SIGINT, true),
    ] {
        let dir = tmp(&format!("command-interrupted-{signal}-{ignores_term}"));
        let hall = dev_hall();
        write_command_model(&dir, &hall, 0.25);
        let pids = dir.join("pids");
        // Each run: a "solver" in the background, then wait for it; SIGTERM ignored by
        // both when asked (the ignoring is inherited).
        let trap = if ignores_term { "trap '' TERM; " } else { "" };
        run_under_sh(
            &dir,
            &format!("{trap}sleep 60 & echo $! >> {}; wait", pids.display()),
        );
        if ignores_term {
            let toml = std::fs::read_to_string(dir.join("model.toml")).unwrap();
            std::fs::write(dir.join("model.toml"), format!("kill_grace_s = 1\n{toml}")).unwrap();
        }
        let child = on_dataset("calibrate", "of-dev-clean")
            .args([
                "--quiet",
                "--threads",
                "2",
                "--model",
                "command",
                "--config",
            ])
            .arg(dir.join("model.toml"))
            .arg("--out")
            .arg(dir.join("cal"))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let started = std::time::Instant::now();
        let running = || -> Vec<i32> {
            std::fs::read_to_string(&pids)
                .unwrap_or_default()
                .lines()
                .filter_map(|l| l.trim().parse().ok())
                .collect()
        };
        while running().is_empty() {
            assert!(started.elapsed().as_secs() < 60, "no run started");
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        // SAFETY: signalling the child we started.
        unsafe {
            libc::kill(child.id() as i32, signal);
        }
        let out = child.wait_with_output().unwrap();
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(out.status.signal(), Some(signal), "{out:?}");
        let said = String::from_utf8_lossy(&out.stderr);
        assert!(
            said.contains("the model runs in progress were ended with it"),
            "{said}"
        );
        // Every "solver" started is gone (killed, or reaped by init once killed).
        let alive = |pid: i32| {
            std::path::Path::new(&format!("/proc/{pid}")).exists()
                && !std::fs::read_to_string(format!("/proc/{pid}/stat"))
                    .unwrap_or_default()
                    .contains(") Z ")
        };
        let until = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while running().into_iter().any(alive) && std::time::Instant::now() < until {
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let left: Vec<i32> = running().into_iter().filter(|p| alive(*p)).collect();
        assert!(
            left.is_empty(),
            "signal {signal}, SIGTERM ignored {ignores_term}: solvers still running: {left:?}"
        );
        // The runs the stop killed, and those it refused to start, are not the model's
        // failures: journaled as failed, a resume would report and replay them as such.
        let journal = std::fs::read_to_string(dir.join("cal").join("runs.jsonl"));
        let failed: Vec<String> = (journal.unwrap_or_default().lines())
            .filter(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["status"] == "failed")
            .map(str::to_string)
            .collect();
        assert!(
            failed.is_empty(),
            "signal {signal}, SIGTERM ignored {ignores_term}: journaled as failed: {failed:?}"
        );
    }
}

/// A stopped `kalibre simulate` says it keeps no journal. The directories of the runs
/// its stop killed are removed, and counted on stderr, by the next command on that model;
/// a failed run's directory is kept.
#[cfg(target_os = "linux")]
#[test]
fn killed_runs_directories_are_removed_by_the_next_command() {
    let dir = tmp("command-killed-dirs");
    let hall = dev_hall();
    write_command_model(&dir, &hall, 0.25);
    let (fail, started) = (dir.join("fail"), dir.join("started"));
    run_under_sh(
        &dir,
        &format!(
            "test -e {} && exit 3; touch partial {}; sleep 60",
            fail.display(),
            started.display()
        ),
    );
    let simulate = || {
        let mut c = on_dataset("simulate", "of-dev-clean");
        c.args(["--model", "command", "--config"])
            .arg(dir.join("model.toml"))
            .arg("--out")
            .arg(dir.join("pred.csv"))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        c
    };
    let child = simulate().spawn().unwrap();
    let t0 = std::time::Instant::now();
    while !started.exists() {
        assert!(t0.elapsed().as_secs() < 60, "no run started");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // SAFETY: signalling the child we started.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let out = child.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("(simulate keeps no journal: run it again"),
        "{said}"
    );
    let runs = |marked: bool| -> Vec<std::path::PathBuf> {
        let mut found: Vec<_> = std::fs::read_dir(dir.join("runs"))
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.is_dir())
            .filter(|p| {
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                p.with_file_name(format!(".{name}.running")).exists() == marked
            })
            .collect();
        found.sort();
        found
    };
    let killed = runs(true);
    assert_eq!(killed.len(), 1, "{killed:?}");
    assert!(killed[0].join("partial").is_file());

    std::fs::write(&fail, "").unwrap();
    let out = simulate().output().unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.contains("kalibre: note: removed 1 run directory that runs killed mid-run left"),
        "{said}"
    );
    assert!(said.contains("exited with code 3"), "{said}");
    // The killed run's files are gone (its name may be the failed run's now).
    assert!(!killed[0].join("partial").exists(), "{killed:?}");
    let kept = runs(false);
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert!(!kept[0].join("partial").exists(), "{kept:?}");
    assert!(runs(true).is_empty());
    // The failed run's directory stays, unmarked, and the next command keeps it.
    let out = simulate().output().unwrap();
    assert!(!String::from_utf8_lossy(&out.stderr).contains("removed"));
    assert!(kept[0].is_dir());
}

/// `kalibre simulate --model command` runs the command once per snapshot: with `kalibre
/// simulate` itself as the command its predictions are the built-in model's, digit for
/// digit; a failed run ends it with the reason and the kept directory; the built-in
/// simulator's extras are refused, as is `--config` without `--model command`.
#[test]
fn simulate_runs_the_command_at_the_given_parameters() {
    let dir = tmp("command-simulate");
    let hall = dev_hall();
    write_command_model(&dir, &hall, 0.25);
    let params = dir.join("params.json");
    std::fs::write(
        &params,
        r#"{"alpha/web": 0.14, "alpha/db": 0.19, "alpha/gpu": 0.11}"#,
    )
    .unwrap();
    let config = dir.join("model.toml");
    let simulate = |extra: &[&str], out: &str| {
        run(on_dataset("simulate", "of-dev-clean")
            .arg("--params")
            .arg(&params)
            .arg("--out")
            .arg(dir.join(out))
            .args(extra))
    };
    let builtin = simulate(&[], "builtin.csv");
    assert_eq!(builtin.status.code(), Some(0), "{}", stderr(&builtin));
    let with_command = ["--model", "command", "--config", config.to_str().unwrap()];
    let command = simulate(&with_command, "command.csv");
    assert_eq!(command.status.code(), Some(0), "{}", stderr(&command));
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    assert_eq!(read("command.csv"), read("builtin.csv"));
    let said = String::from_utf8_lossy(&command.stdout);
    assert!(said.contains(": the command ran in "), "{said}");

    let o = simulate(&[&with_command[..], &["--vtk", "vtk"]].concat(), "x.csv");
    assert_input_error(&o, "--vtk is not available with --model command");
    let o = simulate(&["--config", config.to_str().unwrap()], "x.csv");
    assert_input_error(&o, "--config is for --model command");
    let o = simulate(&["--model", "command"], "x.csv");
    assert_input_error(&o, "--model command needs --config model.toml");

    run_under_sh(&dir, "echo no licence >&2; exit 3");
    let o = simulate(&with_command, "failed.csv");
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("exited with code 3")
            && err.contains("its log: `no licence`")
            && err.contains("its directory is kept: "),
        "{err}"
    );
    assert!(!dir.join("failed.csv").exists());
}
