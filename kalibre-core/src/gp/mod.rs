//! A general-purpose surrogate: a Gaussian process per scenario over the unit box, on an
//! affine trend, with hyperparameters pooled over every scenario and output.
//!
//! For a slow model with few parameters, a handful of outputs and a few scenarios (an
//! external command, say), it saves writing a surrogate: it interpolates the runs,
//! extrapolates along their linear trend, and gives exact gradients.

mod hyper;
mod prepare;

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::{number, Error, FitSummary, ParamSpace, Result, Sample, Scale, Surrogate, TrainingSet};
use hyper::Group;
use prepare::{finish, prepare, Prepared};

/// Ridge on the trend's slopes, relative to the samples' total weight: it makes the fit
/// well-posed with fewer samples than dimensions (then the minimum-norm slopes) while
/// leaving a well-determined trend as least squares gives it.
const TREND_RIDGE_REL: f64 = 1e-6;
/// Samples whose weight is below this fraction of their scenario's largest are left out:
/// their nugget would be 1e12 times the others'.
const MIN_RELATIVE_WEIGHT: f64 = 1e-12;
/// Trend residuals below this RMS (standardised units) are rounding: such an output is
/// affine, and its near-zero residuals would only pull the hyperparameters towards a
/// singular kernel.
const AFFINE_RMS: f64 = 1e-6;

/// A Gaussian-process surrogate for any model whose scenarios compare with `==`.
///
/// Per scenario (the samples grouped by [`Sample::snapshot`]; scenarios that compare
/// equal share one model) and output:
///
/// - inputs are the parameters in the unit box ([`ParamSpace::to_unit`], so log-scaled
///   parameters are uniform in their logarithm); fixed parameters (equal bounds) carry no
///   information and are left out of the kernel;
/// - outputs are standardised (mean and standard deviation over the scenario's samples;
///   a constant output gets 1);
/// - the mean is an affine trend in the unit inputs, fitted by ridge least squares, so
///   that the surrogate extrapolates linearly rather than back to a constant;
/// - a Gaussian process with a squared-exponential kernel, one length scale per input
///   (ARD), and a nugget models the trend's residuals. Its prediction is the posterior
///   mean, so that it interpolates the runs up to the nugget.
///
/// The length scales and the nugget are shared by every scenario and output (there are
/// few runs, so their evidence is pooled): they maximise the sum over scenarios and
/// outputs of the profile log marginal likelihood, each output's signal variance at its
/// closed-form optimum. The search is a fixed grid (see [`Hyperparameters`]): the fit
/// uses no random numbers, so `seed` is unused and the same data give the same surrogate,
/// bit for bit, at any thread count (no threads run inside).
///
/// Sample weights are ignored by default: every sample counts alike. The loop's only
/// source of weights, `Settings::focus`, all but removes the runs far from the
/// measurements, and a process that forgets them extrapolates from the runs near the
/// best alone: on `tests/gp.rs`'s three-parameter model, the plain loop
/// (`Settings::default()`) with a focus of 1 and the weights counting ended at 3.5e-3 to
/// 1.2e-1 MAE over three seeds, against 4e-7 to 8e-6 ignoring them
/// (`Settings::recommended()` reached 1e-8 either way). [`Self::with_weights`] makes
/// them count.
///
/// A scenario without a sample at the last fit (one not in the training set, or whose
/// runs all failed) has no model: `predict` and `vjp` return NaN for it, which the
/// calibration loop reports as an error naming the snapshot, rather than a prediction
/// borrowed from another scenario. So do parameter values of the wrong length or not
/// finite, and an unfitted surrogate predicts no values.
///
/// The first fit of `Calibrator` trains on noisy copies of the design runs
/// (`Settings::augment_copies`) that keep the runs' outputs: to a Gaussian process they
/// are flat plateaus around each run, and they cost the fit (cubic in the samples). The
/// polish can hide what they cost (the recommended loop on the test model reached 7e-9
/// to 1.9e-8 MAE with the 16 copies, 1.6e-8 to 7.8e-7 with one), but without it they
/// cost the search: a library user's oscillator ended 4-10 times further from the data
/// with them. Start from `Settings::recommended_for_gaussian_process`, which has one.
///
/// ```
/// use kalibre_core::{GaussianProcess, ParamSpace, Sample, Scale, Surrogate, TrainingSet};
///
/// # fn main() -> kalibre_core::Result<()> {
/// let space = ParamSpace::new()
///     .with("k", 1.0, 10.0, 2.0, Scale::Log)?
///     .with("h", 0.0, 1.0, 0.5, Scale::Linear)?;
/// // Two scenarios (a load), two outputs each.
/// let f = |load: f64, p: &[f64]| vec![load / p[0] + p[1], (p[1] * load).sin()];
/// let loads = [1.0, 3.0];
/// let mut samples = Vec::new();
/// for (snapshot, &load) in loads.iter().enumerate() {
///     for i in 0..5 {
///         for j in 0..5 {
///             let p = space.from_unit(&[i as f64 / 4.0, j as f64 / 4.0])?;
///             let outputs = f(load, &p);
///             samples.push(Sample { snapshot, params: p, outputs, weight: 1.0 });
///         }
///     }
/// }
/// let mut gp = GaussianProcess::new(space.clone());
/// let fit = gp.fit(TrainingSet { scenarios: &loads, samples: &samples }, 0)?;
/// assert!(fit.train_mse < 1e-6); // the nugget smooths a little
///
/// let at = &samples[37]; // a training point of the second scenario
/// let predicted = gp.predict(&loads[1], &at.params);
/// for (p, y) in predicted.iter().zip(&at.outputs) {
///     assert!((p - y).abs() < 1e-3, "{p} vs {y}");
/// }
/// assert_eq!(gp.hyperparameters().unwrap().length_scales.len(), 2);
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct GaussianProcess<S> {
    space: ParamSpace,
    use_weights: bool,
    fitted: Option<Fitted<S>>,
}

/// The kernel's hyperparameters after a fit.
///
/// The search starts from a common length scale on a log grid (1/32 to 32 in the unit
/// box, factor 2) with each nugget, then searches each dimension's length scale in turn
/// (steps of a factor 2, then of sqrt 2, up to three rounds each) and the nugget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hyperparameters {
    /// Length scale of each parameter in the kernel, unit box (1 spans the bounds; 32,
    /// the grid's end, means the outputs hardly vary with it beyond their trend). Fixed
    /// parameters are not listed.
    pub length_scales: Vec<(String, f64)>,
    /// Noise variance over signal variance for a sample of weight 1 (one of 1e-8, 1e-6,
    /// 1e-4, 1e-2).
    pub nugget: f64,
    /// The pooled profile log marginal likelihood at these values; `None` when no output
    /// varied beyond its affine trend (the hyperparameters then are defaults, which hardly
    /// change a prediction: the process has next to nothing to model).
    pub log_evidence: Option<f64>,
}

#[derive(Debug, Clone)]
struct Fitted<S> {
    /// Indices of the parameters in the kernel (not fixed).
    active: Vec<usize>,
    /// Their length scales.
    lengths: Vec<f64>,
    outputs: usize,
    /// Distinct scenarios, each with its model (none without samples).
    scenarios: Vec<(S, Option<ScenarioModel>)>,
    hyper: Hyperparameters,
}

/// One scenario's fitted process.
#[derive(Debug, Clone)]
struct ScenarioModel {
    /// Training inputs divided by the length scales, row-major `n x d`.
    scaled: Vec<f64>,
    mean: Vec<f64>,
    std: Vec<f64>,
    /// Trend coefficients (standardised units), row-major `(d + 1) x m`: the value at the
    /// box's centre, then the slope per unit coordinate.
    trend: Vec<f64>,
    /// `K^-1 r`, row-major `n x m`.
    alpha: Vec<f64>,
}

impl<S> GaussianProcess<S> {
    /// An unfitted surrogate over `space`: [`Surrogate::fit`] trains it.
    pub fn new(space: ParamSpace) -> Self {
        GaussianProcess {
            space,
            use_weights: false,
            fitted: None,
        }
    }

    /// Makes the samples' weights count (`false`, the default, ignores them). A weight
    /// then inflates the sample's noise and weighs its trend residual: relative to the
    /// largest weight `w_max` of its scenario, its nugget is `nugget * w_max / weight`,
    /// so a run with a low weight is trusted less. A weight under 1e-12 of `w_max` (0,
    /// say) leaves the sample out; if every weight of a scenario is 0, its samples count
    /// alike. `train_mse` is then weighted too.
    pub fn with_weights(mut self, on: bool) -> Self {
        self.use_weights = on;
        self
    }

    /// The parameter space.
    pub fn space(&self) -> &ParamSpace {
        &self.space
    }

    /// The hyperparameters of the last successful fit (`None` before one).
    pub fn hyperparameters(&self) -> Option<&Hyperparameters> {
        self.fitted.as_ref().map(|f| &f.hyper)
    }
}

impl<S: Clone + PartialEq> GaussianProcess<S> {
    /// The fitted model of `scenario` and its unit inputs at `params` (kernel dims only).
    fn locate(
        &self,
        scenario: &S,
        params: &[f64],
    ) -> Option<(&Fitted<S>, &ScenarioModel, Vec<f64>)> {
        let fitted = self.fitted.as_ref()?;
        let (_, model) = fitted.scenarios.iter().find(|(s, _)| s == scenario)?;
        let unit = self.space.to_unit(params).ok()?;
        let z = fitted.active.iter().map(|&i| unit[i]).collect();
        Some((fitted, model.as_ref()?, z))
    }

    fn check(&self, data: &TrainingSet<'_, S>) -> Result<usize> {
        let bad = |i: usize, what: String| Err(Error::Fit(format!("sample {i}: {what}")));
        let first = data
            .samples
            .first()
            .ok_or_else(|| Error::Fit("no training samples".into()))?;
        let m = first.outputs.len();
        if m == 0 {
            return Err(Error::Fit("the samples have no outputs".into()));
        }
        for (i, s) in data.samples.iter().enumerate() {
            if s.snapshot >= data.scenarios.len() {
                return bad(
                    i,
                    format!(
                        "snapshot {} of {} scenarios",
                        s.snapshot,
                        data.scenarios.len()
                    ),
                );
            }
            if s.params.len() != self.space.dim() {
                return bad(
                    i,
                    format!(
                        "{} parameter values for {} parameters",
                        s.params.len(),
                        self.space.dim()
                    ),
                );
            }
            if s.outputs.len() != m {
                return bad(
                    i,
                    format!("{} outputs where sample 0 has {m}", s.outputs.len()),
                );
            }
            if let Some(k) = s.params.iter().position(|v| !v.is_finite()) {
                let name = &self.space.params()[k].name;
                return bad(
                    i,
                    format!("parameter `{name}` is {}, not finite", s.params[k]),
                );
            }
            if let Some(k) = s.outputs.iter().position(|v| !v.is_finite()) {
                return bad(i, format!("output {k} is {}, not finite", s.outputs[k]));
            }
            if !(s.weight.is_finite() && s.weight >= 0.0) {
                return bad(
                    i,
                    format!("weight {} is not finite and >= 0", number(s.weight)),
                );
            }
        }
        Ok(m)
    }

    fn fit_with(
        &mut self,
        data: TrainingSet<'_, S>,
        deadline: Option<Instant>,
    ) -> Result<FitSummary> {
        let m = self.check(&data)?;
        let active: Vec<usize> = (0..self.space.dim())
            .filter(|&i| !self.space.params()[i].is_fixed())
            .collect();
        let d = active.len();
        // Scenarios that compare equal are one model's: their runs pool.
        let first_equal: Vec<usize> = (0..data.scenarios.len())
            .map(|i| {
                (0..=i)
                    .find(|&j| data.scenarios[j] == data.scenarios[i])
                    .unwrap_or(i)
            })
            .collect();
        let mut prepared: Vec<(usize, Option<Prepared>)> = Vec::new();
        for s in (0..data.scenarios.len()).filter(|&s| first_equal[s] == s) {
            let members: Vec<&Sample> = (data.samples.iter())
                .filter(|x| first_equal[x.snapshot] == s)
                .collect();
            // Weights are relative: scaled by the scenario's largest, a sample far below
            // it (or at 0) carries nothing and would only overflow the nugget. When
            // every weight is 0, the samples count alike.
            let top = members.iter().map(|x| x.weight).fold(0.0, f64::max);
            let group: Vec<(&Sample, f64)> = if self.use_weights && top > 0.0 {
                (members.iter())
                    .map(|x| (*x, x.weight / top))
                    .filter(|(_, w)| *w >= MIN_RELATIVE_WEIGHT)
                    .collect()
            } else {
                members.iter().map(|x| (*x, 1.0)).collect()
            };
            let p = (!group.is_empty())
                .then(|| prepare(&self.space, &group, &active, m))
                .transpose()?;
            prepared.push((s, p));
        }

        let groups: Vec<Group<'_>> = (prepared.iter())
            .filter_map(|(_, p)| p.as_ref())
            .map(|p| {
                let k = p.informative.len();
                let residuals = (p.residuals.chunks_exact(m))
                    .flat_map(|row| p.informative.iter().map(move |&j| row[j]))
                    .collect();
                Group {
                    z: &p.z,
                    inv_weight: &p.inv_weight,
                    residuals,
                    m: k,
                }
            })
            .collect();
        let choice = hyper::choose(&groups, d, deadline);
        let lengths: Vec<f64> = choice.index.iter().map(|&i| hyper::length_at(i)).collect();
        let nugget = hyper::NUGGETS[choice.nugget];

        let mut scenarios = Vec::with_capacity(prepared.len());
        for (s, p) in prepared {
            let model = p.map(|p| finish(p, d, m, &lengths, nugget)).transpose()?;
            scenarios.push((data.scenarios[s].clone(), model));
        }
        let names = self.space.names();
        let hyper = Hyperparameters {
            length_scales: active
                .iter()
                .zip(&lengths)
                .map(|(&i, &l)| (names[i].clone(), l))
                .collect(),
            nugget,
            log_evidence: choice.evidence,
        };
        let fitted = Fitted {
            active,
            lengths,
            outputs: m,
            scenarios,
            hyper,
        };
        let previous = self.fitted.replace(fitted);

        // Weighted as the fit weighs the samples: a run it has all but left out would
        // otherwise dominate the figure.
        let all_zero = !self.use_weights || data.samples.iter().all(|s| s.weight == 0.0);
        let (mut se, mut total) = (0.0, 0.0);
        for s in data.samples {
            let w = if all_zero { 1.0 } else { s.weight };
            let pred = self.predict(&data.scenarios[s.snapshot], &s.params);
            for (p, y) in pred.iter().zip(&s.outputs) {
                if w > 0.0 {
                    se += w * (p - y) * (p - y);
                    total += w;
                }
            }
        }
        let train_mse = se / total;
        if !train_mse.is_finite() {
            // Only a model beyond the reach of f64 gets here; keep the previous one.
            self.fitted = previous;
            return Err(Error::Fit(format!("the training error is {train_mse}")));
        }
        Ok(FitSummary {
            train_mse,
            epochs: choice.evaluated,
            timed_out: choice.timed_out,
        })
    }
}

impl ScenarioModel {
    /// Kernel values between the unit point `z` (scaled as `zs`) and each training input.
    fn kernel_row(&self, zs: &[f64]) -> Vec<f64> {
        let d = zs.len();
        let n = self.alpha.len() / self.mean.len();
        (0..n)
            .map(|i| {
                let r2: f64 = (0..d)
                    .map(|l| (zs[l] - self.scaled[i * d + l]).powi(2))
                    .sum();
                (-0.5 * r2).exp()
            })
            .collect()
    }
}

impl<S: Clone + PartialEq> Surrogate for GaussianProcess<S> {
    type Scenario = S;

    /// Fits the trend and the process per scenario and chooses the shared
    /// hyperparameters. `train_mse` is the mean over samples and outputs (weighted with
    /// [`GaussianProcess::with_weights`]), `epochs` counts the hyperparameter candidates
    /// evaluated, and `seed` is unused (the fit is deterministic). On an error the
    /// previous fit stays.
    fn fit(&mut self, data: TrainingSet<'_, S>, seed: u64) -> Result<FitSummary> {
        self.fit_until(data, seed, None)
    }

    /// [`Self::fit`] whose hyperparameter search stops at `deadline` (checked before each
    /// candidate) with the best candidate so far.
    fn fit_until(
        &mut self,
        data: TrainingSet<'_, S>,
        _seed: u64,
        deadline: Option<Instant>,
    ) -> Result<FitSummary> {
        self.fit_with(data, deadline)
    }

    fn predict(&self, scenario: &S, params: &[f64]) -> Vec<f64> {
        let Some(fitted) = &self.fitted else {
            return Vec::new();
        };
        let Some((fitted, model, z)) = self.locate(scenario, params) else {
            return vec![f64::NAN; fitted.outputs];
        };
        let m = fitted.outputs;
        let zs: Vec<f64> = z.iter().zip(&fitted.lengths).map(|(u, l)| u / l).collect();
        let kr = model.kernel_row(&zs);
        (0..m)
            .map(|k| {
                let trend = model.trend[k]
                    + (0..z.len())
                        .map(|l| model.trend[(l + 1) * m + k] * (z[l] - 0.5))
                        .sum::<f64>();
                let gp: f64 = kr
                    .iter()
                    .enumerate()
                    .map(|(i, ki)| ki * model.alpha[i * m + k])
                    .sum();
                model.mean[k] + model.std[k] * (trend + gp)
            })
            .collect()
    }

    fn vjp(&self, scenario: &S, params: &[f64], cotangent: &[f64]) -> Vec<f64> {
        let nan = vec![f64::NAN; params.len()];
        let Some((fitted, model, z)) = self.locate(scenario, params) else {
            return nan;
        };
        let m = fitted.outputs;
        if cotangent.len() != m {
            return nan;
        }
        let d = z.len();
        // The cotangent on the standardised outputs, then on the process's weights.
        let h: Vec<f64> = cotangent
            .iter()
            .zip(&model.std)
            .map(|(g, s)| g * s)
            .collect();
        let zs: Vec<f64> = z.iter().zip(&fitted.lengths).map(|(u, l)| u / l).collect();
        let kr = model.kernel_row(&zs);
        let mut grad_unit: Vec<f64> = (0..d)
            .map(|l| (0..m).map(|k| model.trend[(l + 1) * m + k] * h[k]).sum())
            .collect();
        for (i, ki) in kr.iter().enumerate() {
            let c: f64 = (0..m).map(|k| model.alpha[i * m + k] * h[k]).sum::<f64>() * ki;
            for (l, g) in grad_unit.iter_mut().enumerate() {
                // d k / d z_l = -k (z_l - z_il) / len_l^2, with both scaled by len_l.
                *g -= c * (zs[l] - model.scaled[i * d + l]) / fitted.lengths[l];
            }
        }
        let mut grad = vec![0.0; params.len()];
        for (&i, g) in fitted.active.iter().zip(grad_unit) {
            grad[i] = g * dunit_dphys(&self.space.params()[i], params[i]);
        }
        grad
    }
}

/// `d u / d x` of [`crate::Param::to_unit`] at physical `x`: 0 outside the bounds, where
/// the unit coordinate is clamped.
fn dunit_dphys(p: &crate::Param, x: f64) -> f64 {
    if x < p.lower || x > p.upper || p.is_fixed() {
        return 0.0;
    }
    match p.scale {
        Scale::Linear => 1.0 / (p.upper - p.lower),
        Scale::Log => 1.0 / (x * (p.upper / p.lower).ln()),
    }
}
