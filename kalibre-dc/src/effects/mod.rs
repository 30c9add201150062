//! Physical effects a model may lack, each with its own calibrated parameters.
//!
//! An [`Effect`] names its parameters and changes the simulation. `hall.json` `effects`
//! turns effects on; [`from_spec`] builds one from an entry.

use kalibre_core::Param;

use crate::hall::{EffectSpec, Hall};
use crate::Result;

/// A physical effect added to the model.
pub trait Effect: Send + Sync + std::fmt::Debug {
    /// The kind, e.g. `bypass`.
    fn kind(&self) -> &str;

    /// Parameters, with names relative to the effect (e.g. `fraction`); the calibration
    /// names them `<kind>/<name>`.
    fn parameters(&self) -> Vec<Param>;

    /// The `hall.json` `effects` entry that recreates this effect.
    fn to_spec(&self) -> EffectSpec;
}

/// Builds an effect from its `hall.json` entry, checking its fields against the hall.
pub fn from_spec(spec: &EffectSpec, _hall: &Hall) -> Result<Box<dyn Effect>> {
    Err(crate::Error::Effect {
        kind: spec.kind.clone(),
        message: "unknown effect kind (known: containment_leakage, bypass, crac_supply_offset, rack_recirculation)".into(),
    })
}
