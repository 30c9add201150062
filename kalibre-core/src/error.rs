//! The crate's error type.

use thiserror::Error;

/// Errors of the calibration core.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// A parameter definition or value is invalid (inverted or non-finite bounds, wrong length, ...).
    #[error("parameter `{name}`: {reason}")]
    InvalidParam {
        /// Parameter name (or `#index` when unnamed).
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A setting of an algorithm is out of its range.
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
    /// The run journal could not be read or written.
    #[error("run journal {path}: {reason}")]
    Journal {
        /// Journal file.
        path: String,
        /// What went wrong.
        reason: String,
    },
    /// An I/O error with the file it concerns.
    #[error("{path}: {source}")]
    Io {
        /// File or directory concerned.
        path: String,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A surrogate could not be fitted (no data, non-finite loss, ...).
    #[error("surrogate fit failed: {0}")]
    Fit(String),
    /// A search failed.
    #[error("search failed: {0}")]
    Search(String),
    /// The surrogate has nothing to train on: no model run of the initial design
    /// succeeded, or every run at one snapshot failed (no point then ran at every
    /// snapshot, so no run can be validated against all the measurements).
    #[error("nothing for the surrogate to learn from: {0}")]
    NoSuccessfulRun(String),
    /// An error from the argmin executor, converted at the boundary.
    #[error("optimiser: {0}")]
    Argmin(String),
}

impl Error {
    /// Shorthand for an [`Error::Io`] naming its path.
    pub fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
