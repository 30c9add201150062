//! Named parameters with bounds and scales, and the normalised unit box searchers work in.
//!
//! A [`ParamSpace`] maps physical values (what a model sees) to and from the unit box
//! `[0, 1]^d` (what a searcher sees). Log-scaled parameters are uniform in `ln(value)`.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// How a parameter maps onto `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Scale {
    /// `u = (x - lower) / (upper - lower)`.
    #[default]
    Linear,
    /// `u = ln(x / lower) / ln(upper / lower)`; needs `0 < lower`.
    Log,
}

/// One calibrated parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Param {
    /// Unique name, e.g. `alpha/1u-compute`.
    pub name: String,
    /// Lower bound (physical units).
    pub lower: f64,
    /// Upper bound (physical units).
    pub upper: f64,
    /// Initial value (physical units), within the bounds.
    pub initial: f64,
    /// Mapping onto the unit box.
    pub scale: Scale,
}

impl Param {
    /// A checked parameter: finite bounds with `lower < upper` (or equal: a fixed value),
    /// `lower <= initial <= upper`, and `lower > 0` on a log scale.
    pub fn new(
        name: impl Into<String>,
        lower: f64,
        upper: f64,
        initial: f64,
        scale: Scale,
    ) -> Result<Self> {
        let name = name.into();
        let bad = |reason: String| Error::InvalidParam {
            name: name.clone(),
            reason,
        };
        if !(lower.is_finite() && upper.is_finite() && initial.is_finite()) {
            return Err(bad(format!(
                "bounds and initial value must be finite (lower {lower}, upper {upper}, initial {initial})"
            )));
        }
        if lower > upper {
            return Err(bad(format!(
                "inverted bounds: lower {lower} > upper {upper}"
            )));
        }
        if initial < lower || initial > upper {
            return Err(bad(format!(
                "initial value {initial} outside bounds [{lower}, {upper}]"
            )));
        }
        if scale == Scale::Log && lower <= 0.0 {
            return Err(bad(format!(
                "log scale needs a positive lower bound, got {lower}"
            )));
        }
        Ok(Param {
            name,
            lower,
            upper,
            initial,
            scale,
        })
    }

    /// Physical value to unit coordinate (clamped into `[0, 1]`).
    pub fn to_unit(&self, x: f64) -> f64 {
        if self.upper == self.lower {
            return 0.5;
        }
        let u = match self.scale {
            Scale::Linear => (x - self.lower) / (self.upper - self.lower),
            Scale::Log => (x / self.lower).ln() / (self.upper / self.lower).ln(),
        };
        u.clamp(0.0, 1.0)
    }

    /// Unit coordinate to physical value (the coordinate is clamped into `[0, 1]` first).
    pub fn from_unit(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let x = match self.scale {
            Scale::Linear => self.lower + u * (self.upper - self.lower),
            Scale::Log => self.lower * (u * (self.upper / self.lower).ln()).exp(),
        };
        // Rounding must never step outside the box.
        x.clamp(self.lower, self.upper)
    }

    /// `d x / d u` at unit coordinate `u`: the chain-rule factor from physical to unit gradients.
    pub fn dphys_dunit(&self, u: f64) -> f64 {
        match self.scale {
            Scale::Linear => self.upper - self.lower,
            Scale::Log => self.from_unit(u) * (self.upper / self.lower).ln(),
        }
    }
}

/// An ordered set of named parameters.
///
/// ```
/// use kalibre_core::{ParamSpace, Scale};
/// let space = ParamSpace::new()
///     .with("conductivity", 10.0, 400.0, 50.0, Scale::Log).unwrap()
///     .with("h", 1.0, 100.0, 10.0, Scale::Linear).unwrap();
/// let u = space.to_unit(&[50.0, 10.0]).unwrap();
/// let x = space.from_unit(&u).unwrap();
/// assert!((x[0] - 50.0).abs() < 1e-9 && (x[1] - 10.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParamSpace {
    params: Vec<Param>,
}

impl ParamSpace {
    /// An empty space.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a checked parameter (builder style).
    pub fn with(
        mut self,
        name: impl Into<String>,
        lower: f64,
        upper: f64,
        initial: f64,
        scale: Scale,
    ) -> Result<Self> {
        self.push(Param::new(name, lower, upper, initial, scale)?)?;
        Ok(self)
    }

    /// Adds a parameter; names must be unique.
    pub fn push(&mut self, param: Param) -> Result<()> {
        // Re-check: a `Param` may have been built by struct literal.
        let param = Param::new(
            param.name,
            param.lower,
            param.upper,
            param.initial,
            param.scale,
        )?;
        if self.params.iter().any(|p| p.name == param.name) {
            return Err(Error::InvalidParam {
                name: param.name,
                reason: "duplicate parameter name".into(),
            });
        }
        self.params.push(param);
        Ok(())
    }

    /// Number of parameters.
    pub fn dim(&self) -> usize {
        self.params.len()
    }

    /// True when there is no parameter.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// The parameters in order.
    pub fn params(&self) -> &[Param] {
        &self.params
    }

    /// Parameter names in order.
    pub fn names(&self) -> Vec<String> {
        self.params.iter().map(|p| p.name.clone()).collect()
    }

    /// Index of a parameter by name.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.params.iter().position(|p| p.name == name)
    }

    /// Initial physical values.
    pub fn initial(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.initial).collect()
    }

    fn check_len(&self, len: usize) -> Result<()> {
        if len != self.dim() {
            return Err(Error::Mismatch(format!(
                "expected {} parameter values, got {len}",
                self.dim()
            )));
        }
        Ok(())
    }

    /// Physical values to unit coordinates. Rejects NaN and wrong lengths.
    pub fn to_unit(&self, physical: &[f64]) -> Result<Vec<f64>> {
        self.check_len(physical.len())?;
        self.params
            .iter()
            .zip(physical)
            .map(|(p, &x)| {
                if x.is_finite() {
                    Ok(p.to_unit(x))
                } else {
                    Err(Error::InvalidParam {
                        name: p.name.clone(),
                        reason: format!("value {x} is not finite"),
                    })
                }
            })
            .collect()
    }

    /// Unit coordinates to physical values. Rejects NaN and wrong lengths.
    pub fn from_unit(&self, unit: &[f64]) -> Result<Vec<f64>> {
        self.check_len(unit.len())?;
        self.params
            .iter()
            .zip(unit)
            .map(|(p, &u)| {
                if u.is_finite() {
                    Ok(p.from_unit(u))
                } else {
                    Err(Error::InvalidParam {
                        name: p.name.clone(),
                        reason: format!("unit coordinate {u} is not finite"),
                    })
                }
            })
            .collect()
    }

    /// `d physical / d unit` per coordinate (the Jacobian of [`Self::from_unit`] is diagonal).
    pub fn dphys_dunit(&self, unit: &[f64]) -> Vec<f64> {
        self.params
            .iter()
            .zip(unit)
            .map(|(p, &u)| p.dphys_dunit(u))
            .collect()
    }

    /// Checks that physical values are finite and within bounds, naming the first offender.
    pub fn check_physical(&self, physical: &[f64]) -> Result<()> {
        self.check_len(physical.len())?;
        for (p, &x) in self.params.iter().zip(physical) {
            if !x.is_finite() || x < p.lower || x > p.upper {
                return Err(Error::InvalidParam {
                    name: p.name.clone(),
                    reason: format!("value {x} outside bounds [{}, {}]", p.lower, p.upper),
                });
            }
        }
        Ok(())
    }
}
