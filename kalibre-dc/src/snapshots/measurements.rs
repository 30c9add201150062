//! `measurements.csv`: what was measured of a model of your own (`kalibre calibrate
//! --model command --config model.toml --measurements FILE`), one row per scenario and
//! output, with the same CSV rules as `snapshots.csv` (a header, UTF-8, finite decimal
//! numbers, errors naming the line and column, a near miss of a name suggested).
//!
//! ```csv
//! scenario,output,value
//! winter,t_in,12.3
//! winter,t_out,30.1
//! summer,t_in,25.0
//! ```
//!
//! Scenarios are the `[[scenarios]]` labels of `model.toml`, outputs its `output.names`.
//! An output may be missing from a scenario (not measured there); a scenario with no row
//! is not calibrated against (the caller says so).
//!
//! A fourth column `sd` gives each measurement's standard uncertainty, in the output's
//! units (`scenario,output,value,sd`); then every row has one, finite and positive, and
//! the loop weighs each residual by it.

use std::collections::HashMap;
use std::path::Path;

use super::hints;
use super::lexical::{next_record, parse_decimal, show, LineCounter};
use crate::{Error, Result};

const HEADER: [&str; 4] = ["scenario", "output", "value", "sd"];

/// A value, its standard uncertainty if given, and the line it was read on.
type Read = (f64, Option<f64>, u64);

/// The measurements of each scenario, in the order the scenarios were given: `None` for
/// a scenario with no row, else one entry per output (`None`: not measured there).
pub type ScenarioMeasurements = Vec<Option<Vec<Option<f64>>>>;

/// What `measurements.csv` holds: the values and, with an `sd` column, each one's
/// standard uncertainty (in the same places as the values).
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    /// The measured values.
    pub values: ScenarioMeasurements,
    /// Each value's standard uncertainty, where the file has an `sd` column.
    pub sd: Option<ScenarioMeasurements>,
}

/// Reads `measurements.csv` against the scenario labels and output names of a model.
pub fn load_measurements(
    path: &Path,
    scenarios: &[String],
    outputs: &[String],
) -> Result<Measurements> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_measurements(&bytes, &path.display().to_string(), scenarios, outputs)
}

/// [`load_measurements`] of bytes; `file` names the source in errors.
pub fn parse_measurements(
    bytes: &[u8],
    file: &str,
    scenarios: &[String],
    outputs: &[String],
) -> Result<Measurements> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(bytes);
    let scenario_index: HashMap<&str, usize> = scenarios
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    let output_index: HashMap<&str, usize> = outputs
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    // Each value with the line that gave it, for a duplicate's message.
    let mut values: Vec<Option<Vec<Option<Read>>>> = vec![None; scenarios.len()];
    let mut record = csv::ByteRecord::new();
    let mut lines = LineCounter::default();
    // The columns of the header: 3, or 4 with `sd`.
    let mut columns = 0usize;
    let mut rows = 0usize;
    while let Some(line) = next_record(&mut reader, &mut record, &mut lines, bytes, file)? {
        let last = columns.max(3) - 1;
        let at = |column: Option<usize>| match column {
            Some(c) => format!("line {line}, column {}", HEADER[c]),
            None => format!("line {line}"),
        };
        let mut fields = Vec::with_capacity(record.len());
        for (k, f) in record.iter().enumerate() {
            let text = std::str::from_utf8(f)
                .map_err(|_| Error::format(file, at(Some(k.min(last))), "expected UTF-8 text"))?;
            fields.push(text);
        }
        if let Some(c) = fields.iter().position(|f| f.contains(['\n', '\r'])) {
            return Err(Error::format(
                file,
                at(Some(c.min(last))),
                "a quoted value runs on past its line: is a closing `\"` missing?",
            ));
        }
        let start = record.position().map_or(0, csv::Position::byte);
        if let Some(c) = super::lexical::text_after_closing_quote(bytes, start) {
            return Err(Error::format(
                file,
                at(Some(c.min(last))),
                super::lexical::TEXT_AFTER_QUOTE,
            ));
        }
        if columns == 0 {
            if fields != HEADER[..3] && fields != HEADER {
                return Err(Error::format(
                    file,
                    at(None),
                    format!(
                        "expected the header `scenario,output,value` (or \
                         `scenario,output,value,sd`), found `{}`{}",
                        show(&fields.join(",")),
                        hints::header(&fields)
                    ),
                ));
            }
            columns = fields.len();
            continue;
        }
        if fields.len() != columns {
            return Err(Error::format(
                file,
                at(None),
                format!(
                    "expected {columns} fields ({}), found {}{}",
                    HEADER[..columns].join(","),
                    fields.len(),
                    hints::measurement_field_count(&fields, columns)
                ),
            ));
        }
        let (label, output, text) = (fields[0], fields[1], fields[2]);
        let Some(&s) = scenario_index.get(label) else {
            return Err(Error::format(
                file,
                at(Some(0)),
                format!(
                    "unknown scenario `{}`; expected a [[scenarios]] label of the model's \
                     configuration ({}){}",
                    show(label),
                    kalibre_core::some_names(scenarios),
                    hints::nearest_id(label, scenarios.iter().map(String::as_str))
                ),
            ));
        };
        let Some(&k) = output_index.get(output) else {
            return Err(Error::format(
                file,
                at(Some(1)),
                format!(
                    "unknown output `{}`; expected one of the model's output.names ({}){}",
                    show(output),
                    kalibre_core::some_names(outputs),
                    hints::nearest_id(output, outputs.iter().map(String::as_str))
                ),
            ));
        };
        let v = parse_decimal(text).ok_or_else(|| {
            Error::format(
                file,
                at(Some(2)),
                format!(
                    "expected a finite decimal number for output `{}` of scenario `{}`, found \
                     `{}`{}",
                    show(output),
                    show(label),
                    show(text),
                    hints::value(text, |t| parse_decimal(t).is_some())
                ),
            )
        })?;
        // The fits square these: a value near f64::MAX overflows them into NaN later,
        // where nothing names the file.
        if !kalibre_core::within_magnitude(v) {
            return Err(Error::format(
                file,
                at(Some(2)),
                format!(
                    "{} for output `{}` of scenario `{}` is beyond +/-{}, more than the fit can \
                     square",
                    kalibre_core::number(v),
                    show(output),
                    show(label),
                    kalibre_core::number(kalibre_core::MAX_MAGNITUDE)
                ),
            ));
        }
        let sd = match fields.get(3) {
            None => None,
            Some(text) => Some(parse_decimal(text).filter(|v| *v > 0.0).ok_or_else(|| {
                Error::format(
                    file,
                    at(Some(3)),
                    format!(
                        "expected the standard uncertainty of output `{}` of scenario `{}`, a \
                         finite positive decimal number in the output's units, found `{}`",
                        show(output),
                        show(label),
                        show(text)
                    ),
                )
            })?),
        };
        // Each value is divided by its sd: the quotient must fit too.
        if let Some(sd) = sd.filter(|sd| {
            !kalibre_core::within_magnitude(*sd) || !kalibre_core::within_magnitude(v / sd)
        }) {
            return Err(Error::format(
                file,
                at(Some(3)),
                format!(
                    "sd {} of output `{}` of scenario `{}` is out of scale: the value and the \
                     value over its sd ({}) must be within +/-{}",
                    kalibre_core::number(sd),
                    show(output),
                    show(label),
                    kalibre_core::number(v / sd),
                    kalibre_core::number(kalibre_core::MAX_MAGNITUDE)
                ),
            ));
        }
        let slot = &mut values[s].get_or_insert_with(|| vec![None; outputs.len()])[k];
        if let Some((_, _, first)) = *slot {
            return Err(Error::format(
                file,
                at(Some(1)),
                format!(
                    "output `{}` of scenario `{}` is given twice (first on line {first})",
                    show(output),
                    show(label)
                ),
            ));
        }
        *slot = Some((v, sd, line));
        rows += 1;
    }
    if columns == 0 {
        return Err(Error::format(
            file,
            "line 1",
            "empty file; expected the header `scenario,output,value` and at least one row",
        ));
    }
    if rows == 0 {
        return Err(Error::format(
            file,
            "line 2",
            "no data rows after the header; expected at least one measurement",
        ));
    }
    let pick = |f: fn(&Read) -> Option<f64>| -> ScenarioMeasurements {
        (values.iter())
            .map(|s| {
                s.as_ref()
                    .map(|row| row.iter().map(|v| v.as_ref().and_then(f)).collect())
            })
            .collect()
    };
    Ok(Measurements {
        values: pick(|r| Some(r.0)),
        sd: (columns == 4).then(|| pick(|r| r.1)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    fn parse_full(text: &str) -> Result<Measurements> {
        parse_measurements(
            text.as_bytes(),
            "m.csv",
            &names(&["winter", "summer", "spring"]),
            &names(&["t_in", "t_out"]),
        )
    }

    fn parse(text: &str) -> Result<ScenarioMeasurements> {
        parse_full(text).map(|m| m.values)
    }

    #[test]
    fn rows_land_by_scenario_and_output() {
        let m = parse_full("scenario,output,value\r\nsummer,t_out,30.5\nwinter,t_in,5\n").unwrap();
        assert_eq!(m.sd, None);
        let m = m.values;
        assert_eq!(m[0], Some(vec![Some(5.0), None]));
        assert_eq!(m[1], Some(vec![None, Some(30.5)]));
        assert_eq!(m[2], None);
    }

    #[test]
    fn an_sd_column_lands_beside_its_values() {
        let m = parse_full("scenario,output,value,sd\nsummer,t_out,30.5,0.2\nwinter,t_in,5,1e-3\n")
            .unwrap();
        assert_eq!(m.values[1], Some(vec![None, Some(30.5)]));
        let sd = m.sd.expect("an sd column");
        assert_eq!(sd[0], Some(vec![Some(1e-3), None]));
        assert_eq!(sd[1], Some(vec![None, Some(0.2)]));
        assert_eq!(sd[2], None);
        for (text, needle) in [
            (
                "scenario,output,value,sd\nwinter,t_in,1\n",
                "line 2: expected 4 fields",
            ),
            (
                "scenario,output,value,sd\nwinter,t_in,1,5,2\n",
                "a decimal comma? `5,2`",
            ),
            (
                "scenario,output,value\nwinter,t_in,30,5\n",
                "a decimal comma? `30,5`",
            ),
            (
                "scenario,output,value\nwinter,t_in,30,0.5\n",
                "name it in the header: scenario,output,value,sd",
            ),
            (
                "scenario,output,value,sd\nwinter,t_in,1,0\n",
                "line 2, column sd: expected the standard uncertainty",
            ),
            (
                "scenario,output,value,sd\nwinter,t_in,1,-2\n",
                "line 2, column sd",
            ),
            (
                "scenario,output,value,sd\nwinter,t_in,1,nan\n",
                "line 2, column sd",
            ),
            (
                "scenario,output,value,sd\nwinter,t_in,1,\n",
                "line 2, column sd",
            ),
            (
                "scenario,output,value,sigma\n",
                "line 1: expected the header",
            ),
        ] {
            let e = parse(text).unwrap_err().to_string();
            assert!(e.contains("m.csv") && e.contains(needle), "{needle}: {e}");
        }
    }

    #[test]
    fn values_and_sds_beyond_what_a_fit_can_square_are_named() {
        let e = parse_full("scenario,output,value\nwinter,t_in,1e308\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.csv"), "{e}");
        assert!(e.contains("line 2, column value"), "{e}");
        assert!(e.contains("beyond +/-1e150"), "{e}");
        for sd in ["1e308", "1e-308"] {
            let text = format!("scenario,output,value,sd\nwinter,t_in,7.5,{sd}\n");
            let e = parse_full(&text).unwrap_err().to_string();
            assert!(e.contains("line 2, column sd"), "{sd}: {e}");
            assert!(e.contains("out of scale"), "{sd}: {e}");
        }
        // 1e150 itself, and an sd that keeps the quotient within it, are fine.
        let ok = "scenario,output,value,sd\nwinter,t_in,1e150,1\nwinter,t_out,1e-100,1e-200\n";
        assert!(parse_full(ok).is_ok());
    }

    #[test]
    fn bad_rows_are_named_by_line_and_column() {
        let cases = [
            ("scenario,sensor,value\n", "line 1: expected the header"),
            ("scenario,output,value\n", "line 2: no data rows"),
            (
                "scenario,output,value\nwintr,t_in,1\n",
                "line 2, column scenario: unknown scenario `wintr`",
            ),
            (
                "scenario,output,value\nwintr,t_in,1\n",
                "did you mean `winter`?",
            ),
            (
                "scenario,output,value\nwinter,t_ot,1\n",
                "line 2, column output: unknown output `t_ot`",
            ),
            (
                "scenario,output,value\nwinter,t_in,NaN\n",
                "line 2, column value: expected a finite decimal number",
            ),
            (
                "scenario,output,value\nwinter,t_in,1\nwinter,t_in,2\n",
                "line 3, column output: output `t_in` of scenario `winter` is given twice \
                 (first on line 2)",
            ),
            (
                "scenario,output,value\nwinter,t_in,1,5\n",
                "line 2: expected 3 fields",
            ),
            (
                "scenario,output,value\nwinter,t_in,\"1\"5\n",
                "line 2, column value: text follows a closing `\"`",
            ),
        ];
        for (text, needle) in cases {
            let e = parse(text).unwrap_err().to_string();
            assert!(e.contains("m.csv") && e.contains(needle), "{needle}: {e}");
        }
    }
}
