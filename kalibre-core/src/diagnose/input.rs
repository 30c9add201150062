//! What the diagnosis reads: the calibrated model's residuals with their Jacobian, and the
//! candidate hypotheses, all stacked over the same rows.

use std::collections::HashSet;

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::{Error, Observations, Result};

/// Which measured value a residual row is: an output under a snapshot.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RowInfo {
    /// Output name (sensor id).
    pub output: String,
    /// Output group (for a data hall: `cold` or `hot` aisle).
    pub group: String,
    /// Snapshot label.
    pub snapshot: String,
}

/// The rows of `obs` that were measured, snapshot by snapshot, outputs in order: the row
/// order that [`Residuals::from_observations`] and [`Hypothesis::from_snapshots`] use.
pub fn measured_rows<S>(obs: &Observations<S>) -> Vec<RowInfo> {
    let outputs = obs.outputs();
    obs.snapshots()
        .iter()
        .flat_map(|s| {
            s.measured
                .iter()
                .zip(outputs)
                .filter(|(m, _)| m.is_some())
                .map(|(_, o)| RowInfo {
                    output: o.name.clone(),
                    group: o.group.clone(),
                    snapshot: s.label.clone(),
                })
        })
        .collect()
}

/// Stacks per-snapshot blocks (`outputs x cols`) into the measured rows.
pub(crate) fn stack_blocks<S>(
    obs: &Observations<S>,
    blocks: &[Array2<f64>],
    what: &str,
) -> Result<Array2<f64>> {
    let snaps = obs.snapshots();
    if blocks.len() != snaps.len() {
        return Err(Error::Mismatch(format!(
            "{what}: {} blocks for {} snapshots",
            blocks.len(),
            snaps.len()
        )));
    }
    let cols = blocks.first().map_or(0, |b| b.ncols());
    let mut rows: Vec<f64> = Vec::new();
    let mut n = 0;
    for (s, b) in snaps.iter().zip(blocks) {
        if b.nrows() != s.measured.len() || b.ncols() != cols {
            return Err(Error::Mismatch(format!(
                "{what}, snapshot `{}`: block is {}x{}, expected {}x{cols}",
                s.label,
                b.nrows(),
                b.ncols(),
                s.measured.len()
            )));
        }
        for (k, m) in s.measured.iter().enumerate() {
            if m.is_some() {
                rows.extend(b.row(k).iter());
                n += 1;
            }
        }
    }
    Array2::from_shape_vec((n, cols), rows).map_err(|e| Error::Mismatch(format!("{what}: {e}")))
}

fn check_finite(what: &str, m: &Array2<f64>, rows: &[RowInfo], cols: &[String]) -> Result<()> {
    if let Some(((i, j), v)) = m.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(Error::Mismatch(format!(
            "{what}: entry for output `{}` in snapshot `{}`, parameter `{}` is {v}",
            rows[i].output, rows[i].snapshot, cols[j]
        )));
    }
    Ok(())
}

/// The calibrated model around its parameters: residuals (model minus measurement) of
/// every measured value, and their Jacobian with respect to the calibrated parameters.
#[derive(Debug, Clone)]
pub struct Residuals {
    rows: Vec<RowInfo>,
    residuals: Vec<f64>,
    jacobian: Array2<f64>,
    params: Vec<String>,
    uncertainty: Option<Vec<f64>>,
    model_form: Option<Vec<f64>>,
}

impl Residuals {
    /// Checked residuals: at least one row, one residual and one Jacobian row per row
    /// description, one Jacobian column per parameter name, unique (snapshot, output)
    /// rows and parameter names, every value finite.
    pub fn new(
        rows: Vec<RowInfo>,
        residuals: Vec<f64>,
        jacobian: Array2<f64>,
        params: Vec<String>,
    ) -> Result<Self> {
        if rows.is_empty() {
            return Err(Error::Mismatch(
                "diagnosis needs at least one residual".into(),
            ));
        }
        if residuals.len() != rows.len() {
            return Err(Error::Mismatch(format!(
                "{} residuals for {} row descriptions",
                residuals.len(),
                rows.len()
            )));
        }
        if jacobian.nrows() != rows.len() || jacobian.ncols() != params.len() {
            return Err(Error::Mismatch(format!(
                "Jacobian is {}x{}, expected {}x{} (residual rows x parameters)",
                jacobian.nrows(),
                jacobian.ncols(),
                rows.len(),
                params.len()
            )));
        }
        let mut seen = HashSet::new();
        if let Some(r) = rows.iter().find(|r| !seen.insert((&r.snapshot, &r.output))) {
            return Err(Error::Mismatch(format!(
                "output `{}` appears twice in snapshot `{}`",
                r.output, r.snapshot
            )));
        }
        let mut names = HashSet::new();
        if let Some(p) = params.iter().find(|p| !names.insert(p.as_str())) {
            return Err(Error::Mismatch(format!("parameter `{p}` appears twice")));
        }
        if let Some((i, v)) = residuals.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(Error::Mismatch(format!(
                "residual of output `{}` in snapshot `{}` is {v}",
                rows[i].output, rows[i].snapshot
            )));
        }
        check_finite("Jacobian", &jacobian, &rows, &params)?;
        Ok(Residuals {
            rows,
            residuals,
            jacobian,
            params,
            uncertainty: None,
            model_form: None,
        })
    }

    /// Stacks a calibrated model's outputs against the observations: `predicted[s]` holds
    /// every output of snapshot `s`, `jacobians[s]` is `outputs x parameters`; unmeasured
    /// values are skipped (rows as [`measured_rows`]).
    pub fn from_observations<S>(
        obs: &Observations<S>,
        predicted: &[Vec<f64>],
        jacobians: &[Array2<f64>],
        params: Vec<String>,
    ) -> Result<Self> {
        let snaps = obs.snapshots();
        if predicted.len() != snaps.len() {
            return Err(Error::Mismatch(format!(
                "{} predicted snapshots for {} observed",
                predicted.len(),
                snaps.len()
            )));
        }
        let mut residuals = Vec::new();
        for (s, p) in snaps.iter().zip(predicted) {
            if p.len() != s.measured.len() {
                return Err(Error::Mismatch(format!(
                    "snapshot `{}`: {} predicted outputs for {} observed",
                    s.label,
                    p.len(),
                    s.measured.len()
                )));
            }
            residuals.extend(
                s.measured
                    .iter()
                    .zip(p)
                    .filter_map(|(m, p)| m.map(|m| p - m)),
            );
        }
        let jacobian = if params.is_empty() {
            Array2::zeros((residuals.len(), 0))
        } else {
            stack_blocks(obs, jacobians, "Jacobian")?
        };
        Residuals::new(measured_rows(obs), residuals, jacobian, params)
    }

    /// Adds a known model uncertainty per row (standard deviation, output units), e.g.
    /// the model's own discretisation error from a refined grid. The diagnosis weighs
    /// each row by `1 / sqrt(sigma^2 + u^2)` instead of `1 / sigma`, so that no hypothesis
    /// earns credit for explaining what the model's numerics alone could produce.
    pub fn with_uncertainty(mut self, uncertainty: Vec<f64>) -> Result<Self> {
        self.check_uncertainty(&uncertainty, "uncertainty")?;
        self.uncertainty = Some(uncertainty);
        Ok(self)
    }

    /// Adds a model-form uncertainty per row (standard deviation, output units): what
    /// other plausible physics would read differently. It weighs rows as
    /// [`Self::with_uncertainty`] does (the two add in quadrature), by the share of its
    /// variance the residuals bear out (`Diagnosis::model_form_share`: none where the
    /// model reproduces the data); an output it
    /// covers is still listed among those no hypothesis explains when it is far off,
    /// since a user should look at it (`UnexplainedOutput::model_form_c` says how much
    /// the other physics moves it).
    pub fn with_model_form(mut self, uncertainty: Vec<f64>) -> Result<Self> {
        self.check_uncertainty(&uncertainty, "model-form uncertainty")?;
        self.model_form = Some(uncertainty);
        Ok(self)
    }

    fn check_uncertainty(&self, uncertainty: &[f64], what: &str) -> Result<()> {
        if uncertainty.len() != self.rows.len() {
            return Err(Error::Mismatch(format!(
                "{} {what} values for {} residual rows",
                uncertainty.len(),
                self.rows.len()
            )));
        }
        if let Some((i, u)) = uncertainty
            .iter()
            .enumerate()
            .find(|(_, u)| !(u.is_finite() && **u >= 0.0))
        {
            return Err(Error::Mismatch(format!(
                "{what} of output `{}` in snapshot `{}` is {u}, expected finite and >= 0",
                self.rows[i].output, self.rows[i].snapshot
            )));
        }
        Ok(())
    }

    /// The per-row model-form uncertainty, when given.
    pub fn model_form(&self) -> Option<&[f64]> {
        self.model_form.as_deref()
    }

    /// The per-row model uncertainty, when given.
    pub fn uncertainty(&self) -> Option<&[f64]> {
        self.uncertainty.as_deref()
    }

    /// Row descriptions.
    pub fn rows(&self) -> &[RowInfo] {
        &self.rows
    }

    /// Residuals, model minus measurement.
    pub fn residuals(&self) -> &[f64] {
        &self.residuals
    }

    /// Jacobian, rows x calibrated parameters.
    pub fn jacobian(&self) -> &Array2<f64> {
        &self.jacobian
    }

    /// Calibrated parameter names.
    pub fn params(&self) -> &[String] {
        &self.params
    }
}

/// A parameter the model does not have yet, linearised at 0 (the effect absent).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HypothesisParam {
    /// Name (for a data hall: `<effect kind>/<parameter>`).
    pub name: String,
    /// Lower end of its plausible range (offset from the linearisation point).
    pub lower: f64,
    /// Upper end of its plausible range.
    pub upper: f64,
}

impl HypothesisParam {
    /// A parameter with a plausible range `[lower, upper]`.
    pub fn bounded(name: impl Into<String>, lower: f64, upper: f64) -> Self {
        HypothesisParam {
            name: name.into(),
            lower,
            upper,
        }
    }

    /// A parameter with a symmetric prior scale: the range `[-scale, scale]`.
    pub fn with_scale(name: impl Into<String>, scale: f64) -> Self {
        Self::bounded(name, -scale, scale)
    }

    /// The larger magnitude of its bounds: how far it can move from 0.
    pub fn reach(&self) -> f64 {
        self.lower.abs().max(self.upper.abs())
    }
}

/// A candidate explanation: parameters the model lacks and how the outputs respond to
/// them (a Jacobian block over the same rows as the [`Residuals`]).
#[derive(Debug, Clone)]
pub struct Hypothesis {
    /// Unique name (for a data hall: the effect and its placement).
    pub name: String,
    /// Its parameters.
    pub params: Vec<HypothesisParam>,
    /// Rows x its parameters.
    pub jacobian: Array2<f64>,
    /// The model's own runs contradict the linearisation (a caller that ran the model
    /// towards the fit found no point better than the current parameters): never
    /// significant, whatever its columns predict.
    pub refuted: bool,
}

impl Hypothesis {
    /// A hypothesis from its stacked Jacobian block (checked by the diagnosis).
    pub fn new(
        name: impl Into<String>,
        params: Vec<HypothesisParam>,
        jacobian: Array2<f64>,
    ) -> Self {
        Hypothesis {
            name: name.into(),
            params,
            jacobian,
            refuted: false,
        }
    }

    /// A hypothesis from per-snapshot blocks (`outputs x parameters`), stacked into the
    /// measured rows of `obs` (as [`measured_rows`]).
    pub fn from_snapshots<S>(
        name: impl Into<String>,
        params: Vec<HypothesisParam>,
        obs: &Observations<S>,
        blocks: &[Array2<f64>],
    ) -> Result<Self> {
        let name = name.into();
        let jacobian = stack_blocks(obs, blocks, &format!("hypothesis `{name}`"))?;
        Ok(Hypothesis::new(name, params, jacobian))
    }

    /// Checks the block against the residual rows, the parameters' names and ranges.
    pub(crate) fn check(&self, res: &Residuals) -> Result<()> {
        let what = format!("hypothesis `{}`", self.name);
        if self.params.is_empty() {
            return Err(Error::Mismatch(format!("{what} has no parameter")));
        }
        if self.jacobian.nrows() != res.rows.len() || self.jacobian.ncols() != self.params.len() {
            return Err(Error::Mismatch(format!(
                "{what}: Jacobian is {}x{}, expected {}x{} (residual rows x its parameters)",
                self.jacobian.nrows(),
                self.jacobian.ncols(),
                res.rows.len(),
                self.params.len()
            )));
        }
        for (j, p) in self.params.iter().enumerate() {
            if !(p.lower.is_finite() && p.upper.is_finite() && p.lower < p.upper) {
                return Err(Error::InvalidParam {
                    name: p.name.clone(),
                    reason: format!(
                        "{what}: range [{}, {}] must be finite and increasing",
                        p.lower, p.upper
                    ),
                });
            }
            if self.params[..j].iter().any(|o| o.name == p.name) {
                return Err(Error::Mismatch(format!(
                    "{what}: parameter `{}` appears twice",
                    p.name
                )));
            }
            if res.params.contains(&p.name) {
                return Err(Error::Mismatch(format!(
                    "{what}: parameter `{}` is already calibrated",
                    p.name
                )));
            }
        }
        let names: Vec<String> = self.params.iter().map(|p| p.name.clone()).collect();
        check_finite(&what, &self.jacobian, &res.rows, &names)
    }
}
