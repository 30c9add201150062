//! A second OpenFOAM layout (`data/openfoam-layout2`, session 28): one hot aisle between
//! two rows of 12 racks, a cold aisle along each wall, four CRACs on one plenum. The
//! diagnosis's settings were chosen on the development hall (`data/openfoam`); these
//! data were made after, to see how far they carry (`docs/diagnosis.md`, "Another
//! layout"). What holds there is tested here: the built-in model's realism, the CRAC
//! offset named at its mixed size, and a slot seen by one sensor only reported as
//! resting on that sensor rather than dropped in silence; and (session 30) the stored
//! clean hall left undecided by the ambiguity check (without the model form), where it
//! was named wrongly. The
//! clean hall's false positives over fresh noise draws and the missed cutout are
//! measured in the docs, not asserted.

mod cli_support;

use std::path::{Path, PathBuf};

use cli_support::{on_files, run, stderr, tmp};

use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosis, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::sim::{SimConfig, Simulator};
use kalibre::dc::snapshots;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/openfoam-layout2")
        .join(name)
}

fn truth(dataset: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(data(&format!("{dataset}/truth.json"))).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// Calibrates `dataset` as `kalibre calibrate` does (no journal) and diagnoses at the
/// best parameters as `kalibre diagnose` does.
fn calibrate_and_diagnose(dataset: &str) -> HallDiagnosis {
    calibrate_and_diagnose_with(dataset, &[]).remove(0)
}

/// A change of the default diagnosis settings.
type Variant = dyn Fn(&mut HallDiagnosisSettings);

/// Calibrates `dataset` once and diagnoses it with the default settings and, after
/// them, with each of `variants` applied to the default.
fn calibrate_and_diagnose_with(dataset: &str, variants: &[&Variant]) -> Vec<HallDiagnosis> {
    let hall = Hall::load(&data(&format!("{dataset}/hall.json"))).unwrap();
    let snaps =
        snapshots::load_snapshots(&hall, &data(&format!("{dataset}/snapshots.csv"))).unwrap();
    let settings = HallCalibrationSettings::default();
    let cal = calibrate_hall(&hall, &snaps, &settings, None, Vec::new()).unwrap();
    let default = HallDiagnosisSettings {
        sim: settings.sim.clone(),
        ..HallDiagnosisSettings::default()
    };
    let mut all = vec![default.clone()];
    for change in variants {
        let mut changed = default.clone();
        change(&mut changed);
        all.push(changed);
    }
    all.iter()
        .map(|ds| {
            diagnose_hall(
                &hall,
                &snaps,
                &cal.report.best.params.values(),
                &EffectRegistry::builtin(),
                ds,
            )
            .unwrap()
        })
        .collect()
}

#[test]
fn builtin_model_at_the_true_alphas_is_near_openfoam_on_the_second_layout() {
    let hall = Hall::load(&data("ol2-clean/hall.json")).unwrap();
    let snaps = snapshots::load_snapshots(&hall, &data("ol2-clean/snapshots.csv")).unwrap();
    let t = truth("ol2-clean");
    let alpha: Vec<f64> = hall
        .servers()
        .map(|s| {
            t["alpha_true_cfm_per_w"][&s.server.server_type]
                .as_f64()
                .unwrap()
        })
        .collect();
    let sim = Simulator::new(&hall, SimConfig::default()).unwrap();
    let (mut sum, mut n) = (0.0, 0.0);
    for snap in &snaps {
        let sol = sim.solve(&snap.state, &alpha, &[]).unwrap();
        for (sensor, model_c) in hall.sensors.iter().zip(sol.sensor_c()) {
            let openfoam_c = t["snapshots"][&snap.state.label]["sensor_c_noise_free"][&sensor.id]
                .as_f64()
                .unwrap();
            sum += (model_c - openfoam_c).abs();
            n += 1.0;
        }
    }
    // Measured 0.346 C (the development hall: 1.2 C, its row-end low inlets 3-4 C off).
    let mae = sum / n;
    assert!(
        mae < 0.45,
        "built-in against OpenFOAM at the true alphas: {mae:.3} C"
    );
}

#[test]
fn one_cracs_offset_on_a_shared_plenum_is_named_as_the_supplys_at_its_mixed_size() {
    let d = calibrate_and_diagnose("ol2-offset-crac2");
    let top = d
        .diagnosis
        .significant()
        .next()
        .expect("something significant");
    // crac-2 at -1 C of four CRACs on one plenum: every tile delivers about -0.25 C.
    assert_eq!(
        top.name,
        "crac_supply_offset",
        "{:#?}",
        &d.diagnosis.hypotheses[..3]
    );
    let offset_c = top.fitted.values()[0];
    assert!((-0.4..=-0.1).contains(&offset_c), "offset {offset_c}");
    // And it says which CRAC it cannot tell: all four are as good.
    let close: Vec<&str> = d
        .diagnosis
        .close_alternatives()
        .iter()
        .map(|h| h.name.as_str())
        .collect();
    for crac in ["crac-1", "crac-2", "crac-3", "crac-4"] {
        let name = format!("crac_supply_offset(crac={crac})");
        assert!(close.contains(&name.as_str()), "{name} not in {close:?}");
    }
}

#[test]
fn a_slot_seen_by_one_sensor_is_reported_as_resting_on_that_sensor() {
    let d = calibrate_and_diagnose("ol2-slot-A05");
    let truth = d
        .diagnosis
        .hypotheses
        .iter()
        .find(|h| h.name == "rack_recirculation(rack=A05)")
        .unwrap();
    // The slot warms c-A05-11 by 6.6 C and no other sensor by more than 0.1 C: the
    // single-output check stops it (one sensor cannot tell an effect from a fault), and
    // the listing says which sensor it rests on.
    assert!(truth.explained_fraction > 0.8, "{truth:#?}");
    assert!(!truth.significant, "{truth:#?}");
    assert_eq!(truth.carried_by.as_deref(), Some("c-A05-11"), "{truth:#?}");
    // A hypothesis that passes the check rests on no one sensor.
    assert!(d.diagnosis.significant().all(|h| h.carried_by.is_none()));
}

#[test]
fn the_ambiguity_check_leaves_the_stored_clean_hall_undecided_without_the_model_form() {
    // Without the ambiguity check (the default before session 30) a recirculation in A06
    // or A02 is significant here: the built-in model's own error against OpenFOAM makes
    // it. Other places fit about as well, so with the check nothing is named and the
    // listing says which explanations the data cannot choose between. This holds with
    // the model form off (the default of session 30); with it on (the default since
    // session 31) this stored case is named at A06, one of the 9 wrong names in 13
    // cases of either default (`docs/diagnosis.md`, "Session 31").
    let d = calibrate_and_diagnose_with(
        "ol2-clean",
        &[&|s| s.model_form = false, &|s| {
            s.model_form = false;
            s.diagnose.ambiguity_check = false;
        }],
    );
    let named = |d: &HallDiagnosis| d.diagnosis.significant().next().map(|h| h.name.clone());
    assert_eq!(named(&d[1]), None, "{:#?}", &d[1].diagnosis.hypotheses[..3]);
    assert!(
        d[1].diagnosis
            .hypotheses
            .iter()
            .any(|h| !h.ambiguous_with.is_empty()),
        "{:#?}",
        &d[1].diagnosis.hypotheses[..3]
    );
    let before = named(&d[2]).unwrap_or_default();
    assert!(before.starts_with("rack_recirculation"), "{before}");
    // By default the model's own errors here bear out its tile-jet variant (0.97).
    let share = d[0]
        .diagnosis
        .model_form_share
        .expect("a model-form variant");
    assert!(share > 0.5, "model-form share {share}");
}

#[test]
fn the_cli_says_which_sensor_a_hypothesis_rests_on() {
    let dir = tmp("layout2-slot");
    let (hall, snaps) = (
        data("ol2-slot-A05/hall.json"),
        data("ol2-slot-A05/snapshots.csv"),
    );
    let on_slot = |command: &str| on_files(command, &hall, &snaps);
    let cal = run(on_slot("calibrate").arg("--out").arg(dir.join("cal")));
    assert!(cal.status.success(), "{}", stderr(&cal));
    let out = run(on_slot("diagnose")
        .arg("--calibration")
        .arg(dir.join("cal")));
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("rests on one sensor, c-A05-11")
            && text.contains(r#"if c-A05-11 reads right, add to hall.json "effects": {"kind":"rack_recirculation""#)
            && text.contains("(rack_recirculation(rack=A05) rests on it alone"),
        "{text}"
    );
    // The ambiguity check and the model form (on by default) can be turned off; the
    // listing is the same about the slot's sensor.
    let off = run(on_slot("diagnose")
        .arg("--calibration")
        .arg(dir.join("cal"))
        .arg("--no-ambiguity-check")
        .arg("--no-model-form"));
    assert!(off.status.success(), "{}", stderr(&off));
    assert!(
        String::from_utf8_lossy(&off.stdout).contains("rests on one sensor, c-A05-11"),
        "{}",
        String::from_utf8_lossy(&off.stdout)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
