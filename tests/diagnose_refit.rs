//! The diagnosis's refit of its leading hypotheses with the model (`--refit`), on `demo`
//! truths that hide a large effect: so large that the calibration without it moved the
//! alphas far, and the ranking's linearisation (the effect's first step at those alphas)
//! misjudges it. Refit with the model, the hidden effect is named at about its size, and
//! the model's own runs confirm it; on the clean truth the refit names nothing.

use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosis, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::synth::{self, parse_effect_arg, Preset, SynthOptions};

/// Calibrates `demo` (seed 1, noise 0.15 C, the hidden effect) and diagnoses it with the
/// `refit_top` leading hypotheses refit; the calibrated MAE and the diagnosis.
fn diagnose(hidden: Option<&str>, refit_top: usize) -> (f64, HallDiagnosis) {
    let mut opts = SynthOptions::new(Preset::Demo, 1).with_noise_c(0.15);
    if let Some(e) = hidden {
        opts = opts.with_effect(parse_effect_arg(e).expect("effect"));
    }
    let s = synth::generate(&opts).expect("synth");
    let cal = calibrate_hall(
        &s.hall,
        &s.snapshots,
        &HallCalibrationSettings::default(),
        None,
        vec![],
    )
    .expect("calibrate");
    let settings = HallDiagnosisSettings {
        refit_top,
        ..HallDiagnosisSettings::default()
    };
    let d = diagnose_hall(
        &s.hall,
        &s.snapshots,
        &cal.report.best.params.values(),
        &EffectRegistry::builtin(),
        &settings,
    )
    .expect("diagnose");
    (cal.report.best.mae_c, d)
}

/// The top significant hypothesis's name and fitted value, and the lowest model MAE its
/// refit ran at.
fn top_refit(d: &HallDiagnosis) -> (String, f64, f64) {
    let top = d
        .diagnosis
        .significant()
        .next()
        .expect("a significant hypothesis");
    let refit = d
        .refits
        .iter()
        .find(|r| r.name == top.name)
        .expect("the top hypothesis was refit");
    let best_run = refit
        .steps
        .iter()
        .map(|s| s.model_mae_c)
        .fold(f64::INFINITY, f64::min);
    (top.name.clone(), top.fitted.values()[0], best_run)
}

fn summary(d: &HallDiagnosis) -> String {
    let top: Vec<String> = d
        .diagnosis
        .hypotheses
        .iter()
        .take(4)
        .map(|h| format!("{} {:.3} ({})", h.name, h.fitted.values()[0], h.significant))
        .collect();
    format!("{top:?}, refits {:?}", d.refits)
}

#[test]
fn a_large_recirculation_is_named_at_its_size() {
    let (calibrated, d) = diagnose(Some("rack_recirculation:rack=A05,fraction=0.5"), 3);
    let (name, fitted, best_run) = top_refit(&d);
    assert_eq!(name, "rack_recirculation(rack=A05)", "{}", summary(&d));
    assert!((fitted - 0.5).abs() < 0.1, "{}", summary(&d));
    // A real model run with it reads at most a third of the calibrated error.
    assert!(
        best_run < calibrated / 3.0,
        "{best_run} against {calibrated}"
    );
}

#[test]
fn a_large_bypass_is_named_at_its_size() {
    let (calibrated, d) = diagnose(Some("bypass:behind_rack=A03,fraction=0.3"), 3);
    let (name, fitted, best_run) = top_refit(&d);
    assert_eq!(name, "bypass(behind_rack=A03)", "{}", summary(&d));
    assert!((fitted - 0.3).abs() < 0.1, "{}", summary(&d));
    assert!(
        best_run < calibrated / 2.0,
        "{best_run} against {calibrated}"
    );
}

#[test]
fn on_the_clean_hall_the_refit_names_nothing() {
    let (_, d) = diagnose(None, 3);
    assert_eq!(d.diagnosis.significant().count(), 0, "{}", summary(&d));
    assert_eq!(d.refits.len(), 3, "{:?}", d.refits);
}
