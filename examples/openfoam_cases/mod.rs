//! The OpenFOAM development datasets (`data/openfoam/of-dev-*`) and seeded variants of
//! them: fresh noise draws from OpenFOAM's noise-free values, and the same draws with
//! sensors removed. Shared by `diagnosis_variants` and `recalibration_variants`.
// Each example uses a different part of this module.
#![allow(dead_code)]

use std::path::Path;

use kalibre::dc::calibration::{calibrate_hall, HallCalibration, HallCalibrationSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::snapshots::{self, HallSnapshot};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde_json::Value;

/// Datasets and the name of the hypothesis the diagnosis should put on top.
pub const DATASETS: [(&str, Option<&str>); 4] = [
    ("of-dev-clean", None),
    ("of-dev-crac-offset", Some("crac_supply_offset")),
    ("of-dev-blanking", Some("rack_recirculation(rack=B4)")),
    ("of-dev-bypass", Some("bypass(behind_rack=B3)")),
];
/// The second layout's datasets (`data/openfoam-layout2`, session 28). On its one plenum a
/// single CRAC's offset reaches every tile mixed with the others' supply, so the
/// hall-wide offset is the form the data can identify (the per-CRAC ones are listed as
/// indistinguishable from it); the cutout lies across the `behind_rack` strip of A07.
pub const LAYOUT2_DATASETS: [(&str, Option<&str>); 4] = [
    ("ol2-clean", None),
    ("ol2-offset-crac2", Some("crac_supply_offset")),
    ("ol2-slot-A05", Some("rack_recirculation(rack=A05)")),
    ("ol2-cutout-A07", Some("bypass(behind_rack=A07)")),
];
/// The noise of the stored data (README), so that a variant is another draw of the same.
pub const NOISE_C: f64 = 0.15;
pub const REMOVED_SENSORS: usize = 4;

/// Which data a case diagnoses.
#[derive(Clone, Copy)]
pub enum Case {
    Original,
    Noise(usize),
    NoiseRemoved(usize),
}

impl Case {
    pub fn label(self) -> String {
        match self {
            Case::Original => "original".into(),
            Case::Noise(k) => format!("noise {k}"),
            Case::NoiseRemoved(k) => format!("noise {k}, {REMOVED_SENSORS} sensors removed"),
        }
    }
    /// The case's directory under `--work`, e.g. `noise-3-4-sensors-removed`.
    pub fn slug(self) -> String {
        self.label().replace(", ", "-").replace(' ', "-")
    }
}

/// The seed of one random choice, from (dataset index, k, variant: 0 noise, 1 removal):
/// distinct small integers suffice, `seed_from_u64` scrambles them (SplitMix64).
pub fn seed(dataset: usize, k: usize, variant: u64) -> u64 {
    (1 << 40) | ((dataset as u64) << 24) | ((k as u64) << 8) | variant
}

/// A standard normal draw (Box-Muller; the root package does not depend on `rand_distr`).
pub fn gauss(rng: &mut Xoshiro256PlusPlus) -> f64 {
    let u1 = 1.0 - rng.random::<f64>(); // (0, 1]: ln stays finite
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The snapshots with every reading replaced by noise-free + N(0, NOISE_C).
pub fn noisy(
    hall: &Hall,
    snaps: &[HallSnapshot],
    truth: &Value,
    file: &Path,
    seed: u64,
) -> Result<Vec<HallSnapshot>, String> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut out = snaps.to_vec();
    for s in &mut out {
        let free = &truth["snapshots"][&s.state.label]["sensor_c_noise_free"];
        for (reading, sensor) in s.sensor_c.iter_mut().zip(&hall.sensors) {
            let clean = free[&sensor.id].as_f64().ok_or_else(|| {
                format!(
                    "{}: no snapshots.{}.sensor_c_noise_free.{}",
                    file.display(),
                    s.state.label,
                    sensor.id
                )
            })?;
            // Drawn for every sensor so that the draws do not depend on missing readings.
            let z = gauss(&mut rng);
            if reading.is_some() {
                *reading = Some(clean + NOISE_C * z);
            }
        }
    }
    Ok(out)
}

/// The hall without `REMOVED_SENSORS` seeded random sensors, and the snapshots without
/// their readings; returns the removed ids too.
pub fn remove_sensors(
    hall: &Hall,
    snaps: &[HallSnapshot],
    seed: u64,
) -> Result<(Hall, Vec<HallSnapshot>, Vec<String>), String> {
    let n = hall.sensors.len();
    if n <= REMOVED_SENSORS {
        return Err(format!("hall `{}` has only {n} sensors", hall.name));
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut drop = rand::seq::index::sample(&mut rng, n, REMOVED_SENSORS).into_vec();
    drop.sort_unstable();
    let mut hall = hall.clone();
    let removed = drop.iter().map(|&i| hall.sensors[i].id.clone()).collect();
    hall.sensors = keep(&hall.sensors, &drop);
    let mut snaps = snaps.to_vec();
    for s in &mut snaps {
        s.sensor_c = keep(&s.sensor_c, &drop);
    }
    Ok((hall, snaps, removed))
}

/// The items of `v` whose index is not in `drop`.
fn keep<T: Clone>(v: &[T], drop: &[usize]) -> Vec<T> {
    let kept = v.iter().enumerate().filter(|(i, _)| !drop.contains(i));
    kept.map(|(_, x)| x.clone()).collect()
}

/// The cases of one dataset: the stored data, then per k = 1..=variants a noise draw and
/// the same draw with sensors removed.
pub fn cases(variants: usize) -> Vec<Case> {
    let mut cases = vec![Case::Original];
    for k in 1..=variants {
        cases.push(Case::Noise(k));
        cases.push(Case::NoiseRemoved(k));
    }
    cases
}

/// One dataset as stored: the hall (checked), its snapshots and `truth.json`.
pub struct Dataset {
    pub hall: Hall,
    pub snaps: Vec<HallSnapshot>,
    pub truth: Value,
    truth_path: std::path::PathBuf,
}

impl Dataset {
    /// Loads `dir` (`hall.json`, `snapshots.csv`, `truth.json`).
    pub fn load(dir: &Path) -> Result<Self, String> {
        let hall_path = dir.join("hall.json");
        let hall = Hall::load(&hall_path).map_err(|e| e.to_string())?;
        EffectRegistry::builtin()
            .check_hall(&hall, &hall_path.display().to_string())
            .map_err(|e| e.to_string())?;
        let snaps = snapshots::load_snapshots(&hall, &dir.join("snapshots.csv"))
            .map_err(|e| e.to_string())?;
        let truth_path = dir.join("truth.json");
        let truth: Value = std::fs::read_to_string(&truth_path)
            .map_err(|e| e.to_string())
            .and_then(|t| serde_json::from_str(&t).map_err(|e| e.to_string()))
            .map_err(|e| format!("{}: {e}", truth_path.display()))?;
        Ok(Dataset {
            hall,
            snaps,
            truth,
            truth_path,
        })
    }

    /// Case `case` of dataset number `index` (in [`DATASETS`]): its hall, snapshots, seeds
    /// and removed sensors.
    pub fn case(&self, index: usize, case: Case) -> Result<CaseData, String> {
        let (noise_seed, removal_seed) = match case {
            Case::Original => (None, None),
            Case::Noise(k) => (Some(seed(index, k, 0)), None),
            Case::NoiseRemoved(k) => (Some(seed(index, k, 0)), Some(seed(index, k, 1))),
        };
        let snaps = match noise_seed {
            Some(s) => noisy(&self.hall, &self.snaps, &self.truth, &self.truth_path, s)?,
            None => self.snaps.clone(),
        };
        let (hall, snaps, removed) = match removal_seed {
            Some(s) => remove_sensors(&self.hall, &snaps, s)?,
            None => (self.hall.clone(), snaps, Vec::new()),
        };
        Ok(CaseData {
            hall,
            snaps,
            noise_seed,
            removal_seed,
            removed,
        })
    }
}

/// One case's data.
pub struct CaseData {
    pub hall: Hall,
    pub snaps: Vec<HallSnapshot>,
    pub noise_seed: Option<u64>,
    pub removal_seed: Option<u64>,
    pub removed: Vec<String>,
}

/// Writes `doc` as pretty JSON to `out`, creating its directory.
pub fn write_json(out: &Path, doc: &Value) -> Result<(), String> {
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
    }
    let text = serde_json::to_string_pretty(doc).map_err(|e| format!("JSON: {e}"))?;
    std::fs::write(out, text).map_err(|e| format!("{}: {e}", out.display()))
}

/// Calibrates a case as `kalibre calibrate` does by default (built-in simulator, seed 1,
/// 10 iterations, the polish), with its journal and `report.json` in `dir`; returns the
/// calibration and its settings. A journal left in `dir` by an earlier run is removed
/// first, so the result does not depend on what the directory held.
pub fn calibrate_as_cli(
    hall: &Hall,
    snaps: &[HallSnapshot],
    dir: &Path,
) -> Result<(HallCalibration, HallCalibrationSettings), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let journal = dir.join("runs.jsonl");
    if journal.exists() {
        std::fs::remove_file(&journal).map_err(|e| format!("{}: {e}", journal.display()))?;
    }
    // The CLI's defaults are `HallCalibrationSettings::default()`.
    let settings = HallCalibrationSettings::default();
    let cal = calibrate_hall(hall, snaps, &settings, Some(&journal), Vec::new())
        .map_err(|e| format!("calibration: {e}"))?;
    let report =
        serde_json::to_string_pretty(&cal.report).map_err(|e| format!("report.json: {e}"))?;
    let path = dir.join("report.json");
    std::fs::write(&path, report).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok((cal, settings))
}
