//! The CLI's error: one readable line, and the exit code it maps to.

use std::fmt;

/// An error the CLI reports as one line before exiting non-zero.
#[derive(Debug)]
pub enum CliError {
    /// Bad input (a file, an argument): exit code 2.
    Input(String),
    /// A failure while working (I/O on output, a solver): exit code 1.
    Run(String),
}

impl CliError {
    /// The process exit code.
    pub fn exit_code(&self) -> i32 {
        match self {
            CliError::Input(_) => 2,
            CliError::Run(_) => 1,
        }
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Input(m) | CliError::Run(m) => f.write_str(m),
        }
    }
}

impl From<kalibre_dc::Error> for CliError {
    fn from(e: kalibre_dc::Error) -> Self {
        match e {
            // Reading a hall or snapshot file that is not there is bad input too.
            kalibre_dc::Error::Simulation(_) => CliError::Run(e.to_string()),
            _ => CliError::Input(e.to_string()),
        }
    }
}

impl From<kalibre_core::Error> for CliError {
    fn from(e: kalibre_core::Error) -> Self {
        match e {
            kalibre_core::Error::Io { .. } | kalibre_core::Error::Journal { .. } => {
                CliError::Run(e.to_string())
            }
            _ => CliError::Input(e.to_string()),
        }
    }
}

/// Result of a CLI command.
pub type CliResult<T = ()> = Result<T, CliError>;

/// Wraps an I/O error on an output path.
pub fn io_err(path: &std::path::Path, e: std::io::Error) -> CliError {
    CliError::Run(format!("{}: {e}", path.display()))
}
