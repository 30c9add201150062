//! Diagnosis on `demo` with a hidden effect, at the true alphas (so the residual is the
//! hidden effect, the model's grid error and noise): the diagnosis names the effect.
//! (The user's path, calibrating alpha first, is tested end to end in tests/acceptance.rs.)

use kalibre::dc::diagnosis::{diagnose_hall, HallDiagnosisSettings};
use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::synth::{self, parse_effect_arg, Preset, SynthOptions};
use kalibre::dc::ParamLayout;

fn diagnose_at_truth(effect: Option<&str>) -> Vec<(String, bool, Vec<f64>)> {
    let mut opts = SynthOptions::new(Preset::Demo, 1).with_noise_c(0.15);
    if let Some(e) = effect {
        opts = opts.with_effect(parse_effect_arg(e).unwrap());
    }
    let s = synth::generate(&opts).expect("synth");
    let layout = ParamLayout::new(&s.hall, &[]).unwrap();
    let truth: Vec<f64> = layout
        .space()
        .names()
        .iter()
        .map(|n| s.truth.alpha_type_cfm_per_w[n.trim_start_matches("alpha/")])
        .collect();
    let d = diagnose_hall(
        &s.hall,
        &s.snapshots,
        &truth,
        &EffectRegistry::builtin(),
        &HallDiagnosisSettings::default(),
    )
    .expect("diagnose");
    let json = d.to_json();
    assert_eq!(json["schema"], "kalibre.diagnosis/1");
    d.diagnosis
        .hypotheses
        .iter()
        .map(|h| (h.name.clone(), h.significant, h.fitted.values()))
        .collect()
}

#[test]
fn hidden_crac_offset_is_named_at_true_alpha() {
    let ranked = diagnose_at_truth(Some("crac_supply_offset:offset_c=-1"));
    assert!(
        ranked[0].0.starts_with("crac_supply_offset"),
        "{:?}",
        &ranked[..5]
    );
    assert!(ranked[0].1, "the offset is significant: {:?}", &ranked[..5]);
    // The all-CRAC offset is named (per-CRAC offsets are indistinguishable alternatives
    // that need a 3.5 C offset on one unit), with about the hidden -1 C.
    assert_eq!(ranked[0].0, "crac_supply_offset");
    assert!(
        (ranked[0].2[0] + 1.0).abs() < 0.3,
        "fitted {:?}",
        ranked[0].2
    );
}
