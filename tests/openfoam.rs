//! OpenFOAM as the model: realism on the OpenFOAM development hall, a calibration with
//! OpenFOAM doing every model run, kill and resume of `kalibre calibrate --model
//! openfoam`, and failed (killed) runs recorded while the loop goes on.
//!
//! These tests need OpenFOAM (Debian's `openfoam` package; CI installs it). Without
//! `blockMesh` in PATH they fail with a message saying so; they never skip.

use std::process::Command;
use std::time::{Duration, Instant};

use kalibre_core::{Model, ModelError, Outputs};
use kalibre_dc::calibration::HallCalibrationSettings;
use kalibre_dc::calibration_model::calibrate_hall_model;
use kalibre_dc::effects::Effect;
use kalibre_dc::hall::{EffectSpec, Hall};
use kalibre_dc::openfoam::{OpenFoamModel, OpenFoamSettings, M3_S_PER_CFM};
use kalibre_dc::sim::SimMods;
use kalibre_dc::snapshots::{self, OperatingState};
use kalibre_dc::ParamLayout;

mod openfoam_common;
use openfoam_common::*;

/// The development datasets' snapshots.
const ALL: [&str; 3] = ["t0", "t1", "t2"];

/// Four-step iterations of the calibration test.
const CAL_ITERATIONS: usize = 6;
/// Polish steps of the calibration test: one takes the polish's path with OpenFOAM (a
/// Jacobian from the model's runs, a step); the default 8 spent 52 more solves, 5 of
/// the suite's minutes, on an error the loop had already brought to 0.09 C.
const CAL_POLISH_ITERATIONS: usize = 1;

/// Runs `hall` (with its own effects, at their initial values) at the true alphas on the
/// snapshots `labels` in parallel and returns the MAE (C) against `dataset`'s noise-free
/// OpenFOAM readings, checking each run's energy balance on the way.
fn mae_against_openfoam_data(dataset: &str, hall: &Hall, labels: &[&str], tag: &str) -> f64 {
    let mut snaps =
        snapshots::load_snapshots(hall, &data(&format!("{dataset}/snapshots.csv"))).unwrap();
    snaps.retain(|s| labels.contains(&s.state.label.as_str()));
    assert_eq!(snaps.len(), labels.len(), "{dataset}: snapshots {labels:?}");
    let truth = truth(dataset);
    let dir = tmp(tag);
    let model =
        OpenFoamModel::new(hall, OpenFoamSettings::default().with_cache_root(&dir)).unwrap();
    let space = model.layout().space();
    let params = truth_with_effects(space);
    let results = side_by_side(snaps.iter().map(|s| &s.state), |state| {
        model.evaluate_timed(state, &params)
    });
    let mut all_got = Vec::new();
    let mut all_want = Vec::new();
    for (snap, r) in snaps.iter().zip(results) {
        let (out, timing) = r.unwrap_or_else(|e| panic!("{}: {e}", snap.state.label));
        let want = noise_free_at(&truth, hall, &snap.state.label);
        let m = mae(&out.values, &want);
        eprintln!(
            "{dataset} {}: MAE {m:.3} C, energy balance {:+.3} %, solve {:.1} s, kalibre {:.4} s",
            snap.state.label,
            100.0 * timing.energy_balance,
            timing.solve_s,
            timing.prepare_s + timing.parse_s + timing.cleanup_s
        );
        // Issue 7's overhead target is measured by `examples/run_overhead.rs`, not here:
        // a loaded machine's disk makes the cleanup time swing.
        // The balance closes (the datasets: -0.8 to -0.9 %).
        assert!(timing.energy_balance.abs() < 0.01, "{timing:?}");
        let spread = out.spread.expect("probe spread kept");
        assert!(spread.iter().all(|s| s.is_finite() && *s >= 0.0));
        all_got.extend(out.values);
        all_want.extend(want);
    }
    let m = mae(&all_got, &all_want);
    eprintln!(
        "{dataset} at the true alpha: MAE {m:.3} C over {} values",
        all_got.len()
    );
    m
}

/// One snapshot's noise-free readings in a dataset's truth, in `hall`'s sensor order.
fn noise_free_at(truth: &serde_json::Value, hall: &Hall, label: &str) -> Vec<f64> {
    hall.sensors
        .iter()
        .map(|s| {
            truth["snapshots"][label]["sensor_c_noise_free"][&s.id]
                .as_f64()
                .unwrap()
        })
        .collect()
}

/// A hidden effect's footprint: the MAE (C) between `dataset`'s noise-free readings and
/// the clean hall's, over the three snapshots.
fn footprint_c(hall: &Hall, dataset: &str) -> f64 {
    let readings = |d: &str| -> Vec<f64> {
        let t = truth(d);
        ["t0", "t1", "t2"]
            .iter()
            .flat_map(|label| noise_free_at(&t, hall, label))
            .collect()
    };
    mae(&readings("of-dev-clean"), &readings(dataset))
}

/// At the true alphas the adapter reproduces the development hall's noise-free OpenFOAM
/// readings (made with the same solver by another route), with a closed energy balance:
/// at t1 and t2 here, at t0 through the command line in `tests/simulate_openfoam.rs`
/// (0.083-0.087 C each when all three ran here; a development-hall solve is about 36 s
/// of CPU).
#[test]
fn dev_hall_at_true_alpha_matches_the_openfoam_data() {
    require_openfoam();
    let hall = Hall::load(&data("of-dev-clean/hall.json")).unwrap();
    let m = mae_against_openfoam_data("of-dev-clean", &hall, &["t1", "t2"], "realism");
    // The datasets' own noise is 0.15 C; the model at the hall's initial alpha is 4.9 C off.
    assert!(m < 0.15, "MAE {m:.3} C against the OpenFOAM data");
}

/// The `bypass` effect in the OpenFOAM case: the cable cutout of `of-dev-bypass` written
/// as an effect entry (its opening and its 10 % of the supply, from `truth.json`)
/// reproduces that dataset: the run is far closer to it than the clean hall's readings,
/// 0.58 C MAE away (up to 3 C).
#[test]
fn bypass_effect_reproduces_the_openfoam_cutout_data() {
    require_openfoam();
    let mut hall = Hall::load(&data("of-dev-bypass/hall.json")).unwrap();
    let truth = truth("of-dev-bypass");
    let cut = &truth["hidden_effect"];
    let entry = serde_json::json!({
        "kind": "bypass",
        "position_m": cut["min_xy"],
        "size_m": cut["size_xy"],
        "fraction": cut["fraction"],
    });
    hall.effects
        .push(serde_json::from_value(entry).expect("an effect entry"));
    let m = mae_against_openfoam_data("of-dev-bypass", &hall, &ALL, "bypass");
    let footprint = footprint_c(&hall, "of-dev-bypass");
    eprintln!("the cutout's footprint: {footprint:.3} C; the bypass effect's run: {m:.3} C");
    assert!(m < 0.15, "MAE {m:.3} C against the OpenFOAM cutout data");
    assert!(
        m < 0.25 * footprint,
        "{m:.3} C against a footprint of {footprint:.3} C"
    );
}

/// The `rack_recirculation` effect in the OpenFOAM case: the missing blanking panel of
/// `of-dev-blanking` written as an effect entry (B4, the slot's band z 1.0-1.2 m, and
/// its forced flow, drive velocity x slot area, as a fraction of B4's server flow at the
/// true alphas) reproduces that dataset. The dataset drives air through a real slot; the
/// effect returns the same flow from B4's rear faces to its front faces in that band.
#[test]
fn rack_recirculation_effect_reproduces_the_openfoam_blanking_data() {
    require_openfoam();
    let mut hall = Hall::load(&data("of-dev-blanking/hall.json")).unwrap();
    let truth = truth("of-dev-blanking");
    let slot = &truth["hidden_effect"];
    let z = [
        slot["slot_z"][0].as_f64().unwrap(),
        slot["slot_z"][1].as_f64().unwrap(),
    ];
    let slot_flow =
        slot["drive_u_m_s"].as_f64().unwrap() * slot["width_m"].as_f64().unwrap() * (z[1] - z[0]);
    let snaps = snapshots::load_snapshots(&hall, &data("of-dev-blanking/snapshots.csv")).unwrap();
    let rack = slot["rack"].as_str().unwrap();
    let alpha: std::collections::HashMap<&str, f64> = TRUE_ALPHA.into_iter().collect();
    let rack_flow: f64 = snaps
        .iter()
        .map(|s| {
            hall.servers()
                .zip(&s.state.power_w)
                .filter(|(srv, _)| srv.rack.id == rack)
                .map(|(srv, p)| alpha[srv.server.server_type.as_str()] * p * M3_S_PER_CFM)
                .sum::<f64>()
        })
        .sum::<f64>()
        / snaps.len() as f64;
    let fraction = slot_flow / rack_flow;
    eprintln!(
        "slot flow {slot_flow:.3} m3/s, {rack} draws {rack_flow:.3} m3/s: fraction {fraction:.3}"
    );
    hall.effects.push(
        serde_json::from_value(serde_json::json!({
            "kind": "rack_recirculation",
            "rack": rack,
            "z_m": z,
            "fraction": fraction,
        }))
        .expect("an effect entry"),
    );
    let m = mae_against_openfoam_data("of-dev-blanking", &hall, &ALL, "blanking");
    let footprint = footprint_c(&hall, "of-dev-blanking");
    eprintln!("the slot's footprint: {footprint:.3} C; the recirculation effect's run: {m:.3} C");
    assert!(m < 0.15, "MAE {m:.3} C against the OpenFOAM blanking data");
    assert!(
        m < 0.5 * footprint,
        "{m:.3} C against a footprint of {footprint:.3} C"
    );
}

/// The hall defaults (polish stage included) with `iterations` four-step iterations.
fn loop_settings(iterations: usize, polish_iterations: usize) -> HallCalibrationSettings {
    let mut s = HallCalibrationSettings::default();
    s.core.max_iterations = iterations;
    s.core.polish_iterations = polish_iterations;
    s.core.seed = 3;
    s
}

/// The loop with OpenFOAM doing every model run lowers the error and moves every alpha
/// toward the truth the measurements were made at.
#[test]
fn calibration_with_openfoam_lowers_the_error_and_finds_alpha() {
    require_openfoam();
    let (hall, snaps) = small_hall();
    let model = OpenFoamModel::new(hall, small_settings(&tmp("calibrate"))).unwrap();
    let started = Instant::now();
    let c = calibrate_hall_model(
        hall,
        snaps,
        &model,
        model.layout(),
        &loop_settings(CAL_ITERATIONS, CAL_POLISH_ITERATIONS),
        None,
        Vec::new(),
    )
    .unwrap();
    let r = &c.report;
    let initial = r.initial.mae_c.unwrap();
    eprintln!(
        "OpenFOAM calibration: MAE {initial:.3} -> {:.3} C in {} runs, {:.0} s; best {:?}",
        r.best.mae_c,
        r.runs.total,
        started.elapsed().as_secs_f64(),
        r.best.params.0
    );
    for h in &r.history {
        eprintln!("  iteration {}: MAE {:?}", h.iteration, h.mae_c);
    }
    // The polish ran: its records, unlike the loop's, have no surrogate fit.
    assert!(
        r.history.iter().any(|h| h.training_samples == 0),
        "no polish step in {} records",
        r.history.len()
    );
    // Runs may fail (e.g. design corners at alpha 3 cfm/W, 16 m3/s against 3.5 of supply,
    // miss the energy balance); the loop goes on without them.
    assert!(r.runs.failed < r.runs.total / 2, "{:?}", r.runs);
    assert!(
        r.best.mae_c < 0.5 * initial,
        "MAE {initial:.3} -> {:.3} C",
        r.best.mae_c
    );
    let names = model.layout().space().names();
    let truth = true_params(&names);
    let init = model.layout().space().initial();
    for ((name, best), (t, i)) in r.best.params.0.iter().zip(truth.iter().zip(&init)) {
        let (d_best, d_init) = ((best / t).ln().abs(), (i / t).ln().abs());
        assert!(d_best < 0.5 * d_init, "{name}: {i} -> {best}, truth {t}");
    }
}

/// A model that sends runs with a high web alpha to an OpenFOAM model whose wall-clock
/// limit is far below a solve: those runs are really started and killed.
struct KilledAbove<'a> {
    normal: &'a OpenFoamModel,
    short: &'a OpenFoamModel,
    web_alpha_above: f64,
}

impl Model for KilledAbove<'_> {
    type Scenario = OperatingState;

    fn fingerprint(&self) -> String {
        format!(
            "{}+killed-above-{}",
            self.normal.fingerprint(),
            self.web_alpha_above
        )
    }

    fn evaluate(&self, s: &OperatingState, params: &[f64]) -> Result<Outputs, ModelError> {
        if params[0] > self.web_alpha_above {
            self.short.evaluate(s, params)
        } else {
            self.normal.evaluate(s, params)
        }
    }
}

/// A solve past its limit is killed (with its process group), recorded as a timeout with
/// its log, and the loop goes on to a result.
#[test]
fn timed_out_runs_are_recorded_and_the_loop_goes_on() {
    require_openfoam();
    let (hall, snaps) = small_hall();
    let root = tmp("timeout");
    let normal = OpenFoamModel::new(hall, small_settings(&root)).unwrap();
    let short = OpenFoamModel::new(
        hall,
        small_settings(&root).with_timeout(Duration::from_millis(1500)),
    )
    .unwrap();
    // A single run first: the timeout is a timeout, with the solver's log.
    let err = short
        .evaluate(&snaps[0].state, &normal.layout().space().initial())
        .unwrap_err();
    match &err {
        ModelError::Timeout { seconds, .. } => assert!((seconds - 1.5).abs() < 1e-9),
        e => panic!("expected a timeout, got {e}"),
    }
    let model = KilledAbove {
        normal: &normal,
        short: &short,
        // The initial design spreads log-alpha over [0.01, 3]: about half lies above 0.3.
        web_alpha_above: 0.3,
    };
    let journal = root.join("runs.jsonl");
    // One snapshot: the loop's handling of killed runs is the same per snapshot, and each
    // OpenFOAM solve is about ten seconds of the suite.
    let c = calibrate_hall_model(
        hall,
        &snaps[..1],
        &model,
        normal.layout(),
        // The loop's handling of failures is under test, not the polish stage.
        &loop_settings(1, 0),
        Some(&journal),
        Vec::new(),
    )
    .unwrap();
    assert!(c.report.runs.failed >= 1, "{:?}", c.report.runs);
    assert!(c.report.runs.total > c.report.runs.failed);
    let text = std::fs::read_to_string(&journal).unwrap();
    let failed: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|v| v["status"] == "failed")
        .collect();
    assert_eq!(failed.len(), c.report.runs.failed);
    for f in &failed {
        assert_eq!(f["error"]["kind"], "timeout", "{f}");
    }
    // Nothing of a killed solve survives it.
    let leftovers = solver_pids_under(&root);
    assert!(leftovers.is_empty(), "solver processes left: {leftovers:?}");
}

/// Kills the first solver process found under `root` with `signal`, once it has run
/// `after`; returns its pid (none within two minutes: `None`).
fn kill_the_solver(root: &std::path::Path, signal: i32, after: Duration) -> Option<i32> {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(120) {
        let solver = std::fs::read_dir(root).ok().and_then(|_| {
            solver_pids_under(root).into_iter().find(|pid| {
                std::fs::read_to_string(format!("/proc/{pid}/comm"))
                    .is_ok_and(|c| c.starts_with("buoyant"))
            })
        });
        if let Some(pid) = solver {
            std::thread::sleep(after);
            // SAFETY: kill has no memory effects; a process of this test's solve.
            unsafe {
                libc::kill(pid, signal);
            }
            return Some(pid);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    None
}

/// A solve killed from outside kalibre (the out-of-memory killer's SIGKILL) says nothing
/// about its parameters: it is solved again in a fresh directory, and the killed
/// attempt's directory is kept for its logs. With no retry allowed the failure says
/// what killed it.
#[test]
fn a_solve_killed_from_outside_is_solved_again() {
    require_openfoam();
    let (hall, snaps) = small_hall();
    let root = tmp("killed-outside");
    let model = OpenFoamModel::new(hall, small_settings(&root)).unwrap();
    let params = model.layout().space().initial();
    let state = &snaps[0].state;
    let (result, killed) = std::thread::scope(|sc| {
        let killer = sc.spawn(|| kill_the_solver(&root, libc::SIGKILL, Duration::from_secs(1)));
        let result = model.evaluate_timed(state, &params);
        (result, killer.join().unwrap())
    });
    assert!(killed.is_some(), "no solver was found to kill");
    let (out, timings) = result.expect("the second attempt solves");
    assert_eq!(out.values.len(), hall.sensors.len());
    assert_eq!(timings.killed_attempts.len(), 1, "{timings:?}");
    let kept = &timings.killed_attempts[0];
    assert!(kept.join("logs/solve").is_dir(), "{}", kept.display());
    // Journaled with the run's outputs.
    assert_eq!(
        out.extras.get(kalibre_dc::openfoam::KILLED_ATTEMPTS_KEY),
        Some(&vec![1.0])
    );
    // The same solve, not killed, reads the same: the retry is a full solve.
    let (again, _) = model.evaluate_timed(state, &params).unwrap();
    assert_eq!(again.values, out.values);

    let no_retry = OpenFoamModel::new(hall, small_settings(&root).with_killed_retries(0)).unwrap();
    let (result, killed) = std::thread::scope(|sc| {
        let killer = sc.spawn(|| kill_the_solver(&root, libc::SIGKILL, Duration::from_secs(1)));
        let result = no_retry.evaluate_timed(state, &params);
        (result, killer.join().unwrap())
    });
    assert!(killed.is_some(), "no solver was found to kill");
    match result {
        Err(ModelError::Failed { reason, .. }) => assert!(
            reason.contains("killed by signal 9 from outside kalibre"),
            "{reason}"
        ),
        other => panic!("expected a failed run, got {other:?}"),
    }
}

/// Model options that do not belong to the chosen model are refused before anything
/// runs, and a geometry OpenFOAM cannot represent is a clear input error.
#[test]
fn model_options_are_checked() {
    let dir = tmp("flags");
    let base = |extra: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_kalibre"));
        c.arg("calibrate")
            .args(extra)
            .arg("--hall")
            .arg(data("of-dev-clean/hall.json"))
            .arg("--snapshots")
            .arg(data("of-dev-clean/snapshots.csv"))
            .arg("--out")
            .arg(dir.join("out"));
        c.output().unwrap()
    };
    let cases: [(&[&str], &str); 8] = [
        (&["--np", "2"], "--np is an OpenFOAM option"),
        (
            &["--of-killed-retries", "1"],
            "--of-killed-retries is an OpenFOAM option",
        ),
        (
            &["--model", "openfoam", "--of-killed-retries", "9"],
            "--of-killed-retries: 9 is more than 5",
        ),
        (&["--model", "command"], "--model command needs --config"),
        (&["--config", "m.toml"], "--config is for --model command"),
        (
            &["--model", "openfoam", "--grid-m", "0.25"],
            "not on the 0.25 m grid",
        ),
        // The hall's own path, not `hall.json`.
        (
            &["--model", "openfoam", "--grid-m", "0.25"],
            "of-dev-clean/hall.json: /",
        ),
        // 1e14 cells: refused before blockMesh tries, on any machine.
        (
            &["--model", "openfoam", "--grid-m", "0.0001"],
            "--grid-m 0.0001: the OpenFOAM mesh would have 1.04e14 cells, needing about",
        ),
    ];
    for (args, needle) in cases {
        let o = base(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
    }
}

/// `np` 2 (decomposePar, then mpirun) solves the same case as a serial run.
#[test]
fn parallel_solve_agrees_with_serial() {
    require_openfoam();
    let (hall, snaps) = small_hall();
    let model = OpenFoamModel::new(hall, small_settings(&tmp("np2")).with_np(2)).unwrap();
    let params = true_params(&model.layout().space().names());
    let (out, timing) = model.evaluate_timed(&snaps[0].state, &params).unwrap();
    let serial: Vec<f64> = snaps[0].sensor_c.iter().map(|v| v.unwrap()).collect();
    let m = mae(&out.values, &serial);
    eprintln!("np 2 against serial: MAE {m:.4} C, {timing:?}");
    // Decomposition changes the linear solvers' paths, not the solution. Measured
    // 0.012 C (with generator 1, whose returns let air in: 0.052 C at 1000 iterations).
    assert!(m < 0.05, "MAE {m:.4} C between np 2 and serial");
    // The run passed the model's energy check (its 5 % tolerance, or it would be an
    // error above); measured here at 400 iterations: -0.03 % with np 2 (-1.85 % while
    // the returns let air in), so no tighter bound is claimed on 400 iterations.
    assert!(timing.energy_balance.is_finite());
}

/// An effect kind the case cannot represent (here a user's own kind) is refused by name
/// before anything is meshed.
#[test]
fn unsupported_effects_are_refused_by_name() {
    #[derive(Debug)]
    struct Fog;
    impl Effect for Fog {
        fn kind(&self) -> &str {
            "fog"
        }
        fn parameters(&self) -> Vec<kalibre_core::Param> {
            vec![]
        }
        fn to_spec(&self) -> EffectSpec {
            serde_json::from_value(serde_json::json!({"kind": "fog"})).unwrap()
        }
        fn modify(&self, _: &[f64], _: &Hall, _: &mut SimMods) -> kalibre_dc::Result<()> {
            Ok(())
        }
    }
    let hall = Hall::load(&data("of-dev-clean/hall.json")).unwrap();
    let effects: Vec<Box<dyn Effect>> = vec![Box::new(Fog)];
    let layout = ParamLayout::new(&hall, &effects).unwrap();
    let err =
        OpenFoamModel::with_layout(&hall, small_settings(&tmp("unsupported")), effects, layout)
            .unwrap_err()
            .to_string();
    assert!(
        err.contains("`fog`") && err.contains("crac_supply_offset, bypass, rack_recirculation"),
        "{err}"
    );
}

/// The meshed case is keyed by its mesh: an edited bound or initial value finds the case
/// meshed before (no second mesh), while a sensor moved to another probe point meshes a
/// case of its own.
#[test]
fn an_edited_bound_reuses_the_meshed_case() {
    require_openfoam();
    let (hall, _) = small_layout();
    let root = tmp("bounds-reuse");
    let first = OpenFoamModel::new(&hall, small_settings(&root)).unwrap();
    let mut searched = hall.clone();
    let alpha = &mut searched.server_types[0].alpha_cfm_per_w;
    alpha.max = alpha.initial * 1.5;
    alpha.initial = 0.5 * (alpha.min + alpha.initial);
    let again = OpenFoamModel::new(&searched, small_settings(&root)).unwrap();
    assert_eq!(again.case_dir(), first.case_dir());
    let cases = |root: &std::path::Path| {
        std::fs::read_dir(root)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with("case-"))
            .count()
    };
    assert_eq!(cases(&root), 1, "one meshed case under {}", root.display());
    let mut moved = hall.clone();
    moved.sensors[0].position_m[2] += 0.2;
    let other = OpenFoamModel::new(&moved, small_settings(&root)).unwrap();
    assert_ne!(other.case_dir(), first.case_dir());
    assert_eq!(cases(&root), 2);
}

/// A hall whose CRAC blows through its front and draws its air back in at its top (no
/// tiles, no ceiling grilles) is solved: the supply enters at the CRAC's face, the CRAC
/// top takes the same flow out (every boundary fixes its flux, so the pressure has a
/// reference cell), and the heat the servers put in leaves with the air. The built-in
/// simulator, whose air has no momentum, reads such halls far off (docs/models.md,
/// "Front-supply CRACs"); this is the model that solves them.
#[test]
fn a_front_supply_hall_without_grilles_is_solved_with_its_energy_balanced() {
    require_openfoam();
    let (mut hall, states) = small_layout();
    hall.cracs[0].supply = kalibre_dc::hall::SupplyKind::Front;
    hall.tiles.clear();
    hall.returns.clear();
    let hall = Hall::from_json_str(&hall.to_json_pretty(), "front hall.json").unwrap();
    let root = tmp("front-noreturns");
    // The default 1000 iterations: at the small hall's 400 this flow has not settled
    // (energy balance -1.2 %, against -0.03 % at 1000).
    let model =
        OpenFoamModel::new(&hall, OpenFoamSettings::default().with_cache_root(&root)).unwrap();
    let params = model.layout().space().initial();
    let state = &states[0];
    let (out, timing) = model.evaluate_timed(state, &params).unwrap();
    eprintln!("front supply, no grilles: {timing:?}");
    // As the datasets' halls close theirs (-0.8 to -0.9 %).
    assert!(timing.energy_balance.abs() < 0.01, "{timing:?}");
    let supply_c = state.setpoint_c[0];
    let (mut cold, mut hot) = (Vec::new(), Vec::new());
    for (s, v) in hall.sensors.iter().zip(&out.values) {
        // No air in the room is colder than the supply (the maximum principle, to the
        // solver's overshoot).
        assert!(v.is_finite() && *v > supply_c - 0.2, "{}: {v} C", s.id);
        if s.aisle == kalibre_dc::hall::Aisle::Hot {
            hot.push(*v);
        } else {
            cold.push(*v);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(
        mean(&hot) > mean(&cold) + 1.0,
        "hot aisle {:.2} C, cold aisle {:.2} C",
        mean(&hot),
        mean(&cold)
    );
    // The case has the CRAC's face and top as patches, and no tile.
    let boundary = std::fs::read_dir(&root)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("constant/polyMesh/boundary"))
        .find(|p| p.is_file())
        .expect("a meshed case");
    let text = std::fs::read_to_string(boundary).unwrap();
    assert!(text.contains("sup0") && text.contains("crt0"), "{text}");
    assert!(!text.contains("tile0"), "{text}");
}
