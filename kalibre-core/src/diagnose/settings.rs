//! Settings of the diagnosis, checked once before it runs.

use serde::{Deserialize, Serialize};

use crate::calibrate::MIN_ROBUST_NU;
use crate::{Error, Result};

/// Settings of [`crate::diagnose::diagnose`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `noise_sigma` | none | measurement noise (standard deviation, output units); none: estimated from the refit of the current parameters alone, `sqrt(RSS_0 / (n - rank J))`, which is an upper bound when an effect is missing | finite, > 0 |
/// | `bic_threshold` | 10 | a hypothesis must lower the BIC by at least this much (10: "very strong" evidence on the Kass-Raftery scale) | finite, >= 0 |
/// | `min_held_out_improvement` | 0.05 | it must also remove at least this fraction of the held-out squared error (and, always, predict a lower MAE than the current parameters' own refit) | finite, < 1 |
/// | `inert_snr` | 1 | inert when no parameter, moved from 0 to the far end of its range, changes the outputs by this many noise sigmas (2-norm over all rows) | finite, >= 0 |
/// | `min_independence` | 0.05 | identifiable when the hypothesis's unit columns, with the current parameters' span removed, keep a smallest singular value of at least this (1: orthogonal, 0: dependent), and no other hypothesis spans the same residual directions | (0, 1) |
/// | `prior_weight` | 0 | ridge on the hypothesis's parameters: adds `prior_weight * (dq_j / s_j)^2` in noise-sigma units, `s_j` the larger magnitude of its bounds (a Gaussian prior of that scale); 0: plain least squares | finite, >= 0 |
/// | `robust_nu` | 4 | degrees of freedom of the Student-t likelihood every fit, BIC and held-out check uses, so that a few outputs the model misses for reasons no hypothesis names (its own physics, a faulty sensor) do not decide the ranking; none: Gaussian (least squares) | finite, >= 1 |
/// | `single_output_check` | true | a significant hypothesis must still be preferred (BIC change below 0) with any one output (all its snapshots) left out, so that a model error at one sensor (or a faulty sensor) cannot carry it alone | |
/// | `sensor_bias_rival_bic` | none | with a value `t`: a hypothesis the single-output check would stop stays significant when its BIC is at least `t` below that of a constant bias at the output it rests on (a faulty sensor, or the model's own error there), both refit with the current parameters; none: the check stops it | finite, >= 0 |
/// | `ambiguity_check` | true | when another significant hypothesis of another footprint (not collinear with the best, and its fit changing other readings: cosine of the explained changes below 0.9) has a BIC within 6 of the best's, none is significant: each lists the others in `ambiguous_with` (the data say something is missing, not which) | |
/// | `output_folds` | 5 | folds of the held-out check over outputs when there is one snapshot (with two or more: leave one snapshot out) | >= 2 |
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseSettings {
    /// Measurement noise standard deviation; `None` estimates it.
    pub noise_sigma: Option<f64>,
    /// Least BIC decrease for significance.
    pub bic_threshold: f64,
    /// Least fraction of held-out squared error removed for significance.
    pub min_held_out_improvement: f64,
    /// Movement over the range, in noise sigmas, under which a hypothesis is inert.
    pub inert_snr: f64,
    /// Least independence from the current parameters (and other hypotheses).
    pub min_independence: f64,
    /// Weight of the Gaussian prior (ridge) on hypothesis parameters.
    pub prior_weight: f64,
    /// Number of output folds when there is a single snapshot.
    pub output_folds: usize,
    /// Whether the single-output check applies.
    #[serde(default = "default_true")]
    pub single_output_check: bool,
    /// Student-t degrees of freedom; `None`: Gaussian.
    #[serde(default = "default_robust_nu")]
    pub robust_nu: Option<f64>,
    /// Whether a best explanation that another explanation of a different footprint
    /// fits about as well is left undecided (see the module documentation).
    #[serde(default = "default_true")]
    pub ambiguity_check: bool,
    /// How much lower than a constant bias at its one carrying output a hypothesis's BIC
    /// must be for it to pass the single-output check anyway; `None`: never.
    #[serde(default)]
    pub sensor_bias_rival_bic: Option<f64>,
}

fn default_true() -> bool {
    true
}

fn default_robust_nu() -> Option<f64> {
    Some(4.0)
}

impl Default for DiagnoseSettings {
    fn default() -> Self {
        DiagnoseSettings {
            noise_sigma: None,
            bic_threshold: 10.0,
            min_held_out_improvement: 0.05,
            inert_snr: 1.0,
            min_independence: 0.05,
            prior_weight: 0.0,
            output_folds: 5,
            single_output_check: true,
            robust_nu: default_robust_nu(),
            ambiguity_check: true,
            sensor_bias_rival_bic: None,
        }
    }
}

fn bad(name: &str, reason: String) -> Error {
    Error::InvalidSetting {
        name: name.into(),
        reason,
    }
}

fn non_negative(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(bad(
            name,
            format!("must be finite and >= 0, got {}", crate::number(v)),
        ))
    }
}

impl DiagnoseSettings {
    /// The defaults (see the table).
    pub fn new() -> Self {
        Self::default()
    }

    /// Uses a known measurement noise instead of estimating it.
    pub fn with_noise_sigma(mut self, sigma: f64) -> Self {
        self.noise_sigma = Some(sigma);
        self
    }

    /// Sets the least BIC decrease for significance.
    pub fn with_bic_threshold(mut self, t: f64) -> Self {
        self.bic_threshold = t;
        self
    }

    /// Sets the least held-out improvement for significance.
    pub fn with_min_held_out_improvement(mut self, f: f64) -> Self {
        self.min_held_out_improvement = f;
        self
    }

    /// Sets the inert threshold (noise sigmas).
    pub fn with_inert_snr(mut self, snr: f64) -> Self {
        self.inert_snr = snr;
        self
    }

    /// Sets the least independence for identifiability.
    pub fn with_min_independence(mut self, v: f64) -> Self {
        self.min_independence = v;
        self
    }

    /// Turns the single-output check on or off.
    pub fn with_single_output_check(mut self, on: bool) -> Self {
        self.single_output_check = on;
        self
    }

    /// Sets the likelihood: Student-t with `nu` degrees of freedom, or (`None`) Gaussian.
    pub fn with_robust_nu(mut self, nu: Option<f64>) -> Self {
        self.robust_nu = nu;
        self
    }

    /// Sets the weight of the prior on hypothesis parameters.
    pub fn with_prior_weight(mut self, w: f64) -> Self {
        self.prior_weight = w;
        self
    }

    /// Sets the number of output folds for a single snapshot.
    pub fn with_output_folds(mut self, k: usize) -> Self {
        self.output_folds = k;
        self
    }

    /// Turns the ambiguity check on or off.
    pub fn with_ambiguity_check(mut self, on: bool) -> Self {
        self.ambiguity_check = on;
        self
    }

    /// Lets a hypothesis that rests on one output pass when its BIC is at least `t` below
    /// that of a constant bias at that output; `None`: the single-output check stops it.
    pub fn with_sensor_bias_rival_bic(mut self, t: Option<f64>) -> Self {
        self.sensor_bias_rival_bic = t;
        self
    }

    /// Checks every setting against its range, naming the first offender.
    pub fn check(&self) -> Result<()> {
        if let Some(s) = self.noise_sigma {
            if !(s.is_finite() && s > 0.0) {
                return Err(bad(
                    "noise_sigma",
                    format!("must be finite and > 0, got {}", crate::number(s)),
                ));
            }
        }
        non_negative("bic_threshold", self.bic_threshold)?;
        let h = self.min_held_out_improvement;
        if !(h.is_finite() && h < 1.0) {
            return Err(bad(
                "min_held_out_improvement",
                format!("must be finite and < 1, got {}", crate::number(h)),
            ));
        }
        non_negative("inert_snr", self.inert_snr)?;
        let v = self.min_independence;
        if !(v > 0.0 && v < 1.0) {
            return Err(bad(
                "min_independence",
                format!("must be in (0, 1), got {}", crate::number(v)),
            ));
        }
        non_negative("prior_weight", self.prior_weight)?;
        if let Some(t) = self.sensor_bias_rival_bic {
            non_negative("sensor_bias_rival_bic", t)?;
        }
        if let Some(nu) = self.robust_nu {
            if !(nu.is_finite() && nu >= MIN_ROBUST_NU) {
                return Err(bad(
                    "robust_nu",
                    format!(
                        "must be finite and >= {MIN_ROBUST_NU}, got {}",
                        crate::number(nu)
                    ),
                ));
            }
        }
        if self.output_folds < 2 {
            return Err(bad(
                "output_folds",
                format!("must be at least 2, got {}", self.output_folds),
            ));
        }
        Ok(())
    }
}
