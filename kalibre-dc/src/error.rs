//! The crate's error type.

use thiserror::Error;

/// Errors of the data-hall domain.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// A file breaks its format: names the file, the field (JSON pointer, or CSV line and
    /// column) and what was expected.
    #[error("{file}: {field}: {message}")]
    Format {
        /// The file (path or name).
        file: String,
        /// JSON pointer (`/racks/3/servers/0/u`) or CSV position (`line 12, column value`).
        field: String,
        /// What is wrong and what was expected.
        message: String,
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
    /// An effect entry or effect parameter is invalid.
    #[error("effect `{kind}`: {message}")]
    Effect {
        /// Effect kind.
        kind: String,
        /// What is wrong.
        message: String,
    },
    /// The simulator could not solve (no convergence, inconsistent state).
    #[error("simulator: {0}")]
    Simulation(String),
    /// The hall (or an effect's place in it) cannot be laid on the simulator's grid, or a
    /// simulator setting is out of range: bad input, found before any run, that no
    /// parameter value would cure (a rack thinner than a cell, a tile over solid cells
    /// only, a region with no return path).
    #[error("the built-in simulator cannot set up the hall: {0}")]
    Geometry(String),
    /// Inputs that do not fit together (lengths, ids).
    #[error("{0}")]
    Mismatch(String),
    /// A run journal holds runs of another model than the one calibrating (another hall,
    /// effects, grid, parameters or model options): its runs cannot be reused, and mixing
    /// them in one file would make it unreadable to both.
    #[error(
        "{path}: holds {runs} runs of another model (a different model, hall, grid, effects \
         or settings); calibrate into another directory"
    )]
    OtherModelJournal {
        /// The journal file.
        path: String,
        /// How many of its runs are of another model.
        runs: usize,
        /// The line of the first of them (1-based), when the journal also holds runs of
        /// this model.
        first_line: Option<usize>,
    },
    /// An error of the calibration core.
    #[error(transparent)]
    Core(#[from] kalibre_core::Error),
}

impl Error {
    /// Shorthand for [`Error::Format`].
    pub fn format(
        file: impl Into<String>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Format {
            file: file.into(),
            field: field.into(),
            message: message.into(),
        }
    }

    /// Shorthand for an [`Error::Io`] naming its path.
    pub fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }

    /// An [`Error::Effect`] about an entry of `hall.effects` (its message starts with
    /// `effects/<i>: `, as the registry and the model's placement checks write it) as an
    /// [`Error::Format`] naming the hall's `file` and the entry's JSON pointer, as
    /// [`crate::effects::EffectRegistry::check_hall`] reports; any other error as it is.
    ///
    /// ```
    /// use kalibre_dc::Error;
    /// let e = Error::Effect { kind: "bypass".into(), message: "effects/1: covers no open cell".into() };
    /// assert_eq!(
    ///     e.in_hall_file("hall.json").to_string(),
    ///     "hall.json: /effects/1: effect `bypass`: covers no open cell"
    /// );
    /// ```
    pub fn in_hall_file(self, file: &str) -> Self {
        self.in_hall_file_at(file, None)
    }

    /// [`Self::in_hall_file`], pointing at the entry's `no_field` when the message names
    /// no field.
    pub(crate) fn in_hall_file_at(self, file: &str, no_field: Option<&str>) -> Self {
        // A placement the grid cannot hold, led by the entry's JSON pointer.
        if let Error::Geometry(message) = &self {
            if let Some((pointer, rest)) = message
                .split_once(": ")
                .filter(|(p, _)| p.starts_with('/') && !p.contains(' '))
            {
                return Error::format(
                    file,
                    pointer,
                    format!("the built-in simulator cannot place it: {rest}"),
                );
            }
        }
        let Error::Effect { kind, message } = self else {
            return self;
        };
        let entry = message
            .strip_prefix("effects/")
            .and_then(|m| m.split_once(": "))
            .filter(|(i, _)| i.parse::<usize>().is_ok());
        match entry {
            Some((i, rest)) => {
                let (field, rest) = crate::effects::fields::split_field(rest);
                let pointer = match field.or(no_field) {
                    Some(f) => format!("/effects/{i}/{f}"),
                    None => format!("/effects/{i}"),
                };
                Error::format(file, pointer, format!("effect `{kind}`: {rest}"))
            }
            None => Error::Effect { kind, message },
        }
    }
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
