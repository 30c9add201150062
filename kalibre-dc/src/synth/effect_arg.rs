//! Parsing `--effect KIND[:key=value,...]` into an `effects` entry.

use crate::hall::EffectSpec;
use crate::{Error, Result};

fn bad(arg: &str, message: impl Into<String>) -> Error {
    Error::Mismatch(format!("--effect `{arg}`: {}", message.into()))
}

/// Parses `KIND[:key=value,...]` (e.g. `bypass:fraction=0.1,behind_rack=A03`) into an
/// [`EffectSpec`]. Values that parse as finite numbers become JSON numbers, `true` and
/// `false` become booleans, `[a,b,...]` an array of such values (`z_m=[1.0,1.2]`,
/// `sides=[-x,+x]`), anything else a string. The kind is checked for its syntax
/// only (lower-case letters, digits, `_`); whether it is known is checked against the
/// hall when the effect is built.
pub fn parse_effect_arg(arg: &str) -> Result<EffectSpec> {
    let (kind, rest) = match arg.split_once(':') {
        Some((k, r)) => (k.trim(), Some(r)),
        None => (arg.trim(), None),
    };
    if kind.is_empty() {
        return Err(bad(arg, "missing effect kind before `:`"));
    }
    if !kind
        .chars()
        .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
    {
        return Err(bad(
            arg,
            format!("effect kind `{kind}` may contain only a-z, 0-9 and `_`"),
        ));
    }
    let mut fields = serde_json::Map::new();
    if let Some(rest) = rest {
        if rest.trim().is_empty() {
            return Err(bad(arg, "nothing after `:` (expected key=value,...)"));
        }
        for pair in split_top_level(arg, rest)? {
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| bad(arg, format!("`{pair}` is not key=value")))?;
            let (key, value) = (key.trim(), value.trim());
            if key.is_empty() {
                return Err(bad(arg, format!("empty key in `{pair}`")));
            }
            if key == "kind" {
                return Err(bad(arg, "`kind` is given before `:`, not as a field"));
            }
            if value.is_empty() {
                return Err(bad(arg, format!("empty value for `{key}`")));
            }
            if fields.contains_key(key) {
                return Err(bad(arg, format!("duplicate key `{key}`")));
            }
            let parsed = match value.strip_prefix('[') {
                Some(inner) => {
                    let inner = inner
                        .strip_suffix(']')
                        .ok_or_else(|| bad(arg, format!("`{key}`: `[` without a closing `]`")))?;
                    let items = inner
                        .split(',')
                        .map(|v| {
                            let v = v.trim();
                            if v.is_empty() || v.contains(['[', ']']) {
                                Err(bad(arg, format!("`{key}`: bad list item `{v}`")))
                            } else {
                                parse_value(arg, key, v)
                            }
                        })
                        .collect::<Result<Vec<_>>>()?;
                    serde_json::Value::Array(items)
                }
                None if value.contains(['[', ']']) => {
                    return Err(bad(arg, format!("`{key}={value}`: stray bracket")));
                }
                None => parse_value(arg, key, value)?,
            };
            fields.insert(key.to_string(), parsed);
        }
    }
    Ok(EffectSpec {
        kind: kind.to_string(),
        fields,
    })
}

/// Splits on commas outside brackets.
fn split_top_level<'a>(arg: &str, text: &'a str) -> Result<Vec<&'a str>> {
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0i32, 0usize);
    for (i, c) in text.char_indices() {
        match c {
            '[' => depth += 1,
            ']' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
        if !(0..=1).contains(&depth) {
            return Err(bad(arg, "unbalanced or nested brackets"));
        }
    }
    if depth != 0 {
        return Err(bad(arg, "`[` without a closing `]`"));
    }
    parts.push(&text[start..]);
    Ok(parts)
}

fn parse_value(arg: &str, key: &str, value: &str) -> Result<serde_json::Value> {
    if let Ok(i) = value.parse::<i64>() {
        return Ok(serde_json::Value::from(i));
    }
    if let Ok(x) = value.parse::<f64>() {
        // `nan`, `inf` parse as f64 but are never data.
        return match serde_json::Number::from_f64(x) {
            Some(n) if x.is_finite() => Ok(serde_json::Value::Number(n)),
            _ => Err(bad(arg, format!("`{key}={value}` is not a finite number"))),
        };
    }
    Ok(match value {
        "true" => serde_json::Value::Bool(true),
        "false" => serde_json::Value::Bool(false),
        s => serde_json::Value::String(s.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_strings_and_bare_kind() {
        let e = parse_effect_arg("bypass:fraction=0.1,rack=A03").unwrap();
        assert_eq!(e.kind, "bypass");
        assert_eq!(e.fields["fraction"], serde_json::json!(0.1));
        assert_eq!(e.fields["rack"], serde_json::json!("A03"));
        let e = parse_effect_arg("crac_supply_offset").unwrap();
        assert!(e.fields.is_empty());
    }
}
