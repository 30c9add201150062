//! The calibration loop's settings, checked once before the loop starts.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// Settings of a [`crate::Calibrator`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `seed` | 0 | seeds augmentation, fits, searches and perturbations | any |
/// | `max_iterations` | 20 | four-step iterations after the initial design | >= 1 |
/// | `target_score` | none | stop when the best score (default: MAE) is at most this | finite, >= 0 |
/// | `max_model_runs` | none | stop before exceeding this many model runs (design included) | >= design runs |
/// | `max_wall_s` | none | stop once this much wall time passed: checked before each iteration, polish step and numerical variant (not run once it has passed), and inside each surrogate fit (per epoch) and search (per generation or step), which then end with their best so far and no model run at the proposal | finite, > 0 |
/// | `max_parallel_runs` | none | model runs at once (a dedicated rayon pool); none: the current pool | 1 to 1024 |
/// | `augment_copies` | 16 | samples per design run in the first fit: the run plus `copies - 1` noisy copies | >= 1 |
/// | `augment_sigma` | 0.05 | standard deviation of the augmentation noise, unit box | finite, >= 0 |
/// | `regularizer_weight` | 1 | weight of the regulariser in the search loss (when one is given) | finite, >= 0 |
/// | `duplicate_tol` | 1e-9 | max-norm distance in the unit box under which two points are the same | [0, 1) |
/// | `perturb_sigma` | 0.05 | noise that moves a proposal off an earlier failed point (one within [`super::FAILED_NEIGHBOURHOOD_UNIT`], 1e-3, of it), unit box | finite, > 0 |
/// | `explore_on_repeat` | none | when the search proposes a point already run: none stops (converged); a sigma moves the proposal with that much seeded noise (unit box) and goes on | (0, 1] |
/// | `output_correction` | false | search the surrogate plus, per snapshot and output, the model's outputs minus the surrogate's at the best run (the corrected surrogate matches the model there) | bool |
/// | `linear_correction` | false | with `output_correction`: add a linear term in the unit box fitted to the model-minus-surrogate discrepancy at the other runs (weighted by distance, minimum norm), so the search also follows the model's slopes along explored directions | bool |
/// | `stall_step` | none | with `linear_correction`: when the search's proposal promises less than 10% below the best run's loss (or repeats a run), run instead at the best point moved by this much (max norm, unit box) along the direction the runs near it covered least, so the next correction learns the model's slope there | finite, (0, 1] |
/// | `trust_region` | none | search the surrogate only within this max-norm distance (unit box) of the best point; doubled after a step that improved the model, halved after one that did not (down to 0.001); none: the whole box | [0.001, 1] |
/// | `polish_iterations` | 0 | after the loop, this many Levenberg-Marquardt steps on the model itself (finite-difference Jacobians: `dim + 1` runs per snapshot after each accepted step, one after a rejected one); for models cheap enough to afford it | any |
/// | `robust_nu` | none | the data term's likelihood: none is the paper's mean squared error; `nu` a Student-t with `nu` degrees of freedom (4 is the usual robust choice), its scale fitted to the residuals, in the polish (reweighted Levenberg-Marquardt) and the uncertainty, so that a few outputs the model cannot match do not set the parameters; the iterations' search keeps the squared error (it finds the basin) | finite, >= 1 |
/// | `numerical_weighting` | false | with numerical variants ([`crate::Calibrator::with_numerical_variant`]) and a polish: the variants run at the loop's best before the polish, and the polish weighs each measured output by `s^2 / (s^2 + u^2)`, `u` its largest change over the variants and `s^2` the noise variance that leaves the weighted residuals their degrees of freedom (generalised least squares with the numerics as a per-output error); the uncertainty uses the same weights | bool |
/// | `prior_in_best` | false | with a regulariser: judge which run is the best by its score plus the weighted regulariser at its parameters (the run's own value of what the search minimises, with the score for the misfit), so that a run whose lower error comes from parameters the prior rules out does not become the search's centre | bool |
/// | `focus` | none | fit the surrogate where the model meets the data: a run whose MAE is `m` times the best run's on its snapshot weighs `exp(-((m - 1) / focus)^2 / 2)`; none: every run weighs 1. The first fit (the design) is never focused | finite, >= 0.01 |
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Calibration seed.
    pub seed: u64,
    /// Four-step iterations after the initial design.
    pub max_iterations: usize,
    /// Stop once the best score is at most this.
    pub target_score: Option<f64>,
    /// Budget of model runs, initial design and cached replays included.
    pub max_model_runs: Option<usize>,
    /// Budget of wall-clock time, seconds.
    pub max_wall_s: Option<f64>,
    /// Model runs at once; `None` runs them in the current rayon pool.
    pub max_parallel_runs: Option<usize>,
    /// Samples per design run in the first fit (the run itself plus noisy copies).
    pub augment_copies: usize,
    /// Standard deviation of the augmentation noise in the unit box.
    pub augment_sigma: f64,
    /// Weight of the regulariser in the search loss.
    pub regularizer_weight: f64,
    /// Max-norm distance in the unit box under which two points count as the same.
    pub duplicate_tol: f64,
    /// Standard deviation of the noise that moves a proposal off a failed point.
    pub perturb_sigma: f64,
    /// Width of the fit's focus on runs close to the measurements (none: uniform weights).
    pub focus: Option<f64>,
    /// Noise (unit box) that moves a repeated proposal; none: a repeat stops the loop.
    pub explore_on_repeat: Option<f64>,
    /// Correct the surrogate to match the model at the best run before each search.
    pub output_correction: bool,
    /// With `output_correction`, also correct the surrogate's slopes from the other runs.
    /// Missing in older reports: false.
    #[serde(default)]
    pub linear_correction: bool,
    /// With the linear correction, the geometry step taken instead of a stalled proposal.
    /// Missing in older reports: none.
    #[serde(default)]
    pub stall_step: Option<f64>,
    /// Initial trust-region radius (unit box); none searches the whole box.
    pub trust_region: Option<f64>,
    /// Levenberg-Marquardt steps on the model after the loop (0: none). Missing in older
    /// reports: 0.
    #[serde(default)]
    pub polish_iterations: usize,
    /// The data term's likelihood: none for the paper's mean squared error, or the
    /// degrees of freedom of a Student-t whose scale is fitted to the residuals (the
    /// polish and the uncertainty then weigh outliers down; the iterations' search keeps
    /// the squared error). Missing in older reports: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robust_nu: Option<f64>,
    /// Weigh each output in the polish and the uncertainty by how far the model's
    /// numerical variants leave it trustworthy. Missing in older reports: false.
    #[serde(default)]
    pub numerical_weighting: bool,
    /// Judge the best run by its score plus the weighted regulariser. Missing in older
    /// reports: false.
    #[serde(default)]
    pub prior_in_best: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            seed: 0,
            max_iterations: 20,
            target_score: None,
            max_model_runs: None,
            max_wall_s: None,
            max_parallel_runs: None,
            augment_copies: 16,
            augment_sigma: 0.05,
            regularizer_weight: 1.0,
            duplicate_tol: 1e-9,
            perturb_sigma: 0.05,
            focus: None,
            explore_on_repeat: None,
            output_correction: false,
            linear_correction: false,
            stall_step: None,
            trust_region: None,
            polish_iterations: 0,
            robust_nu: None,
            numerical_weighting: false,
            prior_in_best: false,
        }
    }
}

impl Settings {
    /// The loop `kalibre calibrate` runs (`kalibre_dc`'s hall calibrations start from
    /// it): the surrogate corrected to the model's runs near the best one and along the
    /// directions they explored, a trust region, a step off a stall, sampling beside a
    /// repeated proposal, a focus of the fit on runs near the measurements, and 8 polish
    /// steps on the model's own finite differences. [`Settings::default`] is the paper's
    /// plain loop, kept for its experiments; this one is what to start from with a model
    /// of your own, whose surrogate is rarely right far from its runs. (A library user's
    /// damped oscillator with a ridge-quadratic surrogate: 0.0092-0.0095 MAE on all of 5
    /// seeds, at the noise, where the default reached it on 1.)
    ///
    /// ```
    /// use kalibre_core::Settings;
    /// let s = Settings { seed: 7, ..Settings::recommended() };
    /// assert!(s.output_correction && s.trust_region.is_some());
    /// assert!(s.check().is_ok());
    /// ```
    pub fn recommended() -> Self {
        Settings {
            seed: 1,
            max_iterations: 10,
            focus: Some(1.0),
            explore_on_repeat: Some(0.015),
            output_correction: true,
            linear_correction: true,
            stall_step: Some(0.03),
            trust_region: Some(0.1),
            polish_iterations: 8,
            numerical_weighting: true,
            prior_in_best: true,
            ..Settings::default()
        }
    }
}

impl Settings {
    /// [`Settings::recommended`] for a [`crate::GaussianProcess`] surrogate, the loop
    /// `kalibre calibrate --model command` runs: one sample per design run
    /// (`augment_copies: 1`) and no focus weights. The noisy copies help a surrogate of
    /// a physical form learn it; to a Gaussian process they are flat plateaus around
    /// each run that it fits as data (a library user's damped oscillator, 3 parameters,
    /// no polish: best MAE 0.030-0.136 after 10 iterations over 5 seeds with the 16
    /// copies, 0.004-0.011 with one). A process forgets runs the focus weighs down, so
    /// it ignores the weights unless told otherwise ([`crate::GaussianProcess`]).
    ///
    /// ```
    /// use kalibre_core::Settings;
    /// let s = Settings::recommended_for_gaussian_process();
    /// assert_eq!((s.augment_copies, s.focus), (1, None));
    /// assert!(s.output_correction && s.check().is_ok());
    /// ```
    pub fn recommended_for_gaussian_process() -> Self {
        Settings {
            augment_copies: 1,
            focus: None,
            ..Settings::recommended()
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

/// The smallest [`Settings::trust_region`]: the radius is never halved below it, and a
/// region smaller than this cannot move the search off its start.
pub const MIN_TRUST_REGION: f64 = 1e-3;

/// The fewest degrees of freedom a Student-t likelihood (`robust_nu`) takes here: 1, the
/// Cauchy distribution. Below it the fit weighs every residual as an outlier, so any
/// change "explains" the data.
pub const MIN_ROBUST_NU: f64 = 1.0;

/// The narrowest [`Settings::focus`]: below it a run 5 % worse than the best weighs
/// under 1e-5, so the surrogate learns from the best run alone.
pub const MIN_FOCUS: f64 = 0.01;

/// The most model runs [`Settings::max_parallel_runs`] allows at once.
pub const MAX_PARALLEL_RUNS: usize = 1024;

impl Settings {
    /// Checks every setting against its range, naming the first offender.
    pub fn check(&self) -> Result<()> {
        if self.max_iterations == 0 {
            return Err(bad("max_iterations", "must be at least 1".into()));
        }
        if let Some(t) = self.target_score {
            non_negative("target_score", t)?;
        }
        if self.max_model_runs == Some(0) {
            return Err(bad("max_model_runs", "must be at least 1".into()));
        }
        if let Some(w) = self.max_wall_s {
            if !(w.is_finite() && w > 0.0) {
                return Err(bad(
                    "max_wall_s",
                    format!("must be finite and > 0, got {}", crate::number(w)),
                ));
            }
        }
        match self.max_parallel_runs {
            Some(0) => return Err(bad("max_parallel_runs", "must be at least 1".into())),
            // Each run at once is a thread; thousands of them only thrash.
            Some(n) if n > MAX_PARALLEL_RUNS => {
                return Err(bad(
                    "max_parallel_runs",
                    format!("must be at most {MAX_PARALLEL_RUNS}, got {n}"),
                ))
            }
            _ => {}
        }
        if self.linear_correction && !self.output_correction {
            return Err(bad(
                "linear_correction",
                "needs output_correction (the linear term is anchored at the corrected best run)"
                    .into(),
            ));
        }
        if let Some(h) = self.stall_step {
            if !(h.is_finite() && h > 0.0 && h <= 1.0) {
                return Err(bad(
                    "stall_step",
                    format!("must be in (0, 1], got {}", crate::number(h)),
                ));
            }
            if !self.linear_correction {
                return Err(bad(
                    "stall_step",
                    "needs linear_correction (the step feeds the linear term)".into(),
                ));
            }
        }
        if self.augment_copies == 0 {
            return Err(bad(
                "augment_copies",
                "must be at least 1 (1: no augmentation)".into(),
            ));
        }
        non_negative("augment_sigma", self.augment_sigma)?;
        non_negative("regularizer_weight", self.regularizer_weight)?;
        // The unit box is 1 wide: a tolerance of 1 makes every proposal a repeat, and
        // the loop would stop as converged right after its design.
        if !(self.duplicate_tol >= 0.0 && self.duplicate_tol < 1.0) {
            return Err(bad(
                "duplicate_tol",
                format!(
                    "must be in [0, 1), got {}",
                    crate::number(self.duplicate_tol)
                ),
            ));
        }
        // The unit box is 1 wide: noise beyond that only lands on its faces.
        if let Some(s) = self.explore_on_repeat {
            if !(s.is_finite() && s > 0.0 && s <= 1.0) {
                return Err(bad(
                    "explore_on_repeat",
                    format!("must be in (0, 1], got {}", crate::number(s)),
                ));
            }
        }
        if let Some(r) = self.trust_region {
            if !(r.is_finite() && (MIN_TRUST_REGION..=1.0).contains(&r)) {
                return Err(bad(
                    "trust_region",
                    format!(
                        "must be in [{MIN_TRUST_REGION}, 1], got {}",
                        crate::number(r)
                    ),
                ));
            }
        }
        if let Some(f) = self.focus {
            if !(f.is_finite() && f >= MIN_FOCUS) {
                return Err(bad(
                    "focus",
                    format!(
                        "must be finite and >= {MIN_FOCUS}, got {}",
                        crate::number(f)
                    ),
                ));
            }
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
        if !(self.perturb_sigma.is_finite() && self.perturb_sigma > 0.0) {
            return Err(bad(
                "perturb_sigma",
                format!(
                    "must be finite and > 0, got {}",
                    crate::number(self.perturb_sigma)
                ),
            ));
        }
        Ok(())
    }
}
