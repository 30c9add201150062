//! Named parameters with bounds and scales, and the normalised unit box searchers work in.
//!
//! A [`ParamSpace`] maps physical values (what a model sees) to and from the unit box
//! `[0, 1]^d` (what a searcher sees). Log-scaled parameters are uniform in `ln(value)`.

use serde::{Deserialize, Serialize};

use crate::{number, Error, Result};

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
    /// A checked parameter: a name that is not empty and holds no control character,
    /// finite bounds with `lower < upper` (or equal: a fixed value),
    /// `lower <= initial <= upper`, and `lower > 0` on a log scale.
    pub fn new(
        name: impl Into<String>,
        lower: f64,
        upper: f64,
        initial: f64,
        scale: Scale,
    ) -> Result<Self> {
        let name = name.into();
        // Names key journaled runs and are printed in every message and report. (Their
        // length is not capped: a derived name, `alpha/` and a server id, may run past
        // an id's limit.)
        if name.is_empty() {
            return Err(Error::InvalidParam {
                name: "(unnamed)".into(),
                reason: "the name is empty; expected a name".into(),
            });
        }
        if let Some(why) = crate::number::control_character(&name) {
            return Err(Error::InvalidParam {
                name: name.escape_debug().to_string(),
                reason: format!("the name {why}"),
            });
        }
        let bad = |reason: String| Error::InvalidParam {
            name: name.clone(),
            reason,
        };
        if !(lower.is_finite() && upper.is_finite() && initial.is_finite()) {
            return Err(bad(format!(
                "bounds and initial value must be finite (lower {}, upper {}, initial {})",
                number(lower),
                number(upper),
                number(initial)
            )));
        }
        // The search and the fits work in these units: a bound near f64::MAX overflows
        // them into NaN later, where nothing names the parameter.
        if let Some((what, v)) = [("lower", lower), ("upper", upper), ("initial", initial)]
            .into_iter()
            .find(|(_, v)| !crate::within_magnitude(*v))
        {
            return Err(bad(format!(
                "{what} {} is beyond +/-{}, more than the fit can square",
                number(v),
                number(crate::MAX_MAGNITUDE)
            )));
        }
        if lower > upper {
            return Err(bad(format!(
                "inverted bounds: lower {} > upper {}",
                number(lower),
                number(upper)
            )));
        }
        if initial < lower || initial > upper {
            return Err(bad(format!(
                "initial value {} outside bounds [{}, {}]",
                number(initial),
                number(lower),
                number(upper)
            )));
        }
        if scale == Scale::Log && lower <= 0.0 {
            return Err(bad(format!(
                "log scale needs a positive lower bound, got {}",
                number(lower)
            )));
        }
        // The unit box maps through the span: one that overflows maps every point to NaN.
        let span = match scale {
            Scale::Linear => upper - lower,
            Scale::Log => (upper / lower).ln(),
        };
        if !span.is_finite() {
            return Err(bad(format!(
                "the bounds [{}, {}] span more than a float can hold",
                number(lower),
                number(upper)
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

    /// Equal bounds: the value is given, not calibrated.
    pub fn is_fixed(&self) -> bool {
        self.upper == self.lower
    }

    /// Physical value to unit coordinate (clamped into `[0, 1]`).
    pub fn to_unit(&self, x: f64) -> f64 {
        if self.is_fixed() {
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
        self.physical_at(u, self.log_span())
    }

    /// `d x / d u` at unit coordinate `u`: the chain-rule factor from physical to unit gradients.
    pub fn dphys_dunit(&self, u: f64) -> f64 {
        self.dphys_dunit_at(u, self.log_span())
    }

    /// `ln(upper / lower)` on a log scale (0 on a linear one).
    fn log_span(&self) -> f64 {
        match self.scale {
            Scale::Linear => 0.0,
            Scale::Log => (self.upper / self.lower).ln(),
        }
    }

    /// [`Self::from_unit`] with [`Self::log_span`] given (a [`ParamSpace`] keeps them, so
    /// that mapping thousands of parameters does not take a logarithm for each).
    fn physical_at(&self, u: f64, log_span: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let x = match self.scale {
            Scale::Linear => self.lower + u * (self.upper - self.lower),
            Scale::Log => self.lower * (u * log_span).exp(),
        };
        // Rounding must never step outside the box (max/min, not clamp: a parameter
        // written as a struct literal with inverted bounds must not panic here).
        x.max(self.lower).min(self.upper)
    }

    fn dphys_dunit_at(&self, u: f64, log_span: f64) -> f64 {
        match self.scale {
            Scale::Linear => self.upper - self.lower,
            Scale::Log => self.physical_at(u, log_span) * log_span,
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
#[serde(try_from = "ParamList", into = "ParamList")]
pub struct ParamSpace {
    params: Vec<Param>,
    /// `ln(upper / lower)` per parameter (0 on a linear scale), kept with the parameters.
    log_span: Vec<f64>,
}

/// The serialised form of a [`ParamSpace`]: its parameters, checked again on reading.
#[derive(Serialize, Deserialize)]
struct ParamList {
    params: Vec<Param>,
}

impl TryFrom<ParamList> for ParamSpace {
    type Error = Error;
    fn try_from(list: ParamList) -> Result<Self> {
        let mut space = ParamSpace::new();
        for p in list.params {
            space.push(p)?;
        }
        Ok(space)
    }
}

impl From<ParamSpace> for ParamList {
    fn from(space: ParamSpace) -> Self {
        ParamList {
            params: space.params,
        }
    }
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
        self.log_span.push(param.log_span());
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
        // One branch-free scan first: searchers call this for every candidate.
        let all_finite = unit.iter().fold(true, |ok, u| ok & u.is_finite());
        if let Some((p, u)) = (!all_finite)
            .then(|| self.params.iter().zip(unit).find(|(_, u)| !u.is_finite()))
            .flatten()
        {
            return Err(Error::InvalidParam {
                name: p.name.clone(),
                reason: format!("unit coordinate {u} is not finite"),
            });
        }
        Ok(self
            .params
            .iter()
            .zip(&self.log_span)
            .zip(unit)
            .map(|((p, &span), &u)| p.physical_at(u, span))
            .collect())
    }

    /// `d physical / d unit` per coordinate (the Jacobian of [`Self::from_unit`] is
    /// diagonal), for the first `unit.len()` parameters: unlike `from_unit` it does not
    /// check the length (the loop calls it on points `from_unit` accepted), so give it
    /// one value per parameter.
    pub fn dphys_dunit(&self, unit: &[f64]) -> Vec<f64> {
        self.params
            .iter()
            .zip(&self.log_span)
            .zip(unit)
            .map(|((p, &span), &u)| p.dphys_dunit_at(u, span))
            .collect()
    }

    /// [`Self::dphys_dunit`] from the physical values `from_unit` gave for those unit
    /// coordinates, without taking the exponentials again (bit-identical to it).
    pub fn dphys_dunit_at_physical(&self, physical: &[f64]) -> Vec<f64> {
        self.params
            .iter()
            .zip(&self.log_span)
            .zip(physical)
            .map(|((p, &span), &x)| match p.scale {
                Scale::Linear => p.upper - p.lower,
                Scale::Log => x * span,
            })
            .collect()
    }

    /// Checks that physical values are finite and within bounds, naming the first offender.
    pub fn check_physical(&self, physical: &[f64]) -> Result<()> {
        self.check_len(physical.len())?;
        for (p, &x) in self.params.iter().zip(physical) {
            if x.is_finite() && p.lower == p.upper && x != p.lower {
                // "outside bounds [0, 0]" reads as a typo; equal bounds are a choice.
                return Err(Error::InvalidParam {
                    name: p.name.clone(),
                    reason: format!(
                        "value {}, but this model holds it at {} (equal bounds: a fixed \
                         parameter, or a candidate effect held absent; the values are of a \
                         model that has it free)",
                        number(x),
                        number(p.lower)
                    ),
                });
            }
            if !x.is_finite() || x < p.lower || x > p.upper {
                return Err(Error::InvalidParam {
                    name: p.name.clone(),
                    reason: format!(
                        "value {} outside bounds [{}, {}]",
                        number(x),
                        number(p.lower),
                        number(p.upper)
                    ),
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A name keys journaled runs and is printed: an empty one, or one with a control
    /// character, is refused (a long one is not: `alpha/` and a server id may be long).
    #[test]
    fn parameter_names_must_be_printable_and_not_empty() {
        let e = ParamSpace::new()
            .with("", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap_err();
        assert!(
            matches!(&e, Error::InvalidParam { name, reason }
                if name == "(unnamed)" && reason.contains("empty")),
            "{e}"
        );
        let e = ParamSpace::new()
            .with("k\u{7}", 0.0, 1.0, 0.5, Scale::Linear)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`k\\u{7}`") && e.contains("U+0007"), "{e}");
        let mut space = ParamSpace::new();
        let literal = Param {
            name: String::new(),
            lower: 0.0,
            upper: 1.0,
            initial: 0.5,
            scale: Scale::Linear,
        };
        assert!(
            space.push(literal).is_err(),
            "a struct literal is checked too"
        );
        let long = format!("alpha/{}", "s".repeat(200));
        ParamSpace::new()
            .with(long, 0.0, 1.0, 0.5, Scale::Linear)
            .expect("a long derived name");
    }

    #[test]
    fn a_value_off_a_held_parameter_says_it_is_held() {
        let s = ParamSpace::new()
            .with("loss", 0.0, 0.0, 0.0, Scale::Linear)
            .unwrap();
        let e = s.check_physical(&[2.0]).unwrap_err().to_string();
        assert!(e.contains("this model holds it at 0 (equal bounds"), "{e}");
        assert!(s.check_physical(&[0.0]).is_ok());
    }

    fn space() -> ParamSpace {
        ParamSpace::new()
            .with("alpha", 0.01, 3.0, 0.1, Scale::Log)
            .unwrap()
            .with("h", -2.0, 5.0, 1.0, Scale::Linear)
            .unwrap()
    }

    #[test]
    fn bounds_beyond_what_a_fit_can_square_are_refused_by_name() {
        for (lower, upper, initial) in [(1.0, 1e308, 2.0), (-1e200, 1.0, 0.0)] {
            let e = Param::new("k", lower, upper, initial, Scale::Linear)
                .unwrap_err()
                .to_string();
            assert!(e.contains("parameter `k`"), "{e}");
            assert!(e.contains("beyond +/-1e150"), "{e}");
        }
        assert!(Param::new("k", -1e150, 1e150, 0.0, Scale::Linear).is_ok());
    }

    #[test]
    fn the_space_maps_as_each_parameter_does_bit_for_bit() {
        let s = space();
        for i in 0..=64 {
            let u = [i as f64 / 64.0, 1.0 - i as f64 / 64.0];
            let x = s.from_unit(&u).unwrap();
            let d = s.dphys_dunit(&u);
            let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&d), bits(&s.dphys_dunit_at_physical(&x)));
            for k in 0..2 {
                let p = &s.params()[k];
                assert_eq!(x[k].to_bits(), p.from_unit(u[k]).to_bits());
                assert_eq!(d[k].to_bits(), p.dphys_dunit(u[k]).to_bits());
            }
        }
    }

    #[test]
    fn bounds_whose_span_overflows_are_refused() {
        // Within the magnitude limit, a log span can still overflow (1e150 over 2e-308).
        let e = Param::new("x", f64::MIN_POSITIVE, 1e150, 1.0, Scale::Log).unwrap_err();
        assert!(e.to_string().contains("span more than a float"), "{e}");
        // Beyond it, the limit refuses them first.
        let e = Param::new("x", -1e308, 1e308, 0.0, Scale::Linear).unwrap_err();
        assert!(e.to_string().contains("beyond +/-1e150"), "{e}");
        Param::new("x", -1e150, 1e150, 0.0, Scale::Linear).expect("a span that fits");
        Param::new("x", 1e-150, 1e150, 1.0, Scale::Log).expect("a log span that fits");
    }

    #[test]
    fn a_space_read_from_json_is_checked_and_keeps_its_spans() {
        let s = space();
        let json = serde_json::to_string(&s).unwrap();
        assert!(json.starts_with(r#"{"params":[{"name":"alpha""#), "{json}");
        let back: ParamSpace = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
        assert_eq!(
            back.from_unit(&[0.3, 0.3]).unwrap(),
            s.from_unit(&[0.3, 0.3]).unwrap()
        );

        let inverted = json.replace(r#""lower":0.01,"upper":3.0"#, r#""lower":3.0,"upper":0.01"#);
        assert_ne!(inverted, json);
        let err = serde_json::from_str::<ParamSpace>(&inverted)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("alpha") && err.contains("inverted bounds"),
            "{err}"
        );

        let duplicate = json.replace(r#""name":"h""#, r#""name":"alpha""#);
        let err = serde_json::from_str::<ParamSpace>(&duplicate)
            .unwrap_err()
            .to_string();
        assert!(err.contains("duplicate parameter name"), "{err}");
    }
}
