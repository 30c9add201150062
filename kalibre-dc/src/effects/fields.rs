//! Reading an `effects` entry's fields with errors that name the field.

use kalibre_core::{Param, Scale};
use serde_json::{Map, Value};

use crate::hall::EffectSpec;
use crate::{Error, Result};

/// The fields of one `effects` entry, read once each; [`Fields::finish`] rejects any
/// field that was not read (a typo must not vanish).
#[derive(Debug)]
pub struct Fields<'a> {
    kind: &'a str,
    map: &'a Map<String, Value>,
    used: Vec<String>,
}

impl<'a> Fields<'a> {
    /// Starts reading an entry.
    pub fn new(spec: &'a EffectSpec) -> Self {
        Fields {
            kind: &spec.kind,
            map: &spec.fields,
            used: Vec::new(),
        }
    }

    /// Refuses, before any field is read, a field that is none of `fields` nor a
    /// parameter of `params` (its value or its `_bounds`) nor the free-form `extra`: a
    /// typo is named first, not a required field that the reading then misses.
    pub fn expecting(self, fields: &[&str], params: &[&str]) -> Result<Self> {
        let known: Vec<String> = (fields.iter().map(|f| f.to_string()))
            .chain(
                params
                    .iter()
                    .flat_map(|p| [p.to_string(), format!("{p}_bounds")]),
            )
            .collect();
        match self.first_unknown(|k| known.iter().any(|f| f == k)) {
            None => Ok(self),
            Some(k) => Err(self.error(k, format!("unknown field (known: {})", known.join(", ")))),
        }
    }

    /// The first field, in name order, that `known` does not take, leaving out the
    /// free-form `extra` (which every object of the format may carry, an entry too).
    fn first_unknown(&self, known: impl Fn(&str) -> bool) -> Option<&'a String> {
        (self.map.keys())
            .filter(|k| *k != "extra" && !known(k))
            .min()
    }

    /// An error about `field`.
    pub fn error(&self, field: &str, message: impl std::fmt::Display) -> Error {
        Error::Effect {
            kind: self.kind.to_string(),
            message: format!("field `{field}`: {message}"),
        }
    }

    fn take(&mut self, field: &str) -> Option<&'a Value> {
        self.used.push(field.to_string());
        self.map.get(field)
    }

    /// An optional string.
    pub fn opt_str(&mut self, field: &str) -> Result<Option<&'a str>> {
        match self.take(field) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(v) => Err(self.error(field, format!("expected a string, got {v}"))),
        }
    }

    /// A required string.
    pub fn str(&mut self, field: &str) -> Result<&'a str> {
        self.opt_str(field)?
            .ok_or_else(|| self.error(field, "missing (required)"))
    }

    /// An optional finite number.
    pub fn opt_f64(&mut self, field: &str) -> Result<Option<f64>> {
        match self.take(field) {
            None => Ok(None),
            Some(v) => match v.as_f64() {
                Some(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(self.error(field, format!("expected a finite number, got {v}"))),
            },
        }
    }

    /// An optional non-negative integer, also as a number with no fractional part (`0.0`:
    /// JSON has one number type, and some exporters write every number as a float).
    pub fn opt_usize(&mut self, field: &str) -> Result<Option<usize>> {
        match self.take(field) {
            None => Ok(None),
            Some(v) => {
                let whole = (v.as_u64())
                    .or_else(|| v.as_f64().and_then(crate::hall::whole_count).map(u64::from));
                match whole {
                    Some(x) => Ok(Some(x as usize)),
                    None => {
                        Err(self.error(field, format!("expected a non-negative integer, got {v}")))
                    }
                }
            }
        }
    }

    /// An optional array of exactly `N` finite numbers.
    pub fn opt_array<const N: usize>(&mut self, field: &str) -> Result<Option<[f64; N]>> {
        match self.take(field) {
            None => Ok(None),
            Some(Value::Array(a)) if a.len() == N => {
                let mut out = [0.0; N];
                for (o, v) in out.iter_mut().zip(a) {
                    *o = match v.as_f64() {
                        Some(x) if x.is_finite() => x,
                        _ => {
                            return Err(
                                self.error(field, format!("expected finite numbers, got {v}"))
                            )
                        }
                    };
                }
                Ok(Some(out))
            }
            Some(v) => Err(self.error(field, format!("expected an array of {N} numbers, got {v}"))),
        }
    }

    /// An optional array of strings.
    pub fn opt_str_list(&mut self, field: &str) -> Result<Option<Vec<&'a str>>> {
        match self.take(field) {
            None => Ok(None),
            Some(Value::Array(a)) => a
                .iter()
                .map(|v| {
                    v.as_str()
                        .ok_or_else(|| self.error(field, format!("expected strings, got {v}")))
                })
                .collect::<Result<Vec<_>>>()
                .map(Some),
            Some(v) => Err(self.error(field, format!("expected an array of strings, got {v}"))),
        }
    }

    /// A calibrated parameter: initial value from `name` (default `initial`), bounds from
    /// `name_bounds` (default `[lower, upper]`, which given bounds must lie within).
    pub fn param(&mut self, name: &str, lower: f64, upper: f64, initial: f64) -> Result<Param> {
        let bounds_field = format!("{name}_bounds");
        let [lo, hi] = self
            .opt_array::<2>(&bounds_field)?
            .unwrap_or([lower, upper]);
        if lo > hi || lo < lower || hi > upper {
            return Err(self.error(
                &bounds_field,
                format!(
                    "[{}, {}] must be ordered and within [{lower}, {upper}]",
                    crate::snapshots::number(lo),
                    crate::snapshots::number(hi)
                ),
            ));
        }
        let x = self.opt_f64(name)?.unwrap_or(initial.clamp(lo, hi));
        if x < lo || x > hi {
            return Err(self.error(
                name,
                format!("{} is outside [{lo}, {hi}]", crate::snapshots::number(x)),
            ));
        }
        Param::new(name, lo, hi, x, Scale::Linear).map_err(|e| self.error(name, e))
    }

    /// Rejects fields that were not read (but the free-form `extra`).
    pub fn finish(self) -> Result<()> {
        match self.first_unknown(|k| self.used.iter().any(|f| f == k)) {
            None => Ok(()),
            Some(k) => Err(Error::Effect {
                kind: self.kind.to_string(),
                message: format!(
                    "field `{k}`: unknown field (known: {})",
                    self.used.join(", ")
                ),
            }),
        }
    }
}

/// Splits a message of [`Fields::error`] into the field it names and the rest.
pub(crate) fn split_field(message: &str) -> (Option<&str>, &str) {
    message
        .strip_prefix("field `")
        .and_then(|m| m.split_once("`: "))
        .map_or((None, message), |(f, rest)| (Some(f), rest))
}

/// `no rack `A3` in the hall (its racks: A01, A02, ...)`: an id the hall lacks, with
/// the ones it has ([`kalibre_core::some_names`]), so that a misspelling shows.
pub(crate) fn unknown_id<'a>(what: &str, id: &str, known: impl Iterator<Item = &'a str>) -> String {
    let known: Vec<String> = known.map(str::to_string).collect();
    format!(
        "no {what} `{id}` in the hall (its {what}s: {})",
        kalibre_core::some_names(&known)
    )
}

/// An `effects` entry from a kind and fields.
pub(crate) fn spec(kind: &str, fields: Vec<(&str, Value)>) -> EffectSpec {
    EffectSpec {
        kind: kind.to_string(),
        fields: fields
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
    }
}

/// The spec fields of a parameter: its initial value and, when not the default, its bounds.
pub(crate) fn param_fields(p: &Param, lower: f64, upper: f64) -> Vec<(String, Value)> {
    let mut out = vec![(p.name.clone(), Value::from(p.initial))];
    if p.lower != lower || p.upper != upper {
        out.push((
            format!("{}_bounds", p.name),
            Value::from(vec![p.lower, p.upper]),
        ));
    }
    out
}
