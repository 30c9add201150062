//! `demo` with every CRAC 1 C low, and its true per-type alphas (shared through
//! `#[path]` by the diagnosis tests).

use kalibre_dc::synth::{self, parse_effect_arg, Preset, SynthOptions, Synthesised};
use kalibre_dc::HallModel;

/// `demo` with every CRAC 1 C low, and its true per-type alphas.
pub fn demo() -> (Synthesised, Vec<f64>) {
    let opts = SynthOptions::new(Preset::Demo, 1)
        .with_noise_c(0.15)
        .with_effect(parse_effect_arg("crac_supply_offset:offset_c=-1").unwrap());
    let s = synth::generate(&opts).unwrap();
    let model = HallModel::new(&s.hall, Default::default()).unwrap();
    let params: Vec<f64> = model
        .layout()
        .space()
        .names()
        .iter()
        .map(|n| s.truth.alpha_type_cfm_per_w[n.trim_start_matches("alpha/")])
        .collect();
    (s, params)
}
