//! Extension point: additional linear terms of the thermal graph.
//!
//! The paper's surrogate only knows alpha. A physical effect (issue 6: bypass, leakage,
//! supply offsets, ...) adds its parameters to the [`crate::ParamLayout`] and its influence
//! to the surrogate as a [`SurrogateTerm`]: a feature per sensor `f_k(scenario, params)`
//! that enters every sensor's output as `e_k * (f_k - mean_k) / scale_k`, where `e_k` is a
//! trainable weight fitted with the others (least squares start, then Adam) and the
//! mean and scale are taken over the training samples at each fit.

use std::fmt::Debug;

use crate::snapshots::OperatingState;

/// The [`SurrogateTerm::min_scale`] of terms whose feature is a temperature (K): one that
/// moved less than 0.1 K over the training runs (e.g. recirculation in none of them) is
/// treated as constant.
pub(crate) const TEMPERATURE_MIN_SCALE_K: f64 = 0.1;

/// One additional linear term of the [`super::ThermalGraph`].
pub trait SurrogateTerm: Send + Sync + Debug {
    /// A short name (the effect kind), for reports.
    fn name(&self) -> &str;

    /// The feature of every sensor at a scenario and physical parameters (the full hall
    /// parameter vector), written into `out` (one value per sensor, hall order).
    fn features(&self, scenario: &OperatingState, params: &[f64], out: &mut [f64]);

    /// Adds `sum_k cotangent_k * d f_k / d params` into `grad` (one value per parameter).
    fn features_vjp(
        &self,
        scenario: &OperatingState,
        params: &[f64],
        cotangent: &[f64],
        grad: &mut [f64],
    );

    /// The smallest scale the fit divides this feature by (the feature's units). A
    /// feature that moved less than this over the training samples counts as not having
    /// moved: its weight is then left to the ridge instead of being fitted to a spread
    /// of, say, 1e-9, which a prediction where the feature does move would multiply by
    /// millions. Default 0: the fit's own floor only.
    fn min_scale(&self) -> f64 {
        0.0
    }

    /// Whether the feature is one value for the whole hall (per snapshot), moving with
    /// every server's alpha at once. Such a feature is nearly collinear with the local
    /// heating features over a few runs (the initial design moves every alpha together),
    /// so a free weight per sensor would take variance that belongs to the servers next
    /// to the sensor and give each sensor a response to every type's alpha, in proportion
    /// to the type's total power. The fit holds these weights at zero with
    /// [`super::ThermalGraphSettings::hall_wide_ridge`] instead of `ridge`, so they only
    /// explain what the local blocks cannot. Default false.
    fn hall_wide(&self) -> bool {
        false
    }
}
