//! Parsers that read a model's outputs from the text of its output file.

use regex::Regex;

use super::ExternalError;

/// How outputs are read from the output file. Values are returned in the order of the
/// output names; `NaN` and `inf` parse (and are then rejected as non-finite), anything
/// else that is not a number is an error naming the output.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum OutputParser {
    /// A header row of column names, then data rows; values come from the **last** data
    /// row (solvers that append a row per iteration end with the converged one). Columns
    /// not among the outputs are ignored.
    CsvColumns,
    /// Rows `name,value`, one per output, in any order; a first row `name,value` is a
    /// header and skipped. A name given twice is an error.
    CsvLong,
    /// One regular expression per output with exactly one capture group, the number; the
    /// **last** match in the file counts (a log prints its residuals every iteration).
    Regex(Vec<(String, Regex)>),
}

impl OutputParser {
    /// A regex parser from `(output name, pattern)` pairs; each pattern must compile and
    /// have exactly one capture group.
    pub fn regex<N: Into<String>, P: AsRef<str>>(
        patterns: impl IntoIterator<Item = (N, P)>,
    ) -> Result<Self, ExternalError> {
        let mut out = Vec::new();
        for (name, pat) in patterns {
            let name = name.into();
            let key = format!("output.regex.{name}");
            let re = Regex::new(pat.as_ref())
                .map_err(|e| ExternalError::setting(&key, format!("invalid regex: {e}")))?;
            if re.captures_len() != 2 {
                return Err(ExternalError::setting(
                    &key,
                    format!(
                        "needs exactly one capture group, has {}",
                        re.captures_len() - 1
                    ),
                ));
            }
            out.push((name, re));
        }
        Ok(OutputParser::Regex(out))
    }

    /// Checks the parser against the output names (a regex parser needs exactly one
    /// pattern per output).
    pub(crate) fn check(&self, names: &[String]) -> Result<(), ExternalError> {
        if let OutputParser::Regex(pats) = self {
            for n in names {
                if !pats.iter().any(|(p, _)| p == n) {
                    return Err(ExternalError::setting(
                        format!("output.regex.{n}"),
                        "output has no pattern",
                    ));
                }
            }
            if let Some((p, _)) = pats.iter().find(|(p, _)| !names.contains(p)) {
                return Err(ExternalError::setting(
                    format!("output.regex.{p}"),
                    "pattern for a name that is not in output.names",
                ));
            }
        }
        Ok(())
    }

    /// Text that identifies the parser, for the model's fingerprint.
    pub(crate) fn describe(&self) -> String {
        match self {
            OutputParser::CsvColumns => "csv".into(),
            OutputParser::CsvLong => "csv_long".into(),
            OutputParser::Regex(p) => {
                let mut s = String::from("regex");
                for (n, r) in p {
                    s.push_str(&format!("\u{1f}{n}\u{1f}{}", r.as_str()));
                }
                s
            }
        }
    }

    /// Reads the outputs `names` from `text` (the contents of `file`, named in errors).
    pub fn parse(&self, text: &str, file: &str, names: &[String]) -> Result<Vec<f64>, String> {
        // Spreadsheet exports start with a byte-order mark, which is no part of a name.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        match self {
            OutputParser::CsvColumns => parse_columns(text, file, names),
            OutputParser::CsvLong => parse_long(text, file, names),
            OutputParser::Regex(pats) => names
                .iter()
                .map(|n| {
                    let re = &pats
                        .iter()
                        .find(|(p, _)| p == n)
                        .ok_or_else(|| format!("output `{n}` has no pattern"))?
                        .1;
                    let caps = re.captures_iter(text).last().ok_or_else(|| {
                        format!(
                            "output `{n}`: pattern `{}` does not match {file}",
                            re.as_str()
                        )
                    })?;
                    let m = caps.get(1).map_or("", |m| m.as_str());
                    number(m, n, file)
                })
                .collect(),
        }
    }
}

fn number(text: &str, name: &str, file: &str) -> Result<f64, String> {
    text.trim().parse::<f64>().map_err(|_| {
        format!(
            "output `{name}` in {file}: `{}` is not a number",
            text.trim()
        )
    })
}

/// Data lines: not blank, not a `#` comment; with 1-based line numbers.
fn lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Splits one CSV line (RFC 4180 quoting: `"a,b"` and `""` inside quotes) into trimmed fields.
fn fields(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut cur).trim().to_string()),
            _ => cur.push(c),
        }
    }
    out.push(cur.trim().to_string());
    out
}

fn parse_columns(text: &str, file: &str, names: &[String]) -> Result<Vec<f64>, String> {
    let mut it = lines(text);
    let (_, header) = it.next().ok_or_else(|| format!("{file} is empty"))?;
    let header = fields(header);
    let (row_line, row) = it
        .last()
        .ok_or_else(|| format!("{file} has a header but no data row"))?;
    let row = fields(row);
    if row.len() != header.len() {
        return Err(format!(
            "{file} line {row_line}: {} fields, the header has {}",
            row.len(),
            header.len()
        ));
    }
    names
        .iter()
        .map(|n| {
            let mut at = header.iter().enumerate().filter(|(_, h)| *h == n);
            let (i, _) = at
                .next()
                .ok_or_else(|| format!("output `{n}`: no such column in {file}"))?;
            if at.next().is_some() {
                return Err(format!(
                    "output `{n}`: the header of {file} names it twice; which is meant?"
                ));
            }
            number(&row[i], n, file)
        })
        .collect()
}

fn parse_long(text: &str, file: &str, names: &[String]) -> Result<Vec<f64>, String> {
    let mut found: Vec<Option<f64>> = vec![None; names.len()];
    for (k, (line_no, line)) in lines(text).enumerate() {
        let f = fields(line);
        if k == 0
            && f.len() == 2
            && f[0].eq_ignore_ascii_case("name")
            && f[1].eq_ignore_ascii_case("value")
        {
            continue;
        }
        if f.len() != 2 {
            return Err(format!(
                "{file} line {line_no}: expected `name,value`, got {} fields",
                f.len()
            ));
        }
        if let Some(i) = names.iter().position(|n| *n == f[0]) {
            if found[i].is_some() {
                return Err(format!(
                    "output `{}` appears twice in {file} (line {line_no})",
                    f[0]
                ));
            }
            found[i] = Some(number(&f[1], &f[0], file)?);
        }
    }
    names
        .iter()
        .zip(found)
        .map(|(n, v)| v.ok_or_else(|| format!("output `{n}` missing from {file}")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn columns_take_the_last_row_by_name() {
        let text = "# comment\niter,t_out,\"t,in\"\n1,5.0,3\n2, 6.5 ,4e-1\n\n";
        let v = OutputParser::CsvColumns
            .parse(text, "o.csv", &names(&["t,in", "t_out"]))
            .unwrap();
        assert_eq!(v, [0.4, 6.5]);
        let e = OutputParser::CsvColumns
            .parse(text, "o.csv", &names(&["t_x"]))
            .unwrap_err();
        assert!(e.contains("t_x") && e.contains("o.csv"), "{e}");
        let e = OutputParser::CsvColumns
            .parse("a,b\n1\n", "o.csv", &names(&["a"]))
            .unwrap_err();
        assert!(e.contains("line 2"), "{e}");
        // A column named twice is ambiguous; a byte-order mark is no part of a name.
        let e = OutputParser::CsvColumns
            .parse("a,b,a\n1,2,999\n", "o.csv", &names(&["a"]))
            .unwrap_err();
        assert!(e.contains("names it twice"), "{e}");
        let v = OutputParser::CsvColumns
            .parse("\u{feff}a,b\n1,2\n", "o.csv", &names(&["a"]))
            .unwrap();
        assert_eq!(v, [1.0]);
    }

    #[test]
    fn long_format_any_order_nan_parses() {
        let text = "name,value\nb,2\na,NaN\nextra,1\n";
        let v = OutputParser::CsvLong
            .parse(text, "o.csv", &names(&["a", "b"]))
            .unwrap();
        assert!(v[0].is_nan() && v[1] == 2.0);
        let e = OutputParser::CsvLong
            .parse("a,1\na,2\n", "o.csv", &names(&["a"]))
            .unwrap_err();
        assert!(e.contains("twice"), "{e}");
        let e = OutputParser::CsvLong
            .parse("a,x1\n", "o.csv", &names(&["a"]))
            .unwrap_err();
        assert!(e.contains("`x1` is not a number"), "{e}");
        let e = OutputParser::CsvLong
            .parse("a,1\n", "o.csv", &names(&["a", "b"]))
            .unwrap_err();
        assert!(e.contains("`b` missing"), "{e}");
    }

    #[test]
    fn regex_last_match_and_checks() {
        let p = OutputParser::regex([("res", r"residual = (\S+)"), ("t", r"T=(\S+)")]).unwrap();
        let text = "residual = 1\nT=300\nresidual = 0.5\n";
        assert_eq!(
            p.parse(text, "log", &names(&["t", "res"])).unwrap(),
            [300.0, 0.5]
        );
        assert!(p.check(&names(&["t", "res"])).is_ok());
        assert!(p.check(&names(&["t"])).is_err());
        assert!(p.check(&names(&["t", "res", "u"])).is_err());
        let e = OutputParser::regex([("a", r"(x)(y)")]).unwrap_err();
        assert!(e.to_string().contains("output.regex.a"), "{e}");
        let e = p.parse("T=1\n", "log", &names(&["res"])).unwrap_err();
        assert!(e.contains("does not match"), "{e}");
    }
}
