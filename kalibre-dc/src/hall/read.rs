//! Reading `hall.json`: JSON syntax and structure with the JSON pointer of the first problem,
//! then every rule of `formats.md` section 1 ([`Hall::validate`]).

use std::path::Path;

use serde::Deserialize;
use serde_path_to_error::Segment;

use super::types::{Hall, HALL_SCHEMA};
use crate::json_keys::escape_pointer_token;
use crate::{Error, Result};

/// Just the schema tag: read first so that a file of another schema (or version) is
/// reported as such, not as a list of unknown fields.
#[derive(Deserialize)]
struct SchemaTag {
    schema: Option<serde_json::Value>,
}

impl Hall {
    /// Parses `hall.json` text and checks every rule of the format; `file` names the source
    /// in errors.
    pub fn from_json_str(text: &str, file: &str) -> Result<Hall> {
        // A byte-order mark some editors write on Windows: an encoding marker, not JSON.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        check_schema_tag(text, file)?;
        let mut de = serde_json::Deserializer::from_str(text);
        let hall: Hall = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let pointer = json_pointer(e.path());
            let inner = e.into_inner();
            structural_error(text, file, pointer, &inner)
        })?;
        de.end().map_err(|e| {
            let message = e.to_string();
            Error::format(
                file,
                text_place(&e),
                format!(
                    "expected the end of the file: {}",
                    without_place(&message, &e)
                ),
            )
        })?;
        // Structs refuse a repeated field themselves; maps (an effect's fields) keep the
        // last value silently.
        if let Some((field, message)) = crate::json_keys::duplicate_key_problem(text) {
            return Err(Error::format(file, field, message));
        }
        // serde also reads a struct from an array, field by field in declaration order:
        // a guess the contract forbids, and one no unknown-field check would catch.
        if let Some((field, message)) = positional_object(text, &hall) {
            return Err(Error::format(file, field, message));
        }
        hall.validate(file)?;
        Ok(hall)
    }

    /// Like [`Hall::from_json_str`] for raw bytes, which must be UTF-8.
    pub fn from_json_bytes(bytes: &[u8], file: &str) -> Result<Hall> {
        let text = utf8(bytes, file)?;
        Hall::from_json_str(text, file)
    }

    /// Reads and checks a `hall.json` file.
    pub fn load(path: &Path) -> Result<Hall> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Hall::from_json_bytes(&bytes, &path.display().to_string())
    }
}

/// The text of `bytes`, or an error naming the line of the first byte that is not UTF-8.
pub(crate) fn utf8<'a>(bytes: &'a [u8], file: &str) -> Result<&'a str> {
    std::str::from_utf8(bytes).map_err(|e| {
        let good = &bytes[..e.valid_up_to()];
        let line = good.iter().filter(|&&b| b == b'\n').count() + 1;
        let column = good.len() - good.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1) + 1;
        Error::format(
            file,
            format!("line {line}"),
            format!(
                "expected UTF-8 text; invalid byte at column {column} (byte offset {})",
                e.valid_up_to()
            ),
        )
    })
}

fn check_schema_tag(text: &str, file: &str) -> Result<()> {
    // A syntax error here is left to the full parse, which reports it with its path.
    let Ok(tag) = serde_json::from_str::<SchemaTag>(text) else {
        return Ok(());
    };
    match tag.schema {
        Some(serde_json::Value::String(s)) if s == HALL_SCHEMA => Ok(()),
        Some(other) => Err(Error::format(
            file,
            "/schema",
            format!("expected \"{HALL_SCHEMA}\", found {other}"),
        )),
        None => Err(Error::format(
            file,
            "/schema",
            format!("missing field `schema`; expected \"{HALL_SCHEMA}\""),
        )),
    }
}

/// What is said where an object with named fields was given as an array.
const POSITIONAL: &str =
    "expected an object with named fields, found an array: fields are read by name, never \
     by position";

/// The pointer of the first place where `text` gives as an array what the hall holds as
/// an object (a struct read by position), and the message naming the fields expected.
fn positional_object(text: &str, hall: &Hall) -> Option<(String, String)> {
    let original: serde_json::Value = serde_json::from_str(text).ok()?;
    let written = serde_json::to_value(hall).ok()?;
    let (pointer, fields) = first_positional(&original, &written, String::new())?;
    let pointer = if pointer.is_empty() {
        "/".into()
    } else {
        pointer
    };
    let named = fields
        .iter()
        .map(|f| format!("`{f}`"))
        .collect::<Vec<_>>()
        .join(", ");
    Some((pointer, format!("{POSITIONAL} ({named})")))
}

/// Walks the text's value beside the hall's own serialisation, which writes every struct
/// as an object: an array there was read by position.
fn first_positional(
    original: &serde_json::Value,
    written: &serde_json::Value,
    pointer: String,
) -> Option<(String, Vec<String>)> {
    use serde_json::Value;
    match (original, written) {
        (Value::Array(_), Value::Object(fields)) => {
            Some((pointer, fields.keys().cloned().collect()))
        }
        (Value::Array(a), Value::Array(b)) => a
            .iter()
            .zip(b)
            .enumerate()
            .find_map(|(i, (x, y))| first_positional(x, y, format!("{pointer}/{i}"))),
        (Value::Object(a), Value::Object(b)) => a.iter().find_map(|(k, x)| {
            let y = b.get(k)?;
            first_positional(x, y, format!("{pointer}/{}", escape_pointer_token(k)))
        }),
        _ => None,
    }
}

/// Maps a serde error to [`Error::Format`]: a missing field gets the pointer of the field
/// itself, so that the pointer says where to add it.
fn structural_error(
    text_in: &str,
    file: &str,
    mut pointer: String,
    e: &serde_json::Error,
) -> Error {
    let text = e.to_string();
    if e.classify() == serde_json::error::Category::Data {
        if let Some(name) = text
            .strip_prefix("missing field `")
            .and_then(|rest| rest.split('`').next())
        {
            pointer.push('/');
            pointer.push_str(&escape_pointer_token(name));
        }
        // The whole document of the wrong type (`null`, `[]`) has the root's pointer.
        if pointer.is_empty() {
            pointer.push('/');
        }
        // An array of the wrong length where a struct belongs: serde would say how many
        // elements it takes, as if the array could be right.
        if text.starts_with("invalid length ") && text.contains(", expected struct ") {
            return Error::format(file, pointer, POSITIONAL);
        }
        return Error::format(file, pointer, text);
    }
    let hint = if starts_non_finite(text_in, e.line(), e.column()) {
        "; numbers must be finite (NaN and Infinity are not JSON)"
    } else if e.line() == 1 && looks_like_csv(text_in) {
        // Most often the snapshots file given for the hall.
        "; this file looks like CSV (a snapshots file?), not a hall's JSON description"
    } else {
        ""
    };
    let mut text = text.as_str();
    // A syntax error before any field is read has no pointer: its place is the text's.
    if pointer.is_empty() {
        pointer = text_place(e);
        text = without_place(text, e);
    }
    Error::format(file, pointer, format!("invalid JSON: {text}{hint}"))
}

/// A first line of comma-separated words rather than a JSON value.
fn looks_like_csv(text: &str) -> bool {
    let first = text.lines().next().unwrap_or("").trim();
    !first.starts_with(['{', '[', '"']) && first.contains(',')
}

/// Where in the text a serde_json error is, for the field of an error no field can
/// name: `line 3, column 7` (`line 1` in an empty file, whose column is 0).
fn text_place(e: &serde_json::Error) -> String {
    match e.column() {
        0 => format!("line {}", e.line()),
        c => format!("line {}, column {c}", e.line()),
    }
}

/// A serde_json message without the place it appends, once that place is the field.
fn without_place<'m>(message: &'m str, e: &serde_json::Error) -> &'m str {
    let place = format!(" at line {} column {}", e.line(), e.column());
    message.strip_suffix(&place).unwrap_or(message)
}

/// True when the text at a serde_json error position (1-based line and column) spells a
/// non-finite number, which some writers emit.
fn starts_non_finite(text: &str, line: usize, column: usize) -> bool {
    let at = text
        .lines()
        .nth(line.saturating_sub(1))
        .and_then(|l| l.get(column.saturating_sub(1)..))
        .unwrap_or("");
    let at = at.strip_prefix('-').unwrap_or(at);
    ["NaN", "nan", "Infinity", "inf"]
        .iter()
        .any(|w| at.starts_with(w))
}

/// RFC 6901 JSON pointer of a serde path (`/racks/3/servers/0/u`).
pub(crate) fn json_pointer(path: &serde_path_to_error::Path) -> String {
    let mut out = String::new();
    for segment in path {
        match segment {
            Segment::Seq { index } => {
                out.push('/');
                out.push_str(&index.to_string());
            }
            Segment::Map { key } => {
                out.push('/');
                out.push_str(&escape_pointer_token(key));
            }
            // Enum variants and unknown segments are not keys of the document.
            Segment::Enum { .. } | Segment::Unknown => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_field_points_at_the_field() {
        let err = Hall::from_json_str(
            r#"{"schema":"kalibre.hall/1","name":"x","room":{"size_m":[1,1,1],"colour":1}}"#,
            "h.json",
        )
        .unwrap_err();
        match err {
            Error::Format { field, message, .. } => {
                assert_eq!(field, "/room/colour");
                assert!(message.contains("unknown field `colour`"), "{message}");
            }
            other => panic!("unexpected error {other:?}"),
        }
    }

    #[test]
    fn missing_field_points_where_it_belongs() {
        let err = Hall::from_json_str(
            r#"{"schema":"kalibre.hall/1","name":"x","room":{}}"#,
            "h.json",
        )
        .unwrap_err();
        match err {
            Error::Format { field, message, .. } => {
                assert_eq!(field, "/room/size_m");
                assert!(message.contains("missing field"), "{message}");
            }
            other => panic!("unexpected error {other:?}"),
        }
    }

    #[test]
    fn utf8_error_names_the_line() {
        let err = utf8(b"{\n\"a\": \"\xff\"}", "h.json").unwrap_err();
        match err {
            Error::Format { field, .. } => assert_eq!(field, "line 2"),
            other => panic!("unexpected error {other:?}"),
        }
    }

    /// The development hall with `edit` applied to its JSON: the error's field and message.
    fn dev_hall_error(edit: impl FnOnce(&mut serde_json::Value)) -> (String, String) {
        let text = include_str!("../../../data/openfoam/of-dev-clean/hall.json");
        let mut json: serde_json::Value = serde_json::from_str(text).unwrap();
        edit(&mut json);
        match Hall::from_json_str(&json.to_string(), "h.json").unwrap_err() {
            Error::Format { field, message, .. } => (field, message),
            other => panic!("unexpected error {other:?}"),
        }
    }

    /// JSON has one number type: a count written as a float with no fractional part is
    /// the same count; one with a fraction, or below zero, is refused where it is.
    #[test]
    fn counts_written_as_whole_floats_are_the_same_counts() {
        let text = include_str!("../../../data/openfoam/of-dev-clean/hall.json");
        let mut json: serde_json::Value = serde_json::from_str(text).unwrap();
        let expected = Hall::from_json_str(text, "h.json").unwrap();
        let units = json["racks"][0]["units"].as_u64().unwrap() as f64;
        let server = &mut json["racks"][0]["servers"][0];
        let (u, height_u) = (
            server["u"].as_u64().unwrap(),
            server["height_u"].as_u64().unwrap(),
        );
        server["u"] = serde_json::json!(u as f64);
        server["height_u"] = serde_json::json!(height_u as f64);
        json["racks"][0]["units"] = serde_json::json!(units);
        let floats = json.to_string();
        assert!(
            floats.contains(&format!("\"units\":{units:.1}")),
            "{floats}"
        );
        assert_eq!(Hall::from_json_str(&floats, "h.json").unwrap(), expected);
        let (field, message) = dev_hall_error(|h| h["racks"][0]["units"] = serde_json::json!(42.5));
        assert_eq!(field, "/racks/0/units");
        assert!(
            message.contains("42.5") && message.contains("a whole number"),
            "{message}"
        );
        let (field, _) =
            dev_hall_error(|h| h["racks"][1]["servers"][0]["height_u"] = serde_json::json!(-2));
        assert_eq!(field, "/racks/1/servers/0/height_u");
    }

    /// serde reads a struct from an array by field order; the reader refuses that guess
    /// wherever it would be made, naming the fields it expects.
    #[test]
    fn an_object_written_as_an_array_is_refused_where_it_is() {
        let (field, message) = dev_hall_error(|h| {
            h["server_types"][1]["alpha_cfm_per_w"] = serde_json::json!([0.12, 0.01, 3.0])
        });
        assert_eq!(field, "/server_types/1/alpha_cfm_per_w");
        assert!(message.contains("found an array"), "{message}");
        assert!(message.contains("`initial`, `max`, `min`"), "{message}");
        let (field, _) = dev_hall_error(|h| h["room"] = serde_json::json!([[12.0, 8.4, 3.0]]));
        assert_eq!(field, "/room");
        let (field, _) = dev_hall_error(|h| h["calibrate"] = serde_json::json!(["per_server"]));
        assert_eq!(field, "/calibrate");
        let (field, _) = dev_hall_error(|h| {
            let server = h["racks"][0]["servers"][0].clone();
            let fields: Vec<_> = ["id", "type", "u", "height_u"]
                .iter()
                .map(|k| server[*k].clone())
                .collect();
            h["racks"][0]["servers"][0] = serde_json::Value::Array(fields);
        });
        assert_eq!(field, "/racks/0/servers/0");
        // Of the wrong length, the same: not "expected struct Hall with 13 elements".
        let err = Hall::from_json_str("[]", "h.json").unwrap_err();
        match err {
            Error::Format { field, message, .. } => {
                assert_eq!(field, "/");
                assert!(message.starts_with(POSITIONAL), "{message}");
            }
            other => panic!("unexpected error {other:?}"),
        }
    }
}
