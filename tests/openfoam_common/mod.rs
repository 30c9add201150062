//! Helpers shared by the OpenFOAM test files: the development data, the small test hall
//! and its OpenFOAM measurements.

#![allow(dead_code)] // each test file uses its own part

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use kalibre_core::Model;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{OpenFoamModel, OpenFoamSettings};
use kalibre_dc::snapshots::{self, HallSnapshot, OperatingState};

/// True alpha of the development datasets (cfm/W).
pub const TRUE_ALPHA: [(&str, f64); 3] = [("web", 0.13), ("db", 0.17), ("gpu", 0.12)];
/// SIMPLE iterations on the small hall (the measurements use the same, so the truth is
/// exactly reachable).
pub const SMALL_ITERATIONS: u32 = 400;

/// A development dataset's file.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/openfoam")
        .join(name)
}

/// A development dataset's `truth.json`.
pub fn truth(dataset: &str) -> serde_json::Value {
    let path = data(&format!("{dataset}/truth.json"));
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Fails (never skips) when OpenFOAM is not installed.
pub fn require_openfoam() {
    let found = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).any(|d| d.join("blockMesh").is_file()))
        .unwrap_or(false);
    assert!(
        found,
        "OpenFOAM is not installed (`blockMesh` is not in PATH): install it with \
         `apt-get install -y openfoam` (.ci/run does); these tests do not skip"
    );
}

/// A fresh scratch directory for this process.
pub fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kalibre-of-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The true alphas for the per-type parameter names.
pub fn true_params(names: &[String]) -> Vec<f64> {
    names
        .iter()
        .map(|n| {
            let t = n.trim_start_matches("alpha/");
            TRUE_ALPHA.iter().find(|(k, _)| *k == t).unwrap().1
        })
        .collect()
}

/// Alphas at the truth, effect parameters at the values the hall gives them.
pub fn truth_with_effects(space: &kalibre_core::ParamSpace) -> Vec<f64> {
    space
        .names()
        .iter()
        .zip(space.initial())
        .map(|(n, init)| {
            if n.starts_with("alpha/") {
                true_params(std::slice::from_ref(n))[0]
            } else {
                init
            }
        })
        .collect()
}

/// Mean absolute difference.
pub fn mae(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
}

/// The small test hall's layout: the development hall cut to two rows of four racks in a
/// 6.0 x 4.8 x 2.4 m room (7,120 cells at 0.2 m), and the development snapshots t0 and
/// t1 with its servers' powers.
pub fn small_layout() -> (Hall, Vec<OperatingState>) {
    let dev = Hall::load(&data("of-dev-clean/hall.json")).unwrap();
    let dev_snaps = snapshots::load_snapshots(&dev, &data("of-dev-clean/snapshots.csv")).unwrap();
    let mut h = dev.clone();
    h.name = "of-test-small".into();
    h.room.size_m = [6.0, 4.8, 2.4];
    h.racks.retain(|r| r.position_m[0] < 4.7);
    h.tiles.retain(|t| t.position_m[0] < 4.7);
    h.sensors
        .retain(|s| !s.id.contains("A5") && !s.id.contains("B5"));
    let hall = Hall::from_json_str(&h.to_json_pretty(), "small hall.json").unwrap();
    let dev_ids: Vec<String> = dev.servers().map(|s| s.server.id.clone()).collect();
    let states = dev_snaps[..2]
        .iter()
        .map(|s| OperatingState {
            power_w: hall
                .servers()
                .map(|srv| {
                    let i = dev_ids.iter().position(|d| *d == srv.server.id).unwrap();
                    s.state.power_w[i]
                })
                .collect(),
            ..s.state.clone()
        })
        .collect();
    (hall, states)
}

/// The small test hall ([`small_layout`]) with measurements made by OpenFOAM at the true
/// alphas.
pub fn small_hall() -> &'static (Hall, Vec<HallSnapshot>) {
    static HALL: OnceLock<(Hall, Vec<HallSnapshot>)> = OnceLock::new();
    HALL.get_or_init(|| {
        let (hall, states) = small_layout();
        let model = OpenFoamModel::new(
            &hall,
            OpenFoamSettings::default()
                .with_iterations(SMALL_ITERATIONS)
                .with_cache_root(tmp("truth")),
        )
        .unwrap();
        let params = true_params(&model.layout().space().names());
        let readings = side_by_side(&states, |state| model.evaluate(state, &params).unwrap());
        let snaps: Vec<HallSnapshot> = states
            .into_iter()
            .zip(readings)
            .map(|(state, out)| HallSnapshot {
                state,
                sensor_c: out.values.into_iter().map(Some).collect(),
            })
            .collect();
        (hall, snaps)
    })
}

/// `run` on every state at once, one thread each, in the states' order: one serial
/// OpenFOAM solve per snapshot, side by side, so that a test waiting for them does not
/// leave a core idle.
pub fn side_by_side<'a, T: Send>(
    states: impl IntoIterator<Item = &'a OperatingState>,
    run: impl Fn(&OperatingState) -> T + Sync,
) -> Vec<T> {
    std::thread::scope(|sc| {
        let solves: Vec<_> = states
            .into_iter()
            .map(|state| sc.spawn(|| run(state)))
            .collect();
        solves.into_iter().map(|s| s.join().unwrap()).collect()
    })
}

/// The adapter's settings for the small hall, cases under `root`.
pub fn small_settings(root: &Path) -> OpenFoamSettings {
    OpenFoamSettings::default()
        .with_iterations(SMALL_ITERATIONS)
        .with_cache_root(root)
}

/// Processes whose working directory lies under `root` (OpenFOAM steps run in their
/// run's `logs/<step>` directory).
pub fn solver_pids_under(root: &Path) -> Vec<i32> {
    let root = std::fs::canonicalize(root).unwrap();
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| {
            let e = e.ok()?;
            let pid: i32 = e.file_name().to_str()?.parse().ok()?;
            let cwd = std::fs::read_link(e.path().join("cwd")).ok()?;
            cwd.starts_with(&root).then_some(pid)
        })
        .collect()
}
