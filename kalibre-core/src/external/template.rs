//! Text templates with `{{name}}` placeholders.
//!
//! A placeholder is `{{name}}` or `{{name:spec}}` on one line, with optional spaces inside
//! the braces. Names may contain anything but spaces, braces and `:` (e.g. `alpha/web`).
//! Format specs for numbers: `.N` (N decimals), `e` or `E` (scientific), `.Ne` / `.NE`
//! (scientific with N decimals); without a spec a number is written in the shortest form
//! that reads back to the same `f64`. `{{"{{"}}` writes a literal `{{`. Templates are
//! parsed once; rendering an unknown name is an error naming the template and placeholder.

use std::collections::BTreeMap;

use super::ExternalError;

/// A value a placeholder can take.
#[derive(Debug, Clone, PartialEq)]
pub enum TemplateValue {
    /// A number (parameters, scenario values); takes a format spec.
    Number(f64),
    /// Text (scenario label, run directory); written as is, no format spec.
    Text(String),
}

/// How a number is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Shortest text that reads back to the same `f64` (`0.1`, `350`, `0.000001`).
    Shortest,
    /// Fixed-point with this many decimals (`{{x:.3}}` -> `0.100`).
    Fixed(usize),
    /// Scientific (`{{x:e}}` -> `1e-1`, `{{x:.2E}}` -> `1.00E-1`).
    Exp {
        /// Decimals of the mantissa, or shortest.
        precision: Option<usize>,
        /// `E` instead of `e`.
        upper: bool,
    },
}

/// The most decimals a format spec may ask for: every digit an `f64` holds and more
/// (Rust's formatter panics from 65,536 on).
pub const MAX_DECIMALS: usize = 100;

impl Format {
    fn parse(spec: &str) -> Result<Format, String> {
        let unknown = || "unknown format spec (use `.N`, `e`, `E`, `.Ne` or `.NE`)".to_string();
        let (precision, rest) = match spec.strip_prefix('.') {
            Some(s) => {
                let digits = s.bytes().take_while(u8::is_ascii_digit).count();
                if digits == 0 {
                    return Err(unknown());
                }
                let n = s[..digits]
                    .parse::<usize>()
                    .ok()
                    .filter(|&n| n <= MAX_DECIMALS);
                let n = n.ok_or_else(|| {
                    format!("{} decimals: expected at most {MAX_DECIMALS}", &s[..digits])
                })?;
                (Some(n), &s[digits..])
            }
            None => (None, spec),
        };
        match (precision, rest) {
            (Some(p), "") => Ok(Format::Fixed(p)),
            (_, "e") | (_, "E") => Ok(Format::Exp {
                precision,
                upper: rest == "E",
            }),
            _ => Err(unknown()),
        }
    }

    fn write(self, x: f64) -> String {
        match self {
            Format::Shortest => x.to_string(),
            Format::Fixed(p) => format!("{x:.p$}"),
            Format::Exp {
                precision: None,
                upper: false,
            } => format!("{x:e}"),
            Format::Exp {
                precision: None,
                upper: true,
            } => format!("{x:E}"),
            Format::Exp {
                precision: Some(p),
                upper: false,
            } => format!("{x:.p$e}"),
            Format::Exp {
                precision: Some(p),
                upper: true,
            } => format!("{x:.p$E}"),
        }
    }
}

/// The values placeholders resolve to, by name.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Variables {
    map: BTreeMap<String, TemplateValue>,
}

impl Variables {
    /// No variables.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets a variable; returns the previous value if the name was taken.
    pub fn insert(
        &mut self,
        name: impl Into<String>,
        value: TemplateValue,
    ) -> Option<TemplateValue> {
        self.map.insert(name.into(), value)
    }

    /// The value of a name.
    pub fn get(&self, name: &str) -> Option<&TemplateValue> {
        self.map.get(name)
    }

    /// Every variable, by name.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &TemplateValue)> {
        self.map.iter().map(|(k, v)| (k.as_str(), v))
    }

    /// True when the name is set.
    pub fn contains(&self, name: &str) -> bool {
        self.map.contains_key(name)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Part {
    Text(String),
    Placeholder {
        /// The text between the braces, trimmed (for error messages).
        raw: String,
        name: String,
        format: Format,
        line: usize,
    },
}

/// What separates a placeholder's name from its format (`{{k:.3}}`).
const FORMAT_SEPARATOR: char = ':';

/// Whether `c` cannot stand in a placeholder's name: white space and braces end it.
fn ends_placeholder_name(c: char) -> bool {
    c.is_whitespace() || c == '{' || c == '}'
}

/// Whether `c` keeps a name from being written as a placeholder `{{name}}`: it ends the
/// name, or the format separator splits it there.
pub(crate) fn breaks_placeholder(c: char) -> bool {
    ends_placeholder_name(c) || c == FORMAT_SEPARATOR
}

/// A parsed template.
#[derive(Debug, Clone, PartialEq)]
pub struct Template {
    name: String,
    text: String,
    parts: Vec<Part>,
}

impl Template {
    /// Parses `text`; `name` (the file, or `args[2]`) appears in error messages.
    pub fn parse(name: impl Into<String>, text: impl Into<String>) -> Result<Self, ExternalError> {
        let name = name.into();
        let text = text.into();
        let mut parts = Vec::new();
        let mut literal = String::new();
        let mut line = 1;
        let mut rest = text.as_str();
        while let Some(open) = rest.find("{{") {
            literal.push_str(&rest[..open]);
            line += rest[..open].matches('\n').count();
            let after = &rest[open + 2..];
            let line_end = after.find('\n').unwrap_or(after.len());
            let Some(close) = after[..line_end].find("}}") else {
                return Err(ExternalError::Template {
                    file: name,
                    line,
                    placeholder: after[..line_end].chars().take(40).collect(),
                    reason: "no closing `}}` on the same line".into(),
                });
            };
            let raw = after[..close].trim();
            let bad = |reason: &str| ExternalError::Template {
                file: name.clone(),
                line,
                placeholder: raw.to_string(),
                reason: reason.into(),
            };
            if raw.len() >= 2 && raw.starts_with('"') && raw.ends_with('"') {
                literal.push_str(&raw[1..raw.len() - 1]);
            } else {
                let (var, spec) = match raw.split_once(FORMAT_SEPARATOR) {
                    Some((v, s)) => (v.trim(), Some(s.trim())),
                    None => (raw, None),
                };
                if var.is_empty() {
                    return Err(bad("empty name"));
                }
                if var.contains(ends_placeholder_name) {
                    return Err(bad("a name cannot contain spaces or braces"));
                }
                let format = match spec {
                    None => Format::Shortest,
                    Some(s) => Format::parse(s).map_err(|reason| bad(&reason))?,
                };
                if !literal.is_empty() {
                    parts.push(Part::Text(std::mem::take(&mut literal)));
                }
                parts.push(Part::Placeholder {
                    raw: raw.to_string(),
                    name: var.to_string(),
                    format,
                    line,
                });
            }
            rest = &after[close + 2..];
        }
        literal.push_str(rest);
        if !literal.is_empty() {
            parts.push(Part::Text(literal));
        }
        Ok(Template { name, text, parts })
    }

    /// Reads and parses a template file.
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, ExternalError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| ExternalError::io(path, e))?;
        Self::parse(path.display().to_string(), text)
    }

    /// The template's name in error messages.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The template's source text.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The names its placeholders use, in order of appearance (with repeats).
    pub fn placeholders(&self) -> impl Iterator<Item = &str> {
        self.parts.iter().filter_map(|p| match p {
            Part::Placeholder { name, .. } => Some(name.as_str()),
            Part::Text(_) => None,
        })
    }

    /// The first placeholder that `known` does not accept, as an error.
    pub fn check_names(&self, known: impl Fn(&str) -> bool) -> Result<(), ExternalError> {
        for p in &self.parts {
            if let Part::Placeholder {
                raw, name, line, ..
            } = p
            {
                if !known(name) {
                    return Err(self.unknown(raw, *line));
                }
            }
        }
        Ok(())
    }

    fn unknown(&self, raw: &str, line: usize) -> ExternalError {
        ExternalError::Template {
            file: self.name.clone(),
            line,
            placeholder: raw.to_string(),
            reason: "unknown name (not a parameter, scenario variable or built-in)".into(),
        }
    }

    /// Substitutes every placeholder.
    pub fn render(&self, vars: &Variables) -> Result<String, ExternalError> {
        let mut out = String::with_capacity(self.text.len() + 16 * self.parts.len());
        for p in &self.parts {
            match p {
                Part::Text(t) => out.push_str(t),
                Part::Placeholder {
                    raw,
                    name,
                    format,
                    line,
                } => match vars.get(name) {
                    None => return Err(self.unknown(raw, *line)),
                    Some(TemplateValue::Number(x)) => out.push_str(&format.write(*x)),
                    Some(TemplateValue::Text(t)) => {
                        if *format != Format::Shortest {
                            return Err(ExternalError::Template {
                                file: self.name.clone(),
                                line: *line,
                                placeholder: raw.clone(),
                                reason: "a format spec applies to numbers only, this is text"
                                    .into(),
                            });
                        }
                        out.push_str(t)
                    }
                },
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars() -> Variables {
        let mut v = Variables::new();
        v.insert("alpha/web", TemplateValue::Number(0.125));
        v.insert("k", TemplateValue::Number(350.0));
        v.insert("scenario", TemplateValue::Text("summer".into()));
        v
    }

    #[test]
    fn renders_formats_and_literals() {
        let t = Template::parse(
            "p.in",
            "a = {{alpha/web}}\nb = {{ alpha/web:.3 }}; c = {{k:e}} {{k:.2E}}\n{{\"{{\"}} {{scenario}}",
        )
        .unwrap();
        assert_eq!(
            t.render(&vars()).unwrap(),
            "a = 0.125\nb = 0.125; c = 3.5e2 3.50E2\n{{ summer"
        );
        assert_eq!(
            t.placeholders().collect::<Vec<_>>(),
            ["alpha/web", "alpha/web", "k", "k", "scenario"]
        );
    }

    #[test]
    fn shortest_form_round_trips() {
        let t = Template::parse("t", "{{x}}").unwrap();
        for x in [0.1, 1.0 / 3.0, 1e-7, 6.02e23, -2.5] {
            let mut v = Variables::new();
            v.insert("x", TemplateValue::Number(x));
            let s = t.render(&v).unwrap();
            assert_eq!(s.parse::<f64>().unwrap(), x, "{s}");
        }
    }

    #[test]
    fn errors_name_file_line_and_placeholder() {
        let t = Template::parse("case/p.in", "x\ny = {{nope:.2}}\n").unwrap();
        match t.render(&vars()).unwrap_err() {
            ExternalError::Template {
                file,
                line,
                placeholder,
                ..
            } => {
                assert_eq!(
                    (file.as_str(), line, placeholder.as_str()),
                    ("case/p.in", 2, "nope:.2")
                );
            }
            e => panic!("wrong error {e}"),
        }
        let e = Template::parse("f", "\n\n{{k").unwrap_err();
        assert!(matches!(e, ExternalError::Template { line: 3, .. }), "{e}");
        let e = Template::parse("f", "{{k:.x}}").unwrap_err();
        assert!(e.to_string().contains("format spec"), "{e}");
        // Rust's formatter panics from 65,536 decimals: refused when parsed.
        for spec in [".101", ".65536", ".18446744073709551616e", ".99999999999E"] {
            let e = Template::parse("f", format!("{{{{k:{spec}}}}}")).unwrap_err();
            assert!(
                e.to_string().contains("expected at most 100"),
                "{spec}: {e}"
            );
        }
        assert!(Template::parse("f", "{{k:.100e}}")
            .unwrap()
            .render(&vars())
            .is_ok());
        let e = Template::parse("f", "{{ }}").unwrap_err();
        assert!(e.to_string().contains("empty name"), "{e}");
        let t = Template::parse("f", "{{scenario:.2}}").unwrap();
        assert!(t
            .render(&vars())
            .unwrap_err()
            .to_string()
            .contains("numbers only"));
    }
}
