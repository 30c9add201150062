//! Killing `kalibre calibrate --model openfoam` while OpenFOAM solves, then running it
//! again: no OpenFOAM process is left behind, no finished run is repeated, and the killed
//! solves' run directories are removed.
//!
//! These tests need OpenFOAM (Debian's `openfoam` package; CI installs it). Without
//! `blockMesh` in PATH they fail with a message saying so; they never skip.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use kalibre_dc::snapshots;

mod cli_support;
mod openfoam_common;
use cli_support::assert_each_run_once;
use openfoam_common::*;

fn journal_lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

fn calibrate_cmd(dir: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_kalibre"));
    c.args([
        "calibrate",
        "--model",
        "openfoam",
        "--of-iterations",
        &SMALL_ITERATIONS.to_string(),
        "--iterations",
        "1",
        "--threads",
        "2",
        "--seed",
        "5",
        "--quiet",
        "--hall",
    ])
    .arg(dir.join("hall.json"))
    .arg("--snapshots")
    .arg(dir.join("snapshots.csv"))
    .arg("--out")
    .arg(dir.join("out"));
    c
}

/// Killing `kalibre calibrate --model openfoam` while OpenFOAM is solving and starting it
/// again repeats no finished run.
#[test]
fn openfoam_calibration_resumes_after_kill_without_repeating_runs() {
    require_openfoam();
    let (hall, snaps) = small_hall();
    // One snapshot: resuming works run by run, whatever the snapshot, and each
    // OpenFOAM solve is about ten seconds of the suite.
    let snaps = &snaps[..1];
    let dir = tmp("resume");
    hall.save(&dir.join("hall.json")).unwrap();
    std::fs::write(
        dir.join("snapshots.csv"),
        snapshots::write_snapshots(hall, snaps),
    )
    .unwrap();
    let journal = dir.join("out/runs.jsonl");
    let mut child = calibrate_cmd(&dir).spawn().unwrap();
    let start = Instant::now();
    while journal_lines(&journal).len() < 3 && start.elapsed() < Duration::from_secs(240) {
        std::thread::sleep(Duration::from_millis(100));
    }
    // Let the next solve get going, then kill kalibre in the middle of it.
    std::thread::sleep(Duration::from_secs(2));
    let solving = solver_pids_under(&dir.join("out/openfoam"));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        !solving.is_empty(),
        "no OpenFOAM solve was running at the kill"
    );
    // The solve has its own process group, so the kill does not reach it; the kernel
    // ends it when kalibre ends (PR_SET_PDEATHSIG), rather than letting it run on.
    let t = Instant::now();
    while !solver_pids_under(&dir.join("out/openfoam")).is_empty()
        && t.elapsed() < Duration::from_secs(20)
    {
        std::thread::sleep(Duration::from_millis(100));
    }
    let left = solver_pids_under(&dir.join("out/openfoam"));
    for pid in &left {
        // SAFETY: kill has no memory effects; these are processes this test started.
        unsafe {
            libc_kill(*pid, 9);
        }
    }
    assert!(
        left.is_empty(),
        "solver processes outlived kalibre: {left:?}"
    );
    let before = journal_lines(&journal);
    let done_before = before.len();
    assert!(done_before >= 3, "only {done_before} runs before the kill");
    // The killed solves' directories are left behind, marked as unfinished.
    let interrupted = marked_run_dirs(&dir.join("out/openfoam"));
    assert!(
        !interrupted.is_empty(),
        "no run directory of the killed solve"
    );

    let o = calibrate_cmd(&dir).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // The resume clears them, says so, and leaves no marker.
    let n = interrupted.len();
    let dirs = if n == 1 { "directory" } else { "directories" };
    assert!(
        err.contains(&format!(
            "kalibre: note: removed {n} run {dirs} that runs killed"
        )),
        "{err}"
    );
    assert!(interrupted.iter().all(|d| !d.exists()), "{interrupted:?}");
    // The summary says how steady the readings are at the best parameters.
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("OpenFOAM probe fluctuation   mean "),
        "{said}"
    );
    assert!(marked_run_dirs(&dir.join("out/openfoam")).is_empty());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/report.json")).unwrap())
            .unwrap();
    let total = report["runs"]["total"].as_u64().unwrap() as usize;
    assert!(
        done_before < total,
        "killed before the end ({done_before} of {total})"
    );
    // Every run that gave a result is replayed; one that failed (a design corner can
    // miss the energy balance) runs again, as its cause may have passed.
    let ok_before = before.iter().filter(|r| r["status"] == "ok").count();
    assert_eq!(
        report["runs"]["cached"].as_u64().unwrap() as usize,
        ok_before
    );
    assert_eq!(
        report["runs"]["new"].as_u64().unwrap() as usize,
        total - ok_before,
        "no finished run is repeated"
    );
    let ok_runs: Vec<serde_json::Value> = journal_lines(&journal)
        .into_iter()
        .filter(|r| r["status"] == "ok")
        .collect();
    assert_each_run_once(&ok_runs);
    // Every run journals its servers' intakes, so the report shows them at the best
    // parameters without another solve.
    let servers = hall.servers().count();
    for run in journal_lines(&journal)
        .iter()
        .filter(|r| r["status"] == "ok")
    {
        let intakes = run["extras"]["server_intake_c"].as_array();
        assert_eq!(intakes.map(Vec::len), Some(servers), "{run}");
    }
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    let per_snapshot = format!(" of {servers} above 27.0 C");
    assert_eq!(html.matches(&per_snapshot).count(), snaps.len(), "{html}");

    // `kalibre diagnose` must solve with the model the calibration ran: the built-in
    // simulator, or OpenFOAM with other settings, is refused before any solve.
    let diagnose = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_kalibre"))
            .arg("diagnose")
            .args(extra)
            .arg("--hall")
            .arg(dir.join("hall.json"))
            .arg("--snapshots")
            .arg(dir.join("snapshots.csv"))
            .arg("--calibration")
            .arg(dir.join("out"))
            .output()
            .unwrap()
    };
    for (extra, model) in [
        (&[][..], "builtin"),
        (
            &["--model", "openfoam", "--of-iterations", "300"][..],
            "openfoam",
        ),
    ] {
        let o = diagnose(extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(
            err.contains("runs of another model") && err.contains(&format!("--model {model}")),
            "{extra:?}: {err}"
        );
    }
}

/// Ctrl-C while OpenFOAM meshes (before any solve) ends the mesh's processes with kalibre
/// and says that it ended OpenFOAM's work in progress, not only "model runs"; the
/// half-built mesh stays marked, for the next command's sweep.
#[test]
fn ctrl_c_while_meshing_ends_the_mesh_and_says_so() {
    require_openfoam();
    // A mesh step may end in the instant before the signal: then nothing was in progress,
    // and the plain message is the right one. So up to three tries, each meshing anew.
    let ended = (0..3).any(ctrl_c_while_meshing);
    assert!(ended, "no try caught a mesh program running");
}

/// One try of [`ctrl_c_while_meshing_ends_the_mesh_and_says_so`]: whether the signal
/// ended a mesh program (checking everything else either way).
fn ctrl_c_while_meshing(attempt: usize) -> bool {
    use std::os::unix::process::ExitStatusExt;
    let (hall, snaps) = small_hall();
    let dir = tmp(&format!("ctrl-c-mesh-{attempt}"));
    hall.save(&dir.join("hall.json")).unwrap();
    std::fs::write(
        dir.join("snapshots.csv"),
        snapshots::write_snapshots(hall, &snaps[..1]),
    )
    .unwrap();
    let builds = dir.join("out/openfoam/mesh-builds");
    let child = calibrate_cmd(&dir)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Until a mesh program runs in the build directory (its marker comes first, while
    // kalibre writes the case's dictionaries).
    let meshing = |b: &Path| b.is_dir() && !solver_pids_under(b).is_empty();
    let start = Instant::now();
    while !meshing(&builds) && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let building = marked_dirs(&builds);
    // SAFETY: signalling a child this test started and has not reaped.
    unsafe {
        libc_kill(child.id() as i32, 2);
    }
    let o = child.wait_with_output().unwrap();
    assert!(!building.is_empty(), "no mesh was being built");
    assert_eq!(o.status.signal(), Some(2), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    let ended =
        err.contains("kalibre: stopped; the OpenFOAM solves or meshing in progress were ended");
    assert!(
        ended || err.contains("kalibre: stopped; finished model runs are kept in"),
        "{err}"
    );
    assert!(
        err.contains("runs.jsonl: the same command resumes"),
        "{err}"
    );
    // No mesher outlives kalibre.
    let t = Instant::now();
    while !solver_pids_under(&builds).is_empty() && t.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(100));
    }
    let left = solver_pids_under(&builds);
    for pid in &left {
        // SAFETY: kill has no memory effects; these are processes this test started.
        unsafe {
            libc_kill(*pid, 9);
        }
    }
    assert!(left.is_empty(), "mesh processes outlived kalibre: {left:?}");
    // Left marked as unfinished, so the next command's sweep removes it.
    assert!(
        building.iter().all(|d| d.is_dir()) && !marked_dirs(&builds).is_empty(),
        "{building:?}"
    );
    let _ = std::fs::remove_dir_all(dir);
    ended
}

/// The directories directly under `root` that a marker (`.<name>.running`) says are in
/// use.
fn marked_dirs(root: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(root)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let run = name
                .strip_prefix('.')?
                .strip_suffix(".running")?
                .to_string();
            Some(root.join(run)).filter(|d| d.is_dir())
        })
        .collect()
}

/// The run directories under `root`'s `runs-*` that a marker (`.<name>.running`) says
/// are a run's that has not ended.
fn marked_run_dirs(root: &Path) -> Vec<std::path::PathBuf> {
    let mut dirs = Vec::new();
    for runs in std::fs::read_dir(root).into_iter().flatten().flatten() {
        if !runs.file_name().to_string_lossy().starts_with("runs-") {
            continue;
        }
        for e in std::fs::read_dir(runs.path())
            .into_iter()
            .flatten()
            .flatten()
        {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(run) = name
                .strip_prefix('.')
                .and_then(|n| n.strip_suffix(".running"))
            {
                let dir = runs.path().join(run);
                if dir.is_dir() {
                    dirs.push(dir);
                }
            }
        }
    }
    dirs
}

extern "C" {
    #[link_name = "kill"]
    fn libc_kill(pid: i32, sig: i32) -> i32;
}
