//! `hall.json` and `snapshots.csv` (formats.md sections 1 and 2): malformed inputs are
//! rejected with the file, the field and what was expected; valid files round-trip; the
//! OpenFOAM development datasets load.

use std::path::{Path, PathBuf};

use kalibre_dc::effects::EffectRegistry;
use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{
    load_snapshots, parse_snapshots, parse_snapshots_bytes, to_observations, write_predictions,
    write_snapshots, HallSnapshot,
};
use kalibre_dc::Error;
use serde_json::{json, Value};

#[path = "formats/csv.rs"]
mod csv_cases;
#[path = "formats/hall.rs"]
mod hall_cases;

use csv_cases::csv_cases;
use hall_cases::hall_cases;

const HALL_FILE: &str = "test-hall.json";
const CSV_FILE: &str = "test-snapshots.csv";

/// A small valid hall: two rows facing a cold aisle, one floor CRAC, hot-aisle containment.
fn hall_value() -> Value {
    json!({
        "schema": "kalibre.hall/1",
        "name": "small",
        "room": { "size_m": [8.0, 6.0, 3.0] },
        "server_types": [
            { "id": "1u", "alpha_cfm_per_w": { "initial": 0.12, "min": 0.01, "max": 3.0 } },
            { "id": "2u", "alpha_cfm_per_w": { "initial": 0.15, "min": 0.01, "max": 3.0 } }
        ],
        "cracs": [
            { "id": "crac-1", "position_m": [0.0, 2.0, 0.0], "size_m": [0.8, 2.0, 2.0],
              "rated_flow_m3_s": 4.0, "supply": "floor" }
        ],
        "tiles": [ { "position_m": [2.0, 2.9], "size_m": [0.6, 0.6], "open_fraction": 0.25 } ],
        "returns": [ { "position_m": [2.0, 5.0], "size_m": [1.2, 0.6] } ],
        "racks": [
            { "id": "R1", "position_m": [2.0, 1.4, 0.0], "size_m": [0.6, 1.2, 2.0],
              "inlet": "+y", "units": 42,
              "servers": [
                  { "id": "R1-01", "type": "1u", "u": 1, "height_u": 1 },
                  { "id": "R1-02", "type": "2u", "u": 2, "height_u": 2 }
              ] },
            // Touches R1 at x = 2.6: touching is not overlapping.
            { "id": "R2", "position_m": [2.6, 1.4, 0.0], "size_m": [0.6, 1.2, 2.0],
              "inlet": "+y", "units": 42,
              "servers": [
                  { "id": "R2-01", "type": "1u", "u": 1, "height_u": 10 },
                  { "id": "R2-11", "type": "2u", "u": 11, "height_u": 30 }
              ] },
            { "id": "R3", "position_m": [2.0, 3.8, 0.0], "size_m": [0.6, 1.2, 2.0],
              "inlet": "-y", "units": 42,
              "servers": [ { "id": "R3-01", "type": "2u", "u": 1, "height_u": 42 } ] }
        ],
        "containment": [
            { "kind": "hot_aisle", "min_m": [2.0, 5.0, 0.0], "max_m": [3.2, 6.0, 2.0] }
        ],
        "sensors": [
            { "id": "c01", "position_m": [2.3, 3.2, 1.0], "aisle": "cold" },
            { "id": "h01", "position_m": [2.3, 5.5, 1.5], "aisle": "hot" },
            { "id": "h02", "position_m": [2.3, 0.8, 1.5], "aisle": "hot" }
        ],
        "calibrate": { "alpha": "per_type" },
        "effects": []
    })
}

fn hall() -> Hall {
    Hall::from_json_str(&hall_value().to_string(), HALL_FILE).expect("the base hall is valid")
}

/// Data rows of a valid `snapshots.csv` (line = index + 2). `t1` has no reading for `h02`
/// (a dead sensor) and gives R2's power per rack.
fn csv_rows() -> Vec<String> {
    [
        "t0,setpoint_c,crac-1,18.0",
        "t0,fan_speed,crac-1,0.80",
        "t0,power_w,R1-01,310",
        "t0,power_w,R1-02,420.5",
        "t0,power_w,R2,4000",
        "t0,power_w,R3-01,2500",
        "t0,sensor_c,c01,21.4",
        "t0,sensor_c,h01,33.9",
        "t0,sensor_c,h02,31.2",
        "t1,setpoint_c,crac-1,19.5",
        "t1,fan_speed,crac-1,1",
        "t1,power_w,R1-01,0",
        "t1,power_w,R1-02,400",
        "t1,power_w,R2-01,900",
        "t1,power_w,R2-11,3100",
        "t1,power_w,R3-01,2400",
        "t1,sensor_c,c01,22.0",
        "t1,sensor_c,h01,34.1",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn csv_text(rows: &[String]) -> String {
    let mut s = String::from("snapshot,kind,id,value\n");
    for r in rows {
        s.push_str(r);
        s.push('\n');
    }
    s
}

fn format_error<T: std::fmt::Debug>(r: kalibre_dc::Result<T>) -> (String, String, String) {
    match r {
        Err(Error::Format {
            file,
            field,
            message,
        }) => (file, field, message),
        other => panic!("expected a format error, got {other:?}"),
    }
}

/// Sets the value at `pointer`, adding the last key to its object if it is new.
fn set(v: &mut Value, pointer: &str, new: Value) {
    let (parent, key) = pointer.rsplit_once('/').unwrap();
    let parent = v
        .pointer_mut(parent)
        .unwrap_or_else(|| panic!("no {parent} in the base hall"));
    match parent {
        Value::Object(map) => {
            map.insert(key.to_string(), new);
        }
        Value::Array(items) => items[key.parse::<usize>().unwrap()] = new,
        other => panic!("{pointer}: cannot set inside {other}"),
    }
}

#[test]
fn malformed_halls_are_rejected_with_field_and_reason() {
    let cases = hall_cases();
    assert!(cases.len() >= 25);
    for c in cases {
        let (file, field, message) = format_error(Hall::from_json_str(&c.text, HALL_FILE));
        assert_eq!(file, HALL_FILE, "{}", c.name);
        assert_eq!(field, c.field, "{}: {message}", c.name);
        assert!(
            message.contains(c.phrase),
            "{}: message `{message}` lacks `{}`",
            c.name,
            c.phrase
        );
    }
}

#[test]
fn tolerances_and_extra_are_honoured() {
    // Racks overlapping by less than 1 mm touch; sensors on a rack face are in the air.
    let mut v = hall_value();
    set(&mut v, "/racks/1/position_m/0", json!(2.5995));
    set(&mut v, "/sensors/0/position_m", json!([2.3, 2.6, 1.0]));
    set(
        &mut v,
        "/extra",
        json!({ "anything": [1, { "nested": true }] }),
    );
    set(&mut v, "/racks/0/extra", json!({ "vendor": "x" }));
    set(
        &mut v,
        "/effects",
        json!([{ "kind": "bypass", "fraction": 0.1 }]),
    );
    let hall = Hall::from_json_str(&v.to_string(), HALL_FILE).unwrap();
    assert_eq!(hall.effects[0].kind, "bypass");
    assert_eq!(hall.effects[0].fields["fraction"], json!(0.1));
    // A 2 mm overlap is an overlap.
    set(&mut v, "/racks/1/position_m/0", json!(2.598));
    let (_, field, _) = format_error(Hall::from_json_str(&v.to_string(), HALL_FILE));
    assert_eq!(field, "/racks/1");
}

/// The contract refuses unknown fields except under `extra`, which any object may carry
/// (other tools write these files): every object takes one, it changes no physics, and
/// the hall keeps it when written.
#[test]
fn every_object_may_carry_a_free_form_extra() {
    let mut v = hall_value();
    set(
        &mut v,
        "/effects",
        json!([{ "kind": "rack_recirculation", "rack": "R1" }]),
    );
    let plain = Hall::from_json_str(&v.to_string(), HALL_FILE).unwrap();
    let note = json!({ "from": "dcim", "n": [1, 2] });
    for pointer in [
        "/extra",
        "/room/extra",
        "/server_types/0/extra",
        "/server_types/0/alpha_cfm_per_w/extra",
        "/cracs/0/extra",
        "/tiles/0/extra",
        "/returns/0/extra",
        "/racks/0/extra",
        "/racks/0/servers/0/extra",
        "/containment/0/extra",
        "/sensors/0/extra",
        "/calibrate/extra",
        "/effects/0/extra",
    ] {
        set(&mut v, pointer, note.clone());
    }
    let noted = Hall::from_json_str(&v.to_string(), HALL_FILE).unwrap();
    assert_eq!(noted.physics_json(), plain.physics_json());
    let effects = EffectRegistry::builtin().build_all(&noted).unwrap();
    assert_eq!(effects.len(), 1);
    let written: Value = serde_json::from_str(&noted.to_json_pretty()).unwrap();
    for pointer in [
        "/calibrate/extra",
        "/server_types/0/alpha_cfm_per_w/extra",
        "/effects/0/extra",
    ] {
        assert_eq!(written.pointer(pointer), Some(&note), "{pointer}");
    }
    // Anything else is still a typo.
    set(&mut v, "/effects/0/fraktion", json!(0.2));
    let hall = Hall::from_json_str(&v.to_string(), HALL_FILE).unwrap();
    let e = EffectRegistry::builtin()
        .build_all(&hall)
        .unwrap_err()
        .to_string();
    assert!(e.contains("fraktion") && e.contains("unknown field"), "{e}");
}

#[test]
fn a_server_type_no_server_uses_has_no_alpha_parameter() {
    use kalibre_dc::hall::AlphaMode;
    use kalibre_dc::ParamLayout;
    let mut v = hall_value();
    v["server_types"].as_array_mut().unwrap().insert(
        1,
        json!({ "id": "spare", "alpha_cfm_per_w": { "initial": 0.2, "min": 0.01, "max": 3.0 } }),
    );
    let hall = Hall::from_json_str(&v.to_string(), HALL_FILE).expect("a spare type is fine");
    let layout = ParamLayout::new(&hall, &[]).unwrap();
    assert_eq!(layout.space().names(), ["alpha/1u", "alpha/2u"]);
    // Each server still reads its own type's value.
    let per_server = layout.alpha_per_server(&[0.11, 0.22]);
    let want: Vec<f64> = hall
        .servers()
        .map(|s| {
            if s.server.server_type == "1u" {
                0.11
            } else {
                0.22
            }
        })
        .collect();
    assert_eq!(per_server, want);
    let per_server = ParamLayout::with_mode(&hall, AlphaMode::PerServer, &[]).unwrap();
    assert_eq!(per_server.space().dim(), hall.server_count());
}

#[test]
fn validate_rejects_non_finite_numbers_of_a_built_hall() {
    let mut h = hall();
    h.sensors[1].position_m[0] = f64::NAN;
    let (_, field, message) = format_error(h.validate("built"));
    assert_eq!(field, "/sensors/1/position_m/0");
    assert!(message.contains("finite"), "{message}");
    let mut h = hall();
    h.server_types[0].alpha_cfm_per_w.max = f64::INFINITY;
    let (_, field, _) = format_error(h.validate("built"));
    assert_eq!(field, "/server_types/0/alpha_cfm_per_w/max");
}

#[test]
fn hall_round_trips_through_json_and_a_file() {
    let h = hall();
    let again = Hall::from_json_str(&h.to_json_pretty(), HALL_FILE).unwrap();
    assert_eq!(h, again);
    let path = std::env::temp_dir().join(format!("kalibre-formats-{}.json", std::process::id()));
    h.save(&path).unwrap();
    let loaded = Hall::load(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(h, loaded);
    // Saving an invalid hall fails and names the rule.
    let mut bad = h.clone();
    bad.racks[0].servers[0].u = 99;
    assert!(bad.save(&path).is_err());
    assert!(!path.exists());
}

#[test]
fn snapshots_resolve_rack_power_and_dead_sensors() {
    let h = hall();
    let snaps = parse_snapshots(&h, &csv_text(&csv_rows()), CSV_FILE).unwrap();
    assert_eq!(snaps.len(), 2);
    let t0 = &snaps[0];
    assert_eq!(t0.state.label, "t0");
    assert_eq!(t0.state.setpoint_c, vec![18.0]);
    assert_eq!(t0.state.fan_speed, vec![0.8]);
    // R2's 4000 W shared by height_u 10 and 30.
    assert_eq!(t0.state.power_w, vec![310.0, 420.5, 1000.0, 3000.0, 2500.0]);
    assert_eq!(t0.sensor_c, vec![Some(21.4), Some(33.9), Some(31.2)]);
    assert_eq!(snaps[1].sensor_c, vec![Some(22.0), Some(34.1), None]);
}

/// A snapshot with every fan off is refused even when nothing draws power: no air moves,
/// and nothing sets the temperatures (a solve ran 90 s into a NaN).
#[test]
fn every_fan_off_is_refused_when_no_server_draws_power_too() {
    let mut rows = csv_rows();
    for (i, row) in rows.iter_mut().enumerate() {
        if row.starts_with("t1,power_w") {
            *row = format!("{},0", row.rsplit_once(',').unwrap().0);
        } else if i == 10 {
            *row = "t1,fan_speed,crac-1,0".into();
        }
    }
    let (_, field, message) = format_error(parse_snapshots(&hall(), &csv_text(&rows), CSV_FILE));
    assert_eq!(field, "snapshot `t1` (first at line 11)");
    assert!(
        message.contains("every CRAC's fan_speed is 0 (the servers draw 0 kW)"),
        "{message}"
    );
}

#[test]
fn snapshot_order_is_first_appearance_and_rows_may_interleave() {
    let h = hall();
    let mut rows = csv_rows();
    // t1's rows first, t0's interleaved after.
    rows.rotate_left(9);
    rows.swap(1, 10);
    let snaps = parse_snapshots(&h, &csv_text(&rows), CSV_FILE).unwrap();
    let labels: Vec<&str> = snaps.iter().map(|s| s.state.label.as_str()).collect();
    assert_eq!(labels, ["t1", "t0"]);
    let base = parse_snapshots(&h, &csv_text(&csv_rows()), CSV_FILE).unwrap();
    assert_eq!(snaps[1], base[0]);
    assert_eq!(snaps[0], base[1]);
}

#[test]
fn snapshots_round_trip_through_the_writer() {
    let h = hall();
    let snaps = parse_snapshots(&h, &csv_text(&csv_rows()), CSV_FILE).unwrap();
    let mut odd = snaps.clone();
    // Labels that need quoting and values that need every digit.
    odd[0].state.label = "2024-01-01 10:00, \"peak\"".into();
    odd[1].state.power_w[2] = 1.0 / 3.0;
    odd[1].sensor_c[0] = Some(1e-7);
    for s in [&snaps, &odd] {
        let text = write_snapshots(&h, s);
        let again = parse_snapshots(&h, &text, CSV_FILE).unwrap();
        assert_eq!(&again, s);
    }
}

#[test]
fn predictions_are_sensor_rows_in_the_snapshot_format() {
    let h = hall();
    let labels = vec!["t0".to_string(), "t1".to_string()];
    let predicted = vec![vec![20.5, 30.25, 29.0], vec![21.0, 31.0, 28.5]];
    let text = write_predictions(&h, &labels, &predicted);
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("snapshot,kind,id,value"));
    assert_eq!(lines.next(), Some("t0,sensor_c,c01,20.5"));
    assert_eq!(text.lines().count(), 7);
    assert!(text
        .lines()
        .skip(1)
        .all(|l| l.split(',').nth(1) == Some("sensor_c")));
}

#[test]
fn observations_take_sensors_in_hall_order_with_aisle_groups() {
    let h = hall();
    let snaps = parse_snapshots(&h, &csv_text(&csv_rows()), CSV_FILE).unwrap();
    let obs = to_observations(&h, &snaps).unwrap();
    assert_eq!(obs.output_names(), ["c01", "h01", "h02"]);
    let groups: Vec<&str> = obs.outputs().iter().map(|o| o.group.as_str()).collect();
    assert_eq!(groups, ["cold", "hot", "hot"]);
    assert_eq!(
        obs.snapshots()[1].measured,
        vec![Some(22.0), Some(34.1), None]
    );
    assert_eq!(obs.snapshots()[0].scenario, snaps[0].state);
    assert_eq!(obs.measured_count(), 5);
    let mut short = snaps.clone();
    short[0].state.power_w.pop();
    assert!(matches!(
        to_observations(&h, &short),
        Err(Error::Mismatch(_))
    ));
}

#[test]
fn malformed_snapshots_are_rejected_with_line_and_reason() {
    let h = hall();
    let cases = csv_cases();
    assert!(cases.len() >= 25);
    for c in cases {
        let (file, field, message) = format_error(parse_snapshots(&h, &c.text, CSV_FILE));
        assert_eq!(file, CSV_FILE, "{}", c.name);
        assert_eq!(field, c.field, "{}: {message}", c.name);
        assert!(
            message.contains(c.phrase),
            "{}: message `{message}` lacks `{}`",
            c.name,
            c.phrase
        );
    }
}

#[test]
fn snapshot_bytes_that_are_not_utf8_name_line_and_column() {
    let h = hall();
    let mut bytes = csv_text(&csv_rows()).into_bytes();
    let at = bytes.windows(3).position(|w| w == b"h01").unwrap();
    bytes[at + 1] = 0xff;
    let (_, field, message) = format_error(parse_snapshots_bytes(&h, &bytes, CSV_FILE));
    assert_eq!(field, "line 9, column id");
    assert!(message.contains("UTF-8"), "{message}");
}

#[test]
fn a_byte_order_mark_and_crlf_line_ends_are_accepted() {
    let h = hall();
    let hall_text = hall_value().to_string();
    assert_eq!(
        Hall::from_json_str(&format!("\u{feff}{hall_text}"), HALL_FILE).unwrap(),
        Hall::from_json_str(&hall_text, HALL_FILE).unwrap()
    );
    let text = format!("\u{feff}{}", csv_text(&csv_rows()).replace('\n', "\r\n"));
    let snaps = parse_snapshots(&h, &text, CSV_FILE).unwrap();
    assert_eq!(
        snaps,
        parse_snapshots(&h, &csv_text(&csv_rows()), CSV_FILE).unwrap()
    );
}

/// The OpenFOAM datasets: `$KALIBRE_OPENFOAM_DATA`, else `data/openfoam` in the
/// repository, else the shared copy beside it.
fn datasets() -> Vec<PathBuf> {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = std::env::var_os("KALIBRE_OPENFOAM_DATA")
        .map(PathBuf::from)
        .or_else(|| Some(manifest.join("../data/openfoam")).filter(|p| p.is_dir()))
        .unwrap_or_else(|| manifest.join("../../shared/data/openfoam"));
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap_or_else(|e| panic!("{}: {e}", root.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("hall.json").is_file())
        .collect();
    dirs.sort();
    dirs
}

#[test]
fn openfoam_datasets_load_with_three_snapshots_of_24_sensors() {
    let dirs = datasets();
    assert_eq!(dirs.len(), 4, "{dirs:?}");
    for dir in dirs {
        let hall = Hall::load(&dir.join("hall.json")).unwrap();
        let snaps: Vec<HallSnapshot> = load_snapshots(&hall, &dir.join("snapshots.csv")).unwrap();
        assert_eq!(snaps.len(), 3, "{}", dir.display());
        assert_eq!(hall.sensors.len(), 24);
        assert_eq!(hall.server_count(), 20);
        for s in &snaps {
            assert_eq!(s.sensor_c.len(), 24);
            assert!(s.sensor_c.iter().all(Option::is_some), "{}", dir.display());
        }
        let labels: Vec<&str> = snaps.iter().map(|s| s.state.label.as_str()).collect();
        assert_eq!(labels, ["t0", "t1", "t2"]);
        assert_eq!(snaps[0].state.setpoint_c, vec![17.5]);
        assert_eq!(snaps[1].state.fan_speed, vec![1.0]);
        let total_t0: f64 = snaps[0].state.power_w.iter().sum();
        assert!((total_t0 - 51730.0).abs() < 1.0, "{total_t0}");
        let obs = to_observations(&hall, &snaps).unwrap();
        assert_eq!(obs.measured_count(), 72);
        let hot = obs.outputs().iter().filter(|o| o.group == "hot").count();
        assert_eq!(hot, 6);
        // Round trips of real files.
        assert_eq!(
            Hall::from_json_str(&hall.to_json_pretty(), "x").unwrap(),
            hall
        );
        assert_eq!(
            parse_snapshots(&hall, &write_snapshots(&hall, &snaps), "x").unwrap(),
            snaps
        );
    }
}

#[test]
fn missing_files_are_io_errors_naming_the_path() {
    let err = Hall::load(Path::new("/nonexistent/hall.json")).unwrap_err();
    assert!(
        matches!(&err, Error::Io { path, .. } if path == "/nonexistent/hall.json"),
        "{err:?}"
    );
}
