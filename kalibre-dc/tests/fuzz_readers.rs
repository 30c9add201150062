//! Fuzz-style properties of the two readers: random bytes and random mutations of valid
//! `hall.json` and `snapshots.csv` text give `Ok` or `Err`, never a panic; whatever is
//! accepted satisfies the format's rules.

use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{parse_snapshots, parse_snapshots_bytes, write_snapshots};
use kalibre_dc::Error;
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::RngSeed;
use serde_json::json;

fn hall_text() -> String {
    serde_json::to_string_pretty(&json!({
        "schema": "kalibre.hall/1",
        "name": "fuzz",
        "room": { "size_m": [6.0, 5.0, 3.0] },
        "server_types": [
            { "id": "a", "alpha_cfm_per_w": { "initial": 0.12, "min": 0.01, "max": 3.0 } },
            { "id": "b", "alpha_cfm_per_w": { "initial": 0.2, "min": 0.05, "max": 1.0 } }
        ],
        "cracs": [
            { "id": "k1", "position_m": [0.0, 1.5, 0.0], "size_m": [0.8, 2.0, 2.0],
              "rated_flow_m3_s": 3.0, "supply": "floor" },
            { "id": "k2", "position_m": [5.2, 1.5, 0.0], "size_m": [0.8, 2.0, 2.0],
              "rated_flow_m3_s": 3.0, "supply": "front" }
        ],
        "tiles": [ { "position_m": [2.0, 2.2], "size_m": [0.6, 0.6], "open_fraction": 0.5 } ],
        "returns": [ { "position_m": [2.0, 0.0], "size_m": [1.2, 0.6] } ],
        "racks": [
            { "id": "R1", "position_m": [2.0, 1.0, 0.0], "size_m": [0.6, 1.0, 2.0],
              "inlet": "+y", "units": 42,
              "servers": [
                  { "id": "R1-01", "type": "a", "u": 1, "height_u": 20 },
                  { "id": "R1-21", "type": "b", "u": 21, "height_u": 22 }
              ] },
            { "id": "R2", "position_m": [2.0, 3.0, 0.0], "size_m": [0.6, 1.0, 2.0],
              "inlet": "-y", "units": 10,
              "servers": [ { "id": "R2-01", "type": "a", "u": 1, "height_u": 10 } ] }
        ],
        "containment": [
            { "kind": "cold_aisle", "min_m": [2.0, 2.0, 0.0], "max_m": [2.6, 3.0, 2.0] }
        ],
        "sensors": [
            { "id": "c1", "position_m": [2.3, 2.5, 1.0], "aisle": "cold" },
            { "id": "h1", "position_m": [2.3, 0.5, 1.5], "aisle": "hot" },
            { "id": "h2", "position_m": [2.3, 4.5, 1.5], "aisle": "hot" }
        ],
        "calibrate": { "alpha": "per_server" },
        "effects": [ { "kind": "bypass", "fraction": 0.1 } ],
        "extra": { "note": [1, 2, { "x": null }] }
    }))
    .unwrap()
}

const CSV: &str = "snapshot,kind,id,value
t0,setpoint_c,k1,18
t0,setpoint_c,k2,18.5
t0,fan_speed,k1,0.8
t0,fan_speed,k2,1.0
t0,power_w,R1,5000
t0,power_w,R2-01,2000.5
t0,sensor_c,c1,20.1
t0,sensor_c,h1,31.7
t0,sensor_c,h2,33
t1,setpoint_c,k1,17
t1,setpoint_c,k2,19
t1,fan_speed,k1,0.5
t1,fan_speed,k2,0
t1,power_w,R1-01,2500
t1,power_w,R1-21,1200
t1,power_w,R2,0
t1,sensor_c,h2,29.25
\"t 2\",setpoint_c,k1,16
\"t 2\",setpoint_c,k2,16
\"t 2\",fan_speed,k1,1
\"t 2\",fan_speed,k2,1
\"t 2\",power_w,R1,1e3
\"t 2\",power_w,R2,2.5E2
\"t 2\",sensor_c,c1,-1.5
";

fn base_hall() -> Hall {
    Hall::from_json_str(&hall_text(), "fuzz.json").expect("the base hall is valid")
}

/// Replacement text for a number: boundary values, non-finite spellings and junk.
const NUMBERS: &[&str] = &[
    "0",
    "-0",
    "-1",
    "1",
    "1.5",
    "0.0001",
    "42",
    "43",
    "4294967296",
    "-4294967297",
    "1e400",
    "-1e400",
    "1e-400",
    "NaN",
    "nan",
    "inf",
    "-Infinity",
    "",
    "\"7\"",
    "null",
    "99999999999999999999999999999999",
    "1e",
    "0x10",
    "3.0.1",
    "[]",
    "{}",
    "true",
];

#[derive(Debug, Clone)]
enum Mutation {
    FlipByte(Index, u8),
    InsertByte(Index, u8),
    Truncate(Index),
    DeleteLine(Index),
    DuplicateLine(Index),
    SwapLines(Index, Index),
    ReplaceNumber(Index, Index),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::FlipByte(i, b)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::InsertByte(i, b)),
        any::<Index>().prop_map(Mutation::Truncate),
        any::<Index>().prop_map(Mutation::DeleteLine),
        any::<Index>().prop_map(Mutation::DuplicateLine),
        (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
        (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Mutation::ReplaceNumber(a, b)),
    ]
}

/// Byte ranges of the numbers in `bytes` (runs of digits with sign, point and exponent).
fn number_spans(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() {
            let start = if i > 0 && bytes[i - 1] == b'-' {
                i - 1
            } else {
                i
            };
            while i < bytes.len()
                && (bytes[i].is_ascii_alphanumeric() || b".+-".contains(&bytes[i]))
            {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}

fn split_lines(bytes: &[u8]) -> Vec<Vec<u8>> {
    bytes.split(|&b| b == b'\n').map(<[u8]>::to_vec).collect()
}

fn apply(mut bytes: Vec<u8>, m: &Mutation) -> Vec<u8> {
    match m {
        Mutation::FlipByte(i, b) if !bytes.is_empty() => {
            let k = i.index(bytes.len());
            bytes[k] ^= b.max(&1);
        }
        Mutation::InsertByte(i, b) => {
            let k = i.index(bytes.len() + 1);
            bytes.insert(k, *b);
        }
        Mutation::Truncate(i) => bytes.truncate(i.index(bytes.len() + 1)),
        Mutation::DeleteLine(i) => {
            let mut lines = split_lines(&bytes);
            lines.remove(i.index(lines.len()));
            bytes = lines.join(&b'\n');
        }
        Mutation::DuplicateLine(i) => {
            let mut lines = split_lines(&bytes);
            let k = i.index(lines.len());
            lines.insert(k, lines[k].clone());
            bytes = lines.join(&b'\n');
        }
        Mutation::SwapLines(a, b) => {
            let mut lines = split_lines(&bytes);
            let n = lines.len();
            lines.swap(a.index(n), b.index(n));
            bytes = lines.join(&b'\n');
        }
        Mutation::ReplaceNumber(which, by) => {
            let spans = number_spans(&bytes);
            if !spans.is_empty() {
                let (s, e) = spans[which.index(spans.len())];
                let new = NUMBERS[by.index(NUMBERS.len())].as_bytes();
                bytes.splice(s..e, new.iter().copied());
            }
        }
        Mutation::FlipByte(..) => {}
    }
    bytes
}

/// An accepted hall obeys the rules and survives a round trip.
fn check_accepted_hall(hall: &Hall) {
    hall.validate("again").unwrap();
    let again = Hall::from_json_str(&hall.to_json_pretty(), "again").unwrap();
    assert_eq!(&again, hall);
}

/// Accepted snapshots match the hall and obey section 2.
fn check_accepted_snapshots(hall: &Hall, snaps: &[kalibre_dc::snapshots::HallSnapshot]) {
    assert!(!snaps.is_empty());
    for s in snaps {
        assert_eq!(s.state.setpoint_c.len(), hall.cracs.len());
        assert_eq!(s.state.fan_speed.len(), hall.cracs.len());
        assert_eq!(s.state.power_w.len(), hall.server_count());
        assert_eq!(s.sensor_c.len(), hall.sensors.len());
        assert!(s.state.setpoint_c.iter().all(|v| v.is_finite()));
        assert!(s.state.fan_speed.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(s.state.power_w.iter().all(|v| v.is_finite() && *v >= 0.0));
        assert!(s.sensor_c.iter().flatten().all(|v| v.is_finite()));
        assert!(s.sensor_c.iter().any(Option::is_some));
    }
    let again = parse_snapshots(hall, &write_snapshots(hall, snaps), "again").unwrap();
    assert_eq!(again, snaps);
}

fn is_format_error<T>(r: &kalibre_dc::Result<T>) -> bool {
    matches!(r, Ok(_) | Err(Error::Format { .. }))
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 1000,
        rng_seed: RngSeed::Fixed(20_261_207),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let hall = base_hall();
        let h = Hall::from_json_bytes(&bytes, "random.json");
        prop_assert!(is_format_error(&h));
        let s = parse_snapshots_bytes(&hall, &bytes, "random.csv");
        prop_assert!(is_format_error(&s));
        if let Ok(snaps) = s {
            check_accepted_snapshots(&hall, &snaps);
        }
    }

    #[test]
    fn random_text_lines_never_panic(lines in proptest::collection::vec("[a-z0-9_,.\"\\- ]{0,30}", 0..12)) {
        let hall = base_hall();
        let text = format!("snapshot,kind,id,value\n{}", lines.join("\n"));
        let s = parse_snapshots(&hall, &text, "random.csv");
        prop_assert!(is_format_error(&s));
        if let Ok(snaps) = s {
            check_accepted_snapshots(&hall, &snaps);
        }
    }

    #[test]
    fn mutated_halls_never_panic(ms in proptest::collection::vec(mutation(), 1..5)) {
        let bytes = ms.iter().fold(hall_text().into_bytes(), apply);
        let h = Hall::from_json_bytes(&bytes, "mutated.json");
        prop_assert!(is_format_error(&h));
        if let Ok(hall) = h {
            check_accepted_hall(&hall);
            // The base snapshots against whatever hall the mutation produced.
            let s = parse_snapshots(&hall, CSV, "base.csv");
            prop_assert!(is_format_error(&s));
            if let Ok(snaps) = s {
                check_accepted_snapshots(&hall, &snaps);
            }
        }
    }

    /// Plausible numbers in plausible places: many of these halls are valid, so the
    /// geometric rules and the snapshot reader meet unusual but legal layouts.
    #[test]
    fn halls_with_other_plausible_numbers_never_panic(
        edits in proptest::collection::vec((any::<Index>(), 0.0f64..8.0), 1..4)
    ) {
        let mut bytes = hall_text().into_bytes();
        for (which, v) in &edits {
            let spans = number_spans(&bytes);
            let (s, e) = spans[which.index(spans.len())];
            let new = format!("{}", (v * 10.0).round() / 10.0);
            bytes.splice(s..e, new.bytes());
        }
        let h = Hall::from_json_bytes(&bytes, "plausible.json");
        prop_assert!(is_format_error(&h));
        if let Ok(hall) = h {
            check_accepted_hall(&hall);
            let s = parse_snapshots(&hall, CSV, "base.csv");
            prop_assert!(is_format_error(&s));
            if let Ok(snaps) = s {
                check_accepted_snapshots(&hall, &snaps);
            }
        }
    }

    #[test]
    fn mutated_snapshots_never_panic(ms in proptest::collection::vec(mutation(), 1..5)) {
        let hall = base_hall();
        let bytes = ms.iter().fold(CSV.as_bytes().to_vec(), apply);
        let s = parse_snapshots_bytes(&hall, &bytes, "mutated.csv");
        prop_assert!(is_format_error(&s));
        if let Ok(snaps) = s {
            check_accepted_snapshots(&hall, &snaps);
        }
    }
}

#[test]
fn base_files_are_valid() {
    let hall = base_hall();
    check_accepted_hall(&hall);
    let snaps = parse_snapshots(&hall, CSV, "base.csv").unwrap();
    assert_eq!(snaps.len(), 3);
    check_accepted_snapshots(&hall, &snaps);
}

/// A quote opened and not closed reads the rest of the file into one field: named at its
/// line and column as such, not as a row with too few fields.
#[test]
fn an_unclosed_quote_is_named_where_it_opens() {
    let hall = base_hall();
    let text = CSV.replacen("t0,power_w,R1,5000", "t0,power_w,\"R1,5000", 1);
    assert_ne!(text, CSV);
    let err = parse_snapshots(&hall, &text, "quote.csv")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("quote.csv: line 6, column id: a quoted value runs on past its line"),
        "{err}"
    );
}

#[test]
fn deeply_nested_json_is_an_error_not_a_stack_overflow() {
    let deep = "[".repeat(100_000);
    assert!(matches!(
        Hall::from_json_str(&deep, "deep.json"),
        Err(Error::Format { .. })
    ));
    // Deep nesting where arbitrary JSON is allowed (`extra`).
    let text = hall_text().replacen(
        "\"note\": [",
        &format!("\"note\": [{}", "[".repeat(50_000)),
        1,
    );
    assert!(matches!(
        Hall::from_json_str(&text, "deep.json"),
        Err(Error::Format { .. })
    ));
    let objects = format!("{}1{}", "{\"a\":".repeat(50_000), "}".repeat(50_000));
    assert!(matches!(
        Hall::from_json_str(&objects, "deep.json"),
        Err(Error::Format { .. })
    ));
}

#[test]
fn huge_inputs_are_errors() {
    let hall = base_hall();
    let long_id = "x".repeat(1_000_000);
    let text = format!("snapshot,kind,id,value\nt0,sensor_c,{long_id},1\n");
    match parse_snapshots(&hall, &text, "huge.csv") {
        Err(Error::Format { message, .. }) => assert!(message.len() < 300, "{}", message.len()),
        other => panic!("{other:?}"),
    }
    let big_number = "9".repeat(10_000);
    let text = CSV.replacen("5000", &big_number, 1);
    assert!(matches!(
        parse_snapshots(&hall, &text, "huge.csv"),
        Err(Error::Format { .. })
    ));
    let text = hall_text().replacen("42", &big_number, 1);
    assert!(matches!(
        Hall::from_json_str(&text, "huge.json"),
        Err(Error::Format { .. })
    ));
}
