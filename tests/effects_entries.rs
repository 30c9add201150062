//! Bad `effects` entries in `hall.json`, table-driven: through the CLI (`kalibre simulate`,
//! `calibrate` and `diagnose` exit with code 2 and one line naming the file, the JSON
//! pointer of the field and what is wrong) and through the library (a typed error: the
//! reader's `Error::Format`, the registry's `Error::Effect`, or `Error::Format` from
//! `EffectRegistry::check_hall`). No case may panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use kalibre::dc::effects::EffectRegistry;
use kalibre::dc::hall::Hall;
use kalibre::dc::sim::SimConfig;
use kalibre::dc::synth::{self, Preset, SynthOptions};
use kalibre::dc::{Error, HallModel};
use serde_json::{json, Value};

/// One bad entry: a name, the `effects` value, the pointer the error names and a phrase
/// of its message.
struct Case {
    name: &'static str,
    effects: Value,
    pointer: &'static str,
    needle: &'static str,
}

fn cases() -> Vec<Case> {
    let c = |name, effects, pointer, needle| Case {
        name,
        effects,
        pointer,
        needle,
    };
    vec![
        c(
            "unknown kind",
            json!([{"kind": "leakage"}]),
            "/effects/0/kind",
            "unknown effect kind (known: containment_leakage, bypass",
        ),
        c(
            "unknown parameter",
            json!([{"kind": "bypass", "behind_rack": "A01", "fracton": 0.1}]),
            "/effects/0/fracton",
            "unknown field",
        ),
        c(
            "out-of-range parameter",
            json!([{"kind": "bypass", "behind_rack": "A01", "fraction": 0.9}]),
            "/effects/0/fraction",
            "0.9 is outside [0, 0.5]",
        ),
        c(
            "out-of-range bounds",
            json!([{"kind": "crac_supply_offset", "offset_c_bounds": [-9.0, 1.0]}]),
            "/effects/0/offset_c_bounds",
            "within [-5, 5]",
        ),
        c(
            "huge value",
            json!([{"kind": "containment_leakage", "open_fraction": 1e300}]),
            "/effects/0/open_fraction",
            "1e300 is outside [0, 1]",
        ),
        c(
            "NaN (null after a NaN is written)",
            json!([{"kind": "crac_supply_offset", "offset_c": f64::NAN}]),
            "/effects/0/offset_c",
            "expected a finite number, got null",
        ),
        c(
            "missing required field",
            json!([{"kind": "rack_recirculation", "fraction": 0.1}]),
            "/effects/0/rack",
            "missing (required)",
        ),
        c(
            "missing half of a placement",
            json!([{"kind": "bypass", "position_m": [1.0, 1.0]}]),
            "/effects/0/size_m",
            "needs `position_m` and `size_m`",
        ),
        c(
            "unknown rack id",
            json!([{"kind": "rack_recirculation", "rack": "Z99"}]),
            "/effects/0/rack",
            "no rack `Z99` in the hall",
        ),
        c(
            "unknown CRAC id",
            json!([{"kind": "crac_supply_offset", "crac": "crac-9"}]),
            "/effects/0/crac",
            "no CRAC `crac-9` in the hall",
        ),
        c(
            "wrong type",
            json!([{"kind": "bypass", "behind_rack": "A01", "fraction": "0.1"}]),
            "/effects/0/fraction",
            "expected a finite number, got \"0.1\"",
        ),
        c(
            "wrong type of a list",
            json!([{"kind": "containment_leakage", "sides": "top"}]),
            "/effects/0/sides",
            "expected an array of strings",
        ),
        c(
            "a side with no panel",
            json!([{"kind": "containment_leakage", "sides": ["-x", "top"]}]),
            "/effects/0/sides",
            "`top` opens nothing: containment 0 reaches the ceiling, so it has no top panel",
        ),
        c(
            "second entry bad",
            json!([{"kind": "crac_supply_offset"}, {"kind": "containment_leakage", "containment": 4}]),
            "/effects/1/containment",
            "index 4 is out of range",
        ),
        c(
            "the same effect twice, a default written out in one",
            json!([
                {"kind": "bypass", "behind_rack": "A01", "fraction": 0.1},
                {"kind": "crac_supply_offset", "crac": "crac-1"},
                {"kind": "bypass", "behind_rack": "A01", "depth_m": 0.4, "fraction_bounds": [0.0, 0.3]}
            ]),
            "/effects/2",
            "the same kind in the same place as effects/0",
        ),
        c(
            "a side listed twice",
            json!([{"kind": "containment_leakage", "sides": ["+x", "+x"]}]),
            "/effects/0/sides",
            "`+x` is listed twice",
        ),
        // The same opening written two ways is one placement: the sides in another
        // order, the hall's only containment named or not, a gap over the rack's whole
        // height or none given.
        c(
            "the same leak twice, written two ways",
            json!([
                {"kind": "containment_leakage", "sides": ["+x", "-x"]},
                {"kind": "containment_leakage", "containment": 0, "sides": ["-x", "+x"]}
            ]),
            "/effects/1",
            "the same kind in the same place as effects/0",
        ),
        c(
            "the same gap twice, its whole height written out in one",
            json!([
                {"kind": "rack_recirculation", "rack": "A01"},
                {"kind": "rack_recirculation", "rack": "A01", "z_m": [0.0, 2.0]}
            ]),
            "/effects/1",
            "the same kind in the same place as effects/0",
        ),
        c(
            "two openings that could take the whole supply",
            json!([
                {"kind": "bypass", "behind_rack": "A01"},
                {"kind": "bypass", "behind_rack": "B03"}
            ]),
            "/effects/1/fraction_bounds",
            "take the whole supply (effects/0 0.5, effects/1 0.5: 1 in all)",
        ),
        c(
            "a floor opening under a rack",
            json!([{"kind": "bypass", "position_m": [2.5, 2.5], "size_m": [0.4, 0.4]}]),
            "/effects/0/position_m",
            "the opening lies under rack `A01`",
        ),
        c(
            "kind not a string",
            json!([{"kind": 3}]),
            "/effects/0/kind",
            "expected a string",
        ),
        c(
            "effects not a list",
            json!({"kind": "bypass"}),
            "/effects",
            "expected a sequence",
        ),
    ]
}

/// A demo hall (with hot-aisle containment) and snapshots, written once.
fn fixture() -> &'static (Hall, PathBuf) {
    static FIXTURE: OnceLock<(Hall, PathBuf)> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let s = synth::generate(
            &SynthOptions::new(Preset::Demo, 1)
                .with_snapshots(1)
                .with_measurement_cell_m(0.2)
                .with_reference_runs(false),
        )
        .expect("synth");
        let dir = std::env::temp_dir().join(format!("kalibre-effects-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let snaps = dir.join("snapshots.csv");
        std::fs::write(
            &snaps,
            kalibre::dc::snapshots::write_snapshots(&s.hall, &s.snapshots),
        )
        .unwrap();
        (s.hall, snaps)
    })
}

/// The hall's JSON text with `effects` replaced.
fn hall_text(effects: &Value) -> String {
    let mut v = serde_json::to_value(&fixture().0).unwrap();
    v["effects"] = effects.clone();
    serde_json::to_string_pretty(&v).unwrap()
}

fn write_case(case: &Case) -> PathBuf {
    let dir = fixture().1.parent().unwrap().to_path_buf();
    let path = dir.join(format!("hall-{}.json", case.name.replace(' ', "_")));
    std::fs::write(&path, hall_text(&case.effects)).unwrap();
    path
}

fn kalibre(args: &[&str], hall: &Path) -> Output {
    let snaps = &fixture().1;
    let out = hall.with_extension("out");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_kalibre"));
    cmd.args(args)
        .arg("--hall")
        .arg(hall)
        .arg("--snapshots")
        .arg(snaps);
    match args[0] {
        "simulate" => cmd.arg("--out").arg(out.join("pred.csv")),
        "calibrate" => cmd.arg("--out").arg(&out),
        _ => cmd.arg("--calibration").arg(&out),
    };
    cmd.output().expect("the kalibre binary runs")
}

#[test]
fn the_cli_refuses_bad_entries_with_one_line_naming_file_and_field() {
    for case in cases() {
        let hall = write_case(&case);
        let file = hall.display().to_string();
        for cmd in [
            &["simulate"][..],
            &["calibrate", "--iterations", "1"],
            &["diagnose"],
        ] {
            let o = kalibre(cmd, &hall);
            let err = String::from_utf8_lossy(&o.stderr);
            let what = format!("{} on `{}`", cmd[0], case.name);
            assert_eq!(o.status.code(), Some(2), "{what}: {err}");
            let lines: Vec<&str> = err.lines().collect();
            assert_eq!(lines.len(), 1, "{what}: one line, got: {err}");
            let want = format!("kalibre: error: {file}: {}: ", case.pointer);
            assert!(
                lines[0].starts_with(&want),
                "{what}: `{}` lacks `{want}`",
                lines[0]
            );
            assert!(
                lines[0].contains(case.needle),
                "{what}: `{}` lacks `{}`",
                lines[0],
                case.needle
            );
        }
    }
}

#[test]
fn the_library_returns_typed_errors() {
    let registry = EffectRegistry::builtin();
    for case in cases() {
        let text = hall_text(&case.effects);
        let hall = match Hall::from_json_str(&text, "hall.json") {
            // The reader rejects what is not an entry at all.
            Err(Error::Format {
                file,
                field,
                message,
            }) => {
                assert_eq!(file, "hall.json");
                assert_eq!(field, case.pointer, "{}: {message}", case.name);
                assert!(message.contains(case.needle), "{}: {message}", case.name);
                continue;
            }
            Err(e) => panic!("{}: unexpected error {e:?}", case.name),
            Ok(h) => h,
        };
        // Building the model gives the registry's typed error, naming the entry and field.
        match HallModel::new(&hall, SimConfig::default()) {
            Err(Error::Effect { kind, message }) => {
                let entry = &case.pointer["/".len()..];
                let entry = entry.split('/').take(2).collect::<Vec<_>>().join("/");
                assert!(message.starts_with(&entry), "{}: {message}", case.name);
                assert!(message.contains(case.needle), "{}: {message}", case.name);
                let i: usize = entry["effects/".len()..].parse().unwrap();
                assert_eq!(kind, hall.effects[i].kind, "{}", case.name);
            }
            other => panic!("{}: expected Error::Effect, got {other:?}", case.name),
        }
        // `check_hall` names the file and the field's JSON pointer.
        match registry.check_hall(&hall, "hall.json") {
            Err(Error::Format {
                file,
                field,
                message,
            }) => {
                assert_eq!(file, "hall.json");
                assert_eq!(field, case.pointer, "{}: {message}", case.name);
                assert!(message.contains(case.needle), "{}: {message}", case.name);
            }
            other => panic!("{}: expected Error::Format, got {other:?}", case.name),
        }
    }
}

#[test]
fn good_entries_pass_the_same_checks() {
    let effects = json!([
        {"kind": "bypass", "behind_rack": "A01", "fraction": 0.1},
        {"kind": "containment_leakage", "containment": 0, "sides": ["-x"]},
        {"kind": "crac_supply_offset", "crac": "crac-1", "offset_c": -1.0},
        {"kind": "rack_recirculation", "rack": "B03", "z_m": [1.0, 1.6]}
    ]);
    let hall = Hall::from_json_str(&hall_text(&effects), "hall.json").expect("hall");
    EffectRegistry::builtin()
        .check_hall(&hall, "hall.json")
        .expect("good entries");
    let model = HallModel::new(&hall, SimConfig::default()).expect("model");
    assert_eq!(
        model.layout().space().names()[model.layout().space().dim() - 4..],
        [
            "bypass/fraction",
            "containment_leakage/open_fraction",
            "crac_supply_offset/offset_c",
            "rack_recirculation/fraction"
        ]
    );
}

#[test]
fn a_literal_nan_is_refused_by_the_reader() {
    let text = hall_text(&json!([{"kind": "crac_supply_offset", "offset_c": 1.25}]))
        .replace("1.25", "NaN");
    match Hall::from_json_str(&text, "hall.json") {
        Err(Error::Format {
            file,
            field,
            message,
        }) => {
            assert_eq!(
                (file.as_str(), field.as_str()),
                ("hall.json", "/effects/0/offset_c")
            );
            assert!(
                message.contains("NaN and Infinity are not JSON"),
                "{message}"
            );
        }
        other => panic!("expected Error::Format, got {other:?}"),
    }
    let dir = fixture().1.parent().unwrap().to_path_buf();
    let hall = dir.join("hall-nan.json");
    std::fs::write(&hall, &text).unwrap();
    let o = kalibre(&["simulate"], &hall);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(&format!(
            "kalibre: error: {}: /effects/0/offset_c: ",
            hall.display()
        )),
        "{err}"
    );
}
