//! # kalibre-dc
//!
//! kalibre for air-cooled data halls: the hall and snapshot files, synthetic halls with a
//! hidden truth, the built-in thermal simulator, physical effects, and the thermal graph
//! surrogate of the Kalibre paper.

#![warn(missing_docs)]

pub mod effects;
mod error;
pub mod hall;
mod params;
pub mod snapshots;

pub use error::{Error, Result};
pub use params::ParamLayout;
