//! The diagnosis with OpenFOAM as its solver (`kalibre diagnose --model openfoam`): on the
//! small test hall, measurements made by OpenFOAM with a cable cutout that no candidate
//! places exactly, and the same hall without it.
//!
//! Needs OpenFOAM (CI installs it); fails, never skips, without it.

use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use kalibre_core::Model;
use kalibre_dc::diagnosis::{diagnose_hall_with, HallDiagnosis, HallDiagnosisSettings};
use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{OpenFoamEffectSolver, OpenFoamModel};
use kalibre_dc::snapshots::HallSnapshot;

mod openfoam_common;
use openfoam_common::*;

/// The cutout's share of the supply.
const CUTOUT_FRACTION: f64 = 0.07;
/// Sensor noise added to OpenFOAM's readings (C).
const NOISE_C: f64 = 0.1;

/// `snaps` with readings `values` plus seeded Gaussian noise.
fn measured(snaps: &[HallSnapshot], values: &[Vec<f64>], seed: u64) -> Vec<HallSnapshot> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    snaps
        .iter()
        .zip(values)
        .map(|(s, v)| HallSnapshot {
            state: s.state.clone(),
            sensor_c: v
                .iter()
                .map(|t| {
                    let u1 = 1.0 - rng.random::<f64>();
                    let u2 = rng.random::<f64>();
                    let z = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                    Some(t + NOISE_C * z)
                })
                .collect(),
        })
        .collect()
}

fn files_in(dir: &std::path::Path) -> usize {
    std::fs::read_dir(dir).map(|d| d.count()).unwrap_or(0)
}

fn print(label: &str, d: &HallDiagnosis) {
    eprintln!("{label}: MAE {:.3} C", d.diagnosis.mae);
    for (h, s) in d.diagnosis.hypotheses.iter().zip(&d.suggestions).take(5) {
        eprintln!(
            "  {:<36} significant {:<5} dBIC {:>8.1} explains {:>4.0}% {}",
            h.name,
            h.significant,
            h.delta_bic,
            100.0 * h.explained_fraction,
            serde_json::to_string(s).unwrap()
        );
    }
    for n in &d.not_tried {
        eprintln!("  not tried: {} ({}): {}", n.candidate, n.count, n.reason);
    }
}

/// A cutout in row B's hot aisle, 0.2 m further from the racks than the `behind_rack`
/// candidates' strips and at 7 % of the supply: OpenFOAM's diagnosis names the bypass
/// behind the rack it sits at, at about its size; on the same hall without the cutout it
/// names nothing, reusing every solve of the first diagnosis.
#[test]
fn openfoam_diagnosis_names_the_cutout_and_nothing_on_the_clean_hall() {
    require_openfoam();
    let (hall, clean) = small_hall();
    let root = tmp("diagnose");
    let settings = small_settings(&root);
    // B3 spans x 3.6-4.2 and exhausts into y > 4.0; the candidate strip is y 4.0-4.4.
    let mut with_cut = hall.clone();
    with_cut.effects.push(
        serde_json::from_value(serde_json::json!({
            "kind": "bypass",
            "position_m": [3.6, 4.2],
            "size_m": [0.6, 0.4],
            "fraction": CUTOUT_FRACTION,
        }))
        .unwrap(),
    );
    let with_cut = Hall::from_json_str(&with_cut.to_json_pretty(), "cutout hall.json").unwrap();
    let truth_model = OpenFoamModel::new(&with_cut, settings.clone()).unwrap();
    let names = truth_model.layout().space().names();
    let params: Vec<f64> = names
        .iter()
        .zip(truth_model.layout().space().initial())
        .map(|(n, init)| {
            if n.starts_with("alpha/") {
                true_params(std::slice::from_ref(n))[0]
            } else {
                init
            }
        })
        .collect();
    let cut_values: Vec<Vec<f64>> = clean
        .iter()
        .map(|s| truth_model.evaluate(&s.state, &params).unwrap().values)
        .collect();
    let clean_values: Vec<Vec<f64>> = clean
        .iter()
        .map(|s| s.sensor_c.iter().map(|v| v.unwrap()).collect())
        .collect();
    let footprint = mae(&cut_values.concat(), &clean_values.concat());
    eprintln!("the cutout's footprint: {footprint:.3} C MAE");

    let alpha = true_params(
        &OpenFoamModel::new(hall, settings.clone())
            .unwrap()
            .layout()
            .space()
            .names(),
    );
    let solver = OpenFoamEffectSolver::new(hall, settings).unwrap();
    let mut ds = HallDiagnosisSettings {
        unit_step: 0.03,
        effect_step: 0.2,
        ..HallDiagnosisSettings::default()
    };
    ds.diagnose.robust_nu = Some(4.0);
    let registry = EffectRegistry::builtin();
    let d = diagnose_hall_with(
        hall,
        &measured(clean, &cut_values, 11),
        &alpha,
        &registry,
        &ds,
        &solver,
    )
    .unwrap();
    print("cutout", &d);
    let top = d
        .diagnosis
        .hypotheses
        .iter()
        .position(|h| h.significant)
        .expect("a significant hypothesis");
    assert_eq!(d.diagnosis.hypotheses[top].name, "bypass(behind_rack=B3)");
    let fraction = d.suggestions[top].fields["fraction"].as_f64().unwrap();
    assert!(
        (0.5 * CUTOUT_FRACTION..=2.0 * CUTOUT_FRACTION).contains(&fraction),
        "fitted fraction {fraction}"
    );
    // The candidates OpenFOAM cannot represent are listed, not silently dropped.
    assert!(
        d.not_tried
            .iter()
            .any(|n| n.candidate == "rack_recirculation" && n.count == 8),
        "{:?}",
        d.not_tried
    );

    // The clean hall's readings are the base run's: every solve is kept already.
    let kept = root.join("diagnosis-runs");
    let before = files_in(&kept);
    let d = diagnose_hall_with(
        hall,
        &measured(clean, &clean_values, 12),
        &alpha,
        &registry,
        &ds,
        &solver,
    )
    .unwrap();
    print("clean", &d);
    assert_eq!(files_in(&kept), before, "a kept solve was run again");
    assert!(
        d.diagnosis.significant().next().is_none(),
        "named on the clean hall: {}",
        d.diagnosis.hypotheses[0].name
    );
}
