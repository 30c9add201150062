//! The small OpenFOAM hall the baseline tests calibrate.

#![allow(dead_code)]

use std::path::PathBuf;

use kalibre_core::Observations;
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::sim::SimConfig;
use kalibre_dc::snapshots::{load_snapshots, to_observations, HallSnapshot, OperatingState};
use kalibre_dc::HallModel;

pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/openfoam/of-dev-clean")
}

pub struct Setup {
    pub hall: Hall,
    pub snaps: Vec<HallSnapshot>,
    pub obs: Observations<OperatingState>,
    pub model: HallModel,
}

/// The hall with `mode`, on a 0.4 m grid (coarse: a debug-build solve stays fast).
pub fn setup(mode: AlphaMode) -> Setup {
    let dir = data_dir();
    let mut hall = Hall::load(&dir.join("hall.json")).unwrap();
    hall.calibrate.alpha = mode;
    let snaps = load_snapshots(&hall, &dir.join("snapshots.csv")).unwrap();
    let obs = to_observations(&hall, &snaps).unwrap();
    let model = HallModel::new(&hall, SimConfig::default().with_cell_m(0.4)).unwrap();
    Setup {
        hall,
        snaps,
        obs,
        model,
    }
}
