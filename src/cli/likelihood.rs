//! The likelihood of `kalibre calibrate` and `kalibre diagnose`, and `--nu`, the
//! Student-t's degrees of freedom.

// The fewest degrees of freedom `--nu` takes: 1, the Cauchy distribution.
use kalibre_core::calibrate::MIN_ROBUST_NU as MIN_NU;

use super::{CliError, CliResult};

/// `--nu` when not given: the usual robust choice.
pub const DEFAULT_NU: f64 = 4.0;

/// The likelihood of `kalibre calibrate` and `kalibre diagnose`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Likelihood {
    /// Student-t with `--nu` degrees of freedom.
    StudentT,
    /// Gaussian.
    Gaussian,
}

impl Likelihood {
    /// The settings' `robust_nu` for this likelihood and `--nu` (default
    /// [`DEFAULT_NU`]): a value below 1 (`MIN_ROBUST_NU`), or one given with the Gaussian
    /// likelihood, which has no degrees of freedom, is refused, not ignored.
    pub fn robust_nu(self, nu: Option<f64>) -> CliResult<Option<f64>> {
        if let Some(nu) = nu {
            if !(nu.is_finite() && nu >= MIN_NU) {
                return Err(CliError::Input(format!(
                    "--nu: expected a finite number >= {MIN_NU} (1 is the Cauchy \
                     distribution; fewer degrees of freedom count every residual as an \
                     outlier), got {}",
                    kalibre_dc::snapshots::number(nu)
                )));
            }
        }
        match (self, nu) {
            (Likelihood::StudentT, nu) => Ok(Some(nu.unwrap_or(DEFAULT_NU))),
            (Likelihood::Gaussian, None) => Ok(None),
            (Likelihood::Gaussian, Some(_)) => Err(CliError::Input(
                "--nu is the Student-t likelihood's degrees of freedom: add --likelihood \
                 student-t, or leave --nu out"
                    .into(),
            )),
        }
    }
}
