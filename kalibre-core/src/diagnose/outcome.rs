//! The outcome of a diagnosis: each hypothesis's scores, the verdict, and the outputs no
//! hypothesis explains.

use serde::{Deserialize, Serialize};

use super::{HeldOutScheme, CLOSE_ALTERNATIVE_BIC};
use crate::calibrate::NamedValues;

/// Schema tag of a serialised [`Diagnosis`].
pub const DIAGNOSIS_SCHEMA: &str = "kalibre.core.diagnosis/1";

/// The outcome of a diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Schema tag, [`DIAGNOSIS_SCHEMA`].
    pub schema: String,
    /// Mean absolute residual as given.
    pub mae: f64,
    /// Mean absolute residual after refitting the current parameters alone (linearised):
    /// the floor without a new parameter.
    pub refit_mae: f64,
    /// The current parameters' change in that refit alone: where a model run checks the
    /// floor. Missing in older diagnoses.
    #[serde(default, skip_serializing_if = "NamedValues::is_empty")]
    pub refit_change: NamedValues,
    /// Noise sigma used (given or estimated).
    pub noise_sigma: f64,
    /// Whether `noise_sigma` was estimated.
    pub noise_sigma_estimated: bool,
    /// How rows were held out.
    pub held_out: HeldOutScheme,
    /// Number of held-out folds.
    pub held_out_folds: usize,
    /// Root-mean-square held-out residual with the current parameters alone refit.
    pub held_out_rmse: f64,
    /// One result per hypothesis, best first.
    pub hypotheses: Vec<HypothesisResult>,
    /// Outputs still off by more than [`UNEXPLAINED_SCALES`](super::UNEXPLAINED_SCALES)
    /// scales of the likelihood (RMS over their rows) after the best significant
    /// hypothesis (or, with none, the current parameters' refit), worst first: what the
    /// model misses for a reason no candidate names (its own physics there, or a faulty
    /// or misplaced sensor).
    #[serde(default)]
    pub unexplained: Vec<UnexplainedOutput>,
    /// With a model-form uncertainty
    /// ([`Residuals::with_model_form`](super::Residuals::with_model_form)): the share of
    /// its variance the residuals bear out (maximum likelihood, in `[0, 1]`), by which it
    /// weighs the rows. Near 0 where the model reproduces the data (another physics'
    /// reading is then no uncertainty of it), 1 where the model's errors are as large.
    #[serde(default)]
    pub model_form_share: Option<f64>,
}

/// An output no hypothesis explains, see [`Diagnosis::unexplained`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnexplainedOutput {
    /// Output name (sensor id).
    pub output: String,
    /// Mean residual over its rows (model minus measurement, output units).
    pub mean_residual: f64,
    /// Root mean square of its residuals in scales of the likelihood (under a Gaussian,
    /// noise sigmas).
    pub rms_scales: f64,
    /// With a model-form uncertainty
    /// ([`Residuals::with_model_form`](super::Residuals::with_model_form)): its RMS over
    /// the output's rows, how far other plausible physics moves the output (output units).
    #[serde(default)]
    pub model_form_c: Option<f64>,
}

impl Diagnosis {
    /// The significant hypotheses, best first (empty: no significant missing effect).
    pub fn significant(&self) -> impl Iterator<Item = &HypothesisResult> {
        self.hypotheses.iter().filter(|h| h.significant)
    }

    /// The hypotheses the data hardly tell from the best significant one: fitted within
    /// their range, not inert, and with a BIC less than [`CLOSE_ALTERNATIVE_BIC`] above
    /// the best's (short of "strong" evidence between the two), best first. Empty when
    /// nothing is significant. Whether or not each is significant itself, a reader should
    /// weigh it beside the best: a neighbouring placement with a footprint of much the
    /// same shape, say.
    pub fn close_alternatives(&self) -> Vec<&HypothesisResult> {
        let Some(best) = self.significant().next() else {
            return Vec::new();
        };
        let mut close: Vec<&HypothesisResult> = self
            .hypotheses
            .iter()
            .filter(|h| {
                h.name != best.name
                    && h.in_range
                    && !h.inert
                    && h.delta_bic < best.delta_bic + CLOSE_ALTERNATIVE_BIC
            })
            .collect();
        close.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
        close
    }

    /// The explanations the ambiguity check left undecided between, best first (empty
    /// when it decided): the best undecided hypothesis and those it could not be told
    /// from. Others beyond that window that were left undecided because these are list
    /// the set in their `ambiguous_with` but are not in it.
    pub fn undecided(&self) -> Vec<&str> {
        self.hypotheses
            .iter()
            .filter(|h| !h.ambiguous_with.is_empty())
            .min_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic))
            .map(|best| {
                std::iter::once(best.name.as_str())
                    .chain(best.ambiguous_with.iter().map(String::as_str))
                    .collect()
            })
            .unwrap_or_default()
    }
}

/// How well one hypothesis explains the residuals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HypothesisResult {
    /// Hypothesis name.
    pub name: String,
    /// Fraction of the residual sum of squares (after refitting the current parameters)
    /// it removes, in [0, 1].
    pub explained_fraction: f64,
    /// Predicted MAE after adding it (refit residual).
    pub predicted_mae: f64,
    /// BIC change against the current parameters alone (negative: better).
    pub delta_bic: f64,
    /// Fraction of held-out squared error removed (negative: worse out of sample).
    pub held_out_improvement: f64,
    /// Significant: see the module documentation.
    pub significant: bool,
    /// The caller's model runs contradicted it
    /// ([`Hypothesis::refuted`](super::Hypothesis::refuted)), so it is not significant.
    #[serde(default)]
    pub refuted: bool,
    /// The outputs hardly move over its parameter range.
    pub inert: bool,
    /// The data can tell it apart from the current parameters and other hypotheses.
    pub identifiable: bool,
    /// Smallest singular value of its unit columns outside the current parameters' span.
    pub independence: f64,
    /// Largest movement of the outputs (2-norm over rows) one parameter makes over its
    /// range, in noise sigmas.
    pub movement_sigma: f64,
    /// Other hypotheses spanning the same directions (beyond the current parameters).
    pub collinear_with: Vec<String>,
    /// Rank it adds to the current parameters (the `k` of the BIC).
    pub added_rank: usize,
    /// Fitted values of its parameters (offsets from 0, the effect absent).
    pub fitted: NamedValues,
    /// Whether every fitted value lies in its parameter's range.
    pub in_range: bool,
    /// Each parameter's range `[lower, upper]`, in `fitted`'s order (so that a fit
    /// outside it can be said to be below or above it). Missing in older diagnoses.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ranges: Vec<[f64; 2]>,
    /// Change of the current parameters in the joint refit.
    pub current_change: NamedValues,
    /// The largest BIC change with one output (all its snapshots) left out, for a
    /// hypothesis that passes every other test (none otherwise, or with the check off).
    #[serde(default)]
    pub single_output_delta_bic: Option<f64>,
    /// For a hypothesis the single-output check stops (or, with
    /// [`crate::diagnose::DiagnoseSettings::sensor_bias_rival_bic`], would stop): its BIC
    /// less that of a constant bias at the output it rests on, both refit with the
    /// current parameters; negative when the data prefer the effect to a fault of that
    /// sensor.
    #[serde(default)]
    pub sensor_bias_delta_bic: Option<f64>,
    /// The output this hypothesis rests on when the single-output check alone stops it:
    /// without that output (all its snapshots) the others no longer prefer it. A local
    /// effect seen by one sensor looks like this, and so does a faulty sensor or the
    /// model's own error there; only a look at that sensor tells them apart.
    #[serde(default)]
    pub carried_by: Option<String>,
    /// Significant explanations of other footprints (not collinear with it) that fit
    /// about as well as the best (BIC within [`CLOSE_ALTERNATIVE_BIC`]), when the
    /// ambiguity check left them all undecided: the data say something is missing, not
    /// which of these it is. Empty otherwise.
    #[serde(default)]
    pub ambiguous_with: Vec<String>,
}
