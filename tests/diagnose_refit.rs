//! The diagnosis's refit of its leading hypotheses with the model (`--refit`), on `demo`
//! truths that hide a large effect: so large that the calibration without it moved the
//! alphas far, and the ranking's linearisation (the effect's first step at those alphas)
//! misjudges it. Refit with the model, the hidden effect is named at about its size, and
//! the model's own runs confirm it; on the clean truth the refit names nothing.

use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosis, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::synth::{self, parse_effect_arg, Preset, SynthOptions};

/// Calibrates `demo` (seed 1, noise 0.15 C, the hidden effect) and diagnoses it twice:
/// linearised, and with the `refit_top` leading hypotheses refit. The calibrated MAE and
/// the two diagnoses.
fn diagnose(hidden: Option<&str>, refit_top: usize) -> (f64, HallDiagnosis, HallDiagnosis) {
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
    let run = |refit_top| {
        let settings = HallDiagnosisSettings {
            refit_top,
            ..HallDiagnosisSettings::default()
        };
        diagnose_hall(
            &s.hall,
            &s.snapshots,
            &cal.report.best.params.values(),
            &EffectRegistry::builtin(),
            &settings,
        )
        .expect("diagnose")
    };
    (cal.report.best.mae_c, run(0), run(refit_top))
}

/// The hidden effect (`effect` for `synth --effect`) is named first, at about its size
/// (within `tolerance` of `truth`) and nearer it than the linearised fit; and a model run
/// of the refit reads below `calibrated / factor`.
fn assert_named_at_size(effect: &str, name: &str, truth: f64, tolerance: f64, factor: f64) {
    let (calibrated, linear, d) = diagnose(Some(effect), 3);
    let top = d
        .diagnosis
        .significant()
        .next()
        .expect("a significant hypothesis");
    assert_eq!(top.name, name, "{}", summary(&d));
    let fitted = top.fitted.values()[0];
    assert!((fitted - truth).abs() < tolerance, "{}", summary(&d));
    let linear_fit = linear
        .diagnosis
        .hypotheses
        .iter()
        .find(|h| h.name == name)
        .map(|h| h.fitted.values()[0])
        .expect("the hypothesis in the linearised ranking");
    assert!(
        (fitted - truth).abs() < (linear_fit - truth).abs(),
        "refit {fitted} against linearised {linear_fit}, truth {truth}"
    );
    let best_run = d
        .refits
        .iter()
        .find(|r| r.name == name)
        .expect("the top hypothesis was refit")
        .steps
        .iter()
        .map(|s| s.model_mae_c)
        .fold(f64::INFINITY, f64::min);
    assert!(
        best_run < calibrated / factor,
        "{best_run} against {calibrated}"
    );
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
    // A real model run with it reads at most a third of the calibrated error.
    assert_named_at_size(
        "rack_recirculation:rack=A05,fraction=0.5",
        "rack_recirculation(rack=A05)",
        0.5,
        0.1,
        3.0,
    );
}

#[test]
fn a_large_bypass_is_named_at_its_size() {
    assert_named_at_size(
        "bypass:behind_rack=A03,fraction=0.3",
        "bypass(behind_rack=A03)",
        0.3,
        0.1,
        2.0,
    );
}

#[test]
fn on_the_clean_hall_the_refit_names_nothing() {
    let (_, _, d) = diagnose(None, 3);
    assert_eq!(d.diagnosis.significant().count(), 0, "{}", summary(&d));
    assert_eq!(d.refits.len(), 3, "{:?}", d.refits);
}
