//! The crate's error type.

use thiserror::Error;

/// Errors of the baselines.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the calibration core (parameters, journal, argmin).
    #[error(transparent)]
    Core(#[from] kalibre_core::Error),
    /// An error of the data-hall crate (hall, layout).
    #[error(transparent)]
    Dc(#[from] kalibre_dc::Error),
    /// A setting is out of its range.
    #[error("setting `{name}`: {reason}")]
    InvalidSetting {
        /// Setting name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// Inputs do not fit together (lengths, missing data).
    #[error("{0}")]
    Mismatch(String),
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Checks a setting with a predicate, naming it in the error.
pub(crate) fn require(ok: bool, name: &str, reason: impl FnOnce() -> String) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::InvalidSetting {
            name: name.into(),
            reason: reason(),
        })
    }
}
