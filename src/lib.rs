//! # kalibre
//!
//! Surrogate-assisted calibration of expensive simulation models. This facade crate
//! re-exports the workspace's crates and ships the `kalibre` command-line tool.
//!
//! - [`core`] (`kalibre-core`): the generic four-step loop — fit a surrogate, search it
//!   against the measurements, run the model there, validate — with the run journal.
//! - [`dc`] (`kalibre-dc`): data halls — files, the built-in thermal simulator, effects,
//!   the thermal graph surrogate.
//! - [`baselines`] (`kalibre-baselines`): the paper's comparators.

#![warn(missing_docs)]

pub use kalibre_baselines as baselines;
pub use kalibre_core as core;
pub use kalibre_dc as dc;
