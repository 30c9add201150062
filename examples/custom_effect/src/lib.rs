//! # kalibre-custom-effect
//!
//! A downstream extension of kalibre, written against its public API only: a new effect
//! kind, `cutout_bypass` (cold supply air escaping through one named cable cut-out tile),
//! registered next to the built-in kinds, hidden in a demo hall's truth, found by the
//! diagnosis and calibrated with alpha. `docs/extending.md` walks through it.

#![warn(missing_docs)]

mod cutout;
pub mod story;

pub use cutout::{
    cutout_spec, CutoutBypass, CutoutBypassFactory, FLOW_FRACTION_BOUNDS, KIND, TILE_M,
};

use kalibre::dc::effects::EffectRegistry;

/// The built-in kinds plus `cutout_bypass`.
pub fn registry() -> kalibre::dc::Result<EffectRegistry> {
    EffectRegistry::builtin().with(Box::new(CutoutBypassFactory))
}
