//! The hall: its description (`hall.json`), loading with every rule of `formats.md`
//! enforced, and the geometry the simulator, the surrogate and the generators share.

mod geometry;
mod read;
mod types;
mod validate;
mod write;

pub use geometry::{distance, face_centre, Aabb, ServerRef};
pub use types::*;
pub use validate::{unprintable_name, GEOMETRY_TOL_M, MAX_ALPHA_CFM_PER_W, MAX_NAME_CHARS};
