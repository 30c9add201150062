//! # kalibre-dc
//!
//! kalibre for air-cooled data halls: the hall and snapshot files, synthetic halls with a
//! hidden truth, the built-in thermal simulator, physical effects, and the thermal graph
//! surrogate of the Kalibre paper.

#![warn(missing_docs)]

pub mod calibration;
pub mod calibration_model;
pub mod diagnosis;
pub mod effects;
mod error;
pub mod hall;
pub mod json_keys;
mod model;
pub mod next_hall;
pub mod openfoam;
mod params;
pub mod report;
pub mod sim;
pub mod snapshots;
pub mod story;
pub mod surrogate;
pub mod synth;

pub use error::{Error, Result};
pub use model::{check_sensor_c, operating_state_key, HallModel, PLAUSIBLE_SENSOR_C};
pub use params::ParamLayout;
