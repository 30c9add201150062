//! The thermal graph surrogate of the Kalibre paper, and its search regulariser.
//!
//! - [`ThermalGraph`]: the knowledge-based neural surrogate (cooling block, heating block,
//!   adjacency from the hall's geometry), a [`kalibre_core::Surrogate`] over the hall's
//!   [`crate::ParamLayout`] (alpha per type or per server);
//! - [`Adjacency`]: the sparse CRAC-to-sensor and server-to-sensor weights;
//! - training ([`ThermalGraphSettings`]): least-squares start, then full-batch Adam;
//! - [`TemperatureRisePenalty`]: the paper's power-weighted ReLU prior on server
//!   temperature rises, with a report of where it binds;
//! - [`ThermalGraphObjective`]: the search loss on a fitted graph, precomputed for speed;
//! - [`SurrogateTerm`]: the extension point for effect terms; [`EffectLinearTerm`]: the
//!   learned linear term of one effect parameter.

mod adjacency;
mod effect_linear;
mod flow_balance;
mod graph;
mod local_flow;
mod objective;
mod penalty;
mod ridge;
mod term;
mod train;

pub use adjacency::{Adjacency, AdjacencySettings, Csr};
pub use effect_linear::EffectLinearTerm;
pub use flow_balance::{FlowBalance, FlowBalanceTerm};
pub use graph::{ThermalGraph, ThermalGraphSettings, HALL_WIDE_RIDGE};
pub use local_flow::{LocalRecirculationSettings, LocalRecirculationTerm, LOCAL_RADIUS_M};
pub use objective::ThermalGraphObjective;
pub use penalty::{
    PenaltyReport, PenaltySettings, RiseBound, RiseViolation, TemperatureRisePenalty, M3_S_PER_CFM,
    MAX_RISE_C, MAX_WEIGHT,
};
pub use term::SurrogateTerm;
