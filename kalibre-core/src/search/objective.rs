//! The paper's search loss: surrogate against measurements, plus an optional regulariser.

use crate::{Observations, ParamSpace, Surrogate};

use super::{Objective, OutputCorrection};

/// A domain prior on physical parameters (e.g. the paper's penalty on server temperature
/// rises outside a plausible range).
pub trait Regularizer: Sync {
    /// Value and gradient with respect to physical parameters.
    fn value_and_gradient(&self, params: &[f64]) -> (f64, Vec<f64>);

    /// The value alone, equal to `value_and_gradient(params).0`; override it when the
    /// gradient costs much more (searchers ask for values far more often).
    fn value(&self, params: &[f64]) -> f64 {
        self.value_and_gradient(params).0
    }
}

/// Mean squared error of the surrogate against every measured value of every snapshot,
/// plus `weight * regularizer`, as a function of unit-box coordinates. A point where the
/// surrogate predicts another number of values than there are outputs (or gives a
/// gradient of another length than the parameters) costs NaN: a bad point, as a NaN
/// prediction makes it.
pub struct SurrogateObjective<'a, Su: Surrogate> {
    surrogate: &'a Su,
    observations: &'a Observations<Su::Scenario>,
    space: &'a ParamSpace,
    regularizer: Option<(&'a dyn Regularizer, f64)>,
    measured_count: f64,
    /// Added to the surrogate's prediction per snapshot and output (output correction).
    correction: Option<OutputCorrection>,
}

impl<'a, Su: Surrogate> SurrogateObjective<'a, Su> {
    /// The data term only.
    pub fn new(
        surrogate: &'a Su,
        observations: &'a Observations<Su::Scenario>,
        space: &'a ParamSpace,
    ) -> Self {
        let measured_count = observations.measured_count().max(1) as f64;
        SurrogateObjective {
            surrogate,
            observations,
            space,
            regularizer: None,
            measured_count,
            correction: None,
        }
    }

    /// Adds a fixed offset per snapshot and output to every prediction: with the model's
    /// outputs minus the surrogate's at the best run so far, the corrected surrogate
    /// matches the model there exactly (zero-order consistency, as in trust-region model
    /// management), and the search follows the surrogate's slopes from the model's answer.
    pub fn with_offsets(self, offsets: Vec<Vec<f64>>) -> Self {
        self.with_correction(OutputCorrection::constant(offsets))
    }

    /// Adds a correction (constant or with a linear term) to every prediction.
    pub fn with_correction(mut self, correction: OutputCorrection) -> Self {
        self.correction = Some(correction);
        self
    }

    /// Projections of the point on the correction's explored directions.
    fn projections(&self, x_unit: &[f64]) -> Vec<f64> {
        self.correction
            .as_ref()
            .map_or_else(Vec::new, |c| c.projections(x_unit))
    }

    fn offset(&self, snapshot: usize, output: usize, projections: &[f64]) -> f64 {
        self.correction
            .as_ref()
            .map_or(0.0, |c| c.value_at(snapshot, output, projections))
    }

    /// Adds `weight * regularizer(params)`.
    pub fn with_regularizer(mut self, regularizer: &'a dyn Regularizer, weight: f64) -> Self {
        self.regularizer = Some((regularizer, weight));
        self
    }

    /// The data term (mean squared error) alone, at physical parameters.
    pub fn data_mse(&self, params: &[f64]) -> f64 {
        let proj = match (&self.correction, self.space.to_unit(params)) {
            (Some(_), Ok(u)) => self.projections(&u),
            (Some(_), Err(_)) => return f64::NAN,
            (None, _) => Vec::new(),
        };
        self.data_mse_at(params, &proj)
    }

    fn data_mse_at(&self, params: &[f64], proj: &[f64]) -> f64 {
        let mut sum = 0.0;
        for (s, snap) in self.observations.snapshots().iter().enumerate() {
            let pred = self.surrogate.predict(&snap.scenario, params);
            // A zip would drop the outputs a short prediction lacks and score the point
            // a perfect fit: another length is a bad point, as a NaN is.
            if pred.len() != snap.measured.len() {
                return f64::NAN;
            }
            for (k, (p, m)) in pred.iter().zip(&snap.measured).enumerate() {
                if let Some(m) = m {
                    let r = p + self.offset(s, k, proj) - m;
                    sum += r * r;
                }
            }
        }
        sum / self.measured_count
    }
}

impl<Su: Surrogate> Objective for SurrogateObjective<'_, Su>
where
    Su: Sync,
    Su::Scenario: Sync,
{
    fn dim(&self) -> usize {
        self.space.dim()
    }

    fn cost(&self, x_unit: &[f64]) -> f64 {
        let params = match self.space.from_unit(x_unit) {
            Ok(p) => p,
            Err(_) => return f64::INFINITY,
        };
        let mut cost = self.data_mse_at(&params, &self.projections(x_unit));
        if let Some((reg, w)) = self.regularizer {
            cost += w * reg.value(&params);
        }
        cost
    }

    fn cost_and_gradient(&self, x_unit: &[f64]) -> (f64, Vec<f64>) {
        let params = match self.space.from_unit(x_unit) {
            Ok(p) => p,
            Err(_) => return (f64::INFINITY, vec![0.0; x_unit.len()]),
        };
        let proj = self.projections(x_unit);
        let bad = (f64::NAN, vec![f64::NAN; x_unit.len()]);
        let mut cost = 0.0;
        let mut grad_phys = vec![0.0; params.len()];
        let mut grad_correction = vec![0.0; x_unit.len()];
        for (s, snap) in self.observations.snapshots().iter().enumerate() {
            let pred = self.surrogate.predict(&snap.scenario, &params);
            // As in `data_mse_at`: a prediction of another length is a bad point.
            if pred.len() != snap.measured.len() {
                return bad;
            }
            let mut cotangent = vec![0.0; pred.len()];
            for (k, ((c, p), m)) in cotangent
                .iter_mut()
                .zip(&pred)
                .zip(&snap.measured)
                .enumerate()
            {
                if let Some(m) = m {
                    let r = p + self.offset(s, k, &proj) - m;
                    cost += r * r;
                    *c = 2.0 * r / self.measured_count;
                }
            }
            if let Some(corr) = &self.correction {
                corr.add_vjp(s, &cotangent, &mut grad_correction);
            }
            let g = self.surrogate.vjp(&snap.scenario, &params, &cotangent);
            if g.len() != params.len() {
                return bad;
            }
            for (acc, gi) in grad_phys.iter_mut().zip(g) {
                *acc += gi;
            }
        }
        cost /= self.measured_count;
        if let Some((reg, w)) = self.regularizer {
            let (v, g) = reg.value_and_gradient(&params);
            cost += w * v;
            for (acc, gi) in grad_phys.iter_mut().zip(g) {
                *acc += w * gi;
            }
        }
        let scale = self.space.dphys_dunit_at_physical(&params);
        let grad_unit = grad_phys
            .iter()
            .zip(scale)
            .zip(&grad_correction)
            .map(|((g, s), gc)| g * s + gc)
            .collect();
        (cost, grad_unit)
    }
}
