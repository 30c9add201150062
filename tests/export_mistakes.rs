//! What an export script that writes `hall.json` and `snapshots.csv` for kalibre gets
//! wrong, and what kalibre says (a walkthrough of `docs/formats.md` by an engineer
//! writing a hall by hand): lengths in millimetres, padded labels, a rack facing a wall,
//! equipment off the simulator's grid, alpha in another unit, and a sum of powers.

mod cli_support;
use cli_support::*;

use std::path::{Path, PathBuf};

/// The clean development hall with `edit` applied, written to `dir/name`.
fn edited_hall(dir: &Path, name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
    let text = std::fs::read_to_string(data("of-dev-clean/hall.json")).unwrap();
    let mut hall: serde_json::Value = serde_json::from_str(&text).unwrap();
    edit(&mut hall);
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_string_pretty(&hall).unwrap()).unwrap();
    path
}

/// `kalibre simulate` of `hall` on the development snapshots (or `snapshots`).
fn simulate(dir: &Path, hall: &Path, snapshots: Option<&Path>) -> std::process::Output {
    let default = data("of-dev-clean/snapshots.csv");
    run(on_files("simulate", hall, snapshots.unwrap_or(&default))
        .arg("--out")
        .arg(dir.join("pred.csv")))
}

/// A hall in millimetres is blamed on its room size, not on a `--grid-m` never given.
#[test]
fn a_hall_in_millimetres_names_the_room_not_the_grid_flag() {
    let dir = tmp("export-mm");
    let hall = edited_hall(&dir, "hall.json", |h| {
        for v in h["room"]["size_m"].as_array_mut().unwrap() {
            *v = serde_json::json!(v.as_f64().unwrap() * 1000.0);
        }
    });
    let o = simulate(&dir, &hall, None);
    assert_input_error(
        &o,
        "hall.json: /room/size_m: a room of 7200 x 4800 x 3000 m",
    );
    assert!(stderr(&o).contains("are its lengths in metres?"));
    let o = run(
        on_files("simulate", &hall, &data("of-dev-clean/snapshots.csv"))
            .args(["--grid-m", "0.2", "--out"])
            .arg(dir.join("pred.csv")),
    );
    assert_input_error(&o, "--grid-m: cells of 0.2 m give");
}

/// A label padded with a space would be another snapshot, each then incomplete: it is
/// refused at its line.
#[test]
fn a_padded_snapshot_label_is_refused_at_its_line() {
    let dir = tmp("export-label");
    let text = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[5] = lines[5].replacen("t0,", "t0 ,", 1);
    let csv = dir.join("snapshots.csv");
    std::fs::write(&csv, lines.join("\n")).unwrap();
    let o = simulate(&dir, &data("of-dev-clean/hall.json"), Some(&csv));
    assert_input_error(
        &o,
        "snapshots.csv: line 6, column snapshot: snapshot label `t0 ` starts or ends with a space",
    );
}

/// A rack turned to draw its air from the wall it stands against: the simulator's
/// refusal names the hall file and the rack's field.
#[test]
fn a_rack_facing_a_wall_is_named_in_the_hall_file() {
    let dir = tmp("export-wall");
    let hall = edited_hall(&dir, "hall.json", |h| {
        let rack = &mut h["racks"][0];
        rack["position_m"][1] = serde_json::json!(0.0);
        rack["inlet"] = serde_json::json!("-y");
        // Its hot-aisle sensor would now be inside it.
        let sensors = h["sensors"].as_array_mut().unwrap();
        sensors.retain(|s| s["id"] != "h-A1");
    });
    let text = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let kept: Vec<&str> = text.lines().filter(|l| !l.contains(",h-A1,")).collect();
    let csv = dir.join("snapshots.csv");
    std::fs::write(&csv, kept.join("\n")).unwrap();
    let o = simulate(&dir, &hall, Some(&csv));
    assert_input_error(
        &o,
        "hall.json: /racks/0/inlet: the built-in simulator cannot place it: server `A1-01` \
         of rack `A1`: no open cell at its intake",
    );
}

/// Racks a quarter cell off the grid are moved to it, and the user hears of it with a
/// grid that places them; the development hall, on the grid, gives no warning.
#[test]
fn equipment_off_the_grid_is_warned_of_with_a_grid_that_places_it() {
    let dir = tmp("export-grid");
    let hall = edited_hall(&dir, "hall.json", |h| {
        for r in h["racks"].as_array_mut().unwrap() {
            let x = r["position_m"][0].as_f64().unwrap();
            r["position_m"][0] = serde_json::json!(x + 0.05);
        }
    });
    let o = simulate(&dir, &hall, None);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("kalibre: warning: ")
            && err.contains("20 edges of racks, CRACs, tiles or containment lie between")
            && err.contains("(the first: /racks/0/position_m, x = 2.45 m taken as 2.4 m)")
            && err.contains("--grid-m 0.05 places them as written"),
        "{err}"
    );
    let o = simulate(&dir, &data("of-dev-clean/hall.json"), None);
    assert!(
        o.status.success() && stderr(&o).is_empty(),
        "{}",
        stderr(&o)
    );
}

/// Alpha in m3/s per W passes `0 < min <= initial <= max`; the rise it implies is warned of.
#[test]
fn alpha_in_another_unit_is_warned_of() {
    let dir = tmp("export-alpha");
    let hall = edited_hall(&dir, "hall.json", |h| {
        h["server_types"][1]["alpha_cfm_per_w"] =
            serde_json::json!({ "initial": 7e-5, "min": 1e-5, "max": 1e-4 });
    });
    let o = simulate(&dir, &hall, None);
    let err = stderr(&o);
    assert!(
        err.contains("/server_types/1/alpha_cfm_per_w/initial: 7e-5 cfm/W warms the air")
            && err.contains("is it in another unit"),
        "{err}"
    );
}

/// A snapshot with every fan off says what the servers draw in readable kilowatts, not
/// with the sum's floating-point noise.
#[test]
fn the_power_of_a_snapshot_without_air_is_given_in_whole_watts() {
    let dir = tmp("export-fans");
    let text = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let mut servers = 0;
    let edited: Vec<String> = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            match (f[0], f[1]) {
                ("t0", "fan_speed") => format!("t0,fan_speed,{},0", f[2]),
                ("t0", "power_w") => {
                    servers += 1;
                    format!("t0,power_w,{},100.1", f[2])
                }
                _ => l.to_string(),
            }
        })
        .collect();
    let csv = dir.join("snapshots.csv");
    std::fs::write(&csv, edited.join("\n")).unwrap();
    let o = simulate(&dir, &data("of-dev-clean/hall.json"), Some(&csv));
    let kw = (servers as f64 * 100.1).round() / 1000.0;
    assert_input_error(&o, &format!("(the servers draw {kw} kW)"));
}

/// A calibration of the development hall on `snapshots`, of a second or two, into
/// `dir/cal`.
fn quick_calibration(dir: &Path, snapshots: &Path) -> std::process::Output {
    run(
        on_files("calibrate", &data("of-dev-clean/hall.json"), snapshots)
            .args(QUICK_CALIBRATION)
            .arg("--out")
            .arg(dir.join("cal")),
    )
}

/// The development snapshots with `convert` applied to the value of each row it picks
/// (by kind and id), written to `dir/name`.
fn edited_snapshots(
    dir: &Path,
    name: &str,
    picks: impl Fn(&str, &str) -> bool,
    convert: impl Fn(f64) -> f64,
) -> PathBuf {
    let text = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        if i > 0 && picks(f[1], f[2]) {
            let v: f64 = f[3].parse().unwrap();
            out.push_str(&format!("{},{},{},{}\n", f[0], f[1], f[2], convert(v)));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, out).unwrap();
    path
}

/// A sensor exported in Fahrenheit (its readings 45 C above the supply) and setpoints in
/// Fahrenheit are warned of, naming the file, the sensor or CRAC, and the value read as
/// Fahrenheit; the clean data give no such warning.
#[test]
fn readings_and_setpoints_in_fahrenheit_are_warned_of() {
    let dir = tmp("export-fahrenheit");
    let to_f = |c: f64| ((c * 1.8 + 32.0) * 100.0).round() / 100.0;
    let one_sensor = edited_snapshots(
        &dir,
        "one-sensor.csv",
        |kind, id| kind == "sensor_c" && id == "c-A3-hi",
        to_f,
    );
    let calibrate = |snapshots: &Path| quick_calibration(&dir, snapshots);
    let o = calibrate(&one_sensor);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = stderr(&o);
    assert!(
        said.contains(&format!(
            "kalibre: warning: {}: 3 reading(s) of sensor `c-A3-hi` lie more than 30 C (hot \
             aisle: 50 C) above the warmest running CRAC's setpoint",
            one_sensor.display()
        )) && said.contains("Read as Fahrenheit it is"),
        "{said}"
    );
    assert!(!said.contains("setpoint(s) above 45 C"), "{said}");

    let setpoints = edited_snapshots(&dir, "setpoints.csv", |kind, _| kind == "setpoint_c", to_f);
    let o = simulate(&dir, &data("of-dev-clean/hall.json"), Some(&setpoints));
    let said = stderr(&o);
    assert!(
        said.contains(&format!(
            "kalibre: warning: {}: 3 setpoint(s) above 45 C (CRAC `crac-1`)",
            setpoints.display()
        )) && said.contains("is 63.5 C; read as Fahrenheit it is 17.5 C"),
        "{said}"
    );

    let o = calibrate(&data("of-dev-clean/snapshots.csv"));
    assert!(o.status.success(), "{}", stderr(&o));
    let said = stderr(&o);
    assert!(!said.contains("Fahrenheit"), "{said}");
}

/// A sensor that reads one value in every snapshot while the conditions change (stuck,
/// or filled in by the export) is warned of, naming the file, the sensor and the value.
#[test]
fn a_stuck_sensor_is_warned_of() {
    let dir = tmp("export-stuck");
    let stuck = edited_snapshots(
        &dir,
        "stuck.csv",
        |kind, id| kind == "sensor_c" && id == "h-B4",
        |_| 22.0,
    );
    let o = quick_calibration(&dir, &stuck);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!(
            "kalibre: warning: {}: sensor `h-B4` reads 22 C in each of its 3 readings while \
             the setpoints, fans or powers change",
            stuck.display()
        )),
        "{}",
        stderr(&o)
    );
    assert_eq!(stderr(&o).matches("22 C in each").count(), 1, "one warning");
}

/// Readings missing from some snapshots (a dead sensor, an export that left it out) are
/// fitted around, and the calibration says so, naming the file and the sensor.
#[test]
fn missing_readings_are_noted() {
    let dir = tmp("export-missing");
    let text = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let kept: String = text
        .lines()
        .filter(|l| {
            !l.starts_with("t1,sensor_c,c-A3-hi,") && !l.starts_with("t2,sensor_c,c-A3-hi,")
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let path = dir.join("missing.csv");
    std::fs::write(&path, kept).unwrap();
    let o = quick_calibration(&dir, &path);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!(
            "note: {}: 2 sensor reading(s) are missing (`c-A3-hi` in 2 of 3 snapshots); the \
             calibration fits the readings there are",
            path.display()
        )),
        "{}",
        stderr(&o)
    );
}
