//! Front-supply CRACs: how far is the built-in model (potential flow, no momentum or
//! buoyancy) from OpenFOAM where the supply blows through a CRAC's face?
//!
//! Four halls of 40 servers in two rows of four racks with two `front` CRACs (24 kW),
//! either at the aisle ends blowing down the cold aisle or on the wall behind a row
//! blowing at its back, each with ceiling grilles over the hot aisles and without (the
//! CRACs then draw at their tops); four held out of the choice of how the built-in model
//! releases a front CRAC's supply (the aisle ends at half the fan speed, and one row
//! facing its CRAC across the cold aisle, each with grilles and without); and, for scale,
//! the development hall (floor supply) with and without its grilles. One snapshot each, at the halls' initial alphas, on the
//! 0.2 m grid: the MAE of the built-in model's readings against OpenFOAM's, by aisle,
//! and the hottest server intake of each (docs/models.md, "Front-supply CRACs and halls
//! without grilles").
//!
//! `cargo run --release --example front_supply_study -- [--work DIR] [--np N] [--out FILE]
//! [--openfoam-from FILE]` (run from the workspace root; OpenFOAM on the PATH; 10 solves of
//! about 15 s with `--np 2`, meshed in `--work`, default `out/front_supply_study/`;
//! `--out` default `docs/results/front_supply_study.json`). `--openfoam-from` takes
//! OpenFOAM's readings from an earlier run's JSON instead of solving again, to score a
//! change to the built-in model against them.

use std::path::PathBuf;

use kalibre::dc::openfoam::{OpenFoamModel, OpenFoamSettings, SERVER_INTAKE_KEY};
use kalibre_core::Model;
use kalibre_dc::hall::{Aisle, Hall};
use kalibre_dc::sim::{server_air, SimConfig};
use kalibre_dc::snapshots::{load_snapshots, OperatingState};
use kalibre_dc::HallModel;
use serde_json::{json, Value};

/// The development data the two floor-supply halls are.
const DEV: &str = "data/openfoam/of-dev-clean";

/// Where the `front` CRACs stand.
#[derive(Clone, Copy, PartialEq)]
enum Layout {
    /// Two, at both ends of the cold aisle, blowing down it.
    AisleEnds,
    /// Two, on the wall behind row B, blowing at its back.
    BehindRow,
    /// One row of six racks facing one CRAC on the wall across its cold aisle (held out
    /// of the choice of the jet release: not among the halls it was first measured on).
    SingleRow,
}

/// A front-supply hall: rows A (y 1.2-2.4, drawing from +y) and B (y 3.6-4.8, from -y)
/// of four 40U racks with five 8U servers each, three sensors per rack (cold aisle at
/// 0.5 and 1.7 m, its hot aisle at 1.5 m), grilles over both hot aisles when `grilles`.
fn front_hall(layout: Layout, grilles: bool) -> Value {
    if layout == Layout::SingleRow {
        return single_row_hall(grilles);
    }
    let (room_y, cracs) = match layout {
        Layout::AisleEnds => (
            6.0,
            json!([
                {"id": "crac-w", "position_m": [0.0, 2.2, 0.0], "size_m": [0.8, 1.6, 2.0],
                 "rated_flow_m3_s": 1.5, "supply": "front"},
                {"id": "crac-e", "position_m": [6.4, 2.2, 0.0], "size_m": [0.8, 1.6, 2.0],
                 "rated_flow_m3_s": 1.5, "supply": "front"}
            ]),
        ),
        _ => (
            7.2,
            json!([
                {"id": "crac-n1", "position_m": [1.6, 6.4, 0.0], "size_m": [1.6, 0.8, 2.0],
                 "rated_flow_m3_s": 1.5, "supply": "front"},
                {"id": "crac-n2", "position_m": [4.0, 6.4, 0.0], "size_m": [1.6, 0.8, 2.0],
                 "rated_flow_m3_s": 1.5, "supply": "front"}
            ]),
        ),
    };
    let mut racks = Vec::new();
    let mut sensors = Vec::new();
    for (row, y, inlet) in [("A", 1.2, "+y"), ("B", 3.6, "-y")] {
        for i in 0..4 {
            let x = 2.4 + 0.6 * i as f64;
            let id = format!("{row}{}", i + 1);
            racks.push(rack(&id, x, y, inlet, |k| {
                if (i + k) % 2 == 0 {
                    "web"
                } else {
                    "db"
                }
            }));
            let (cold_y, hot_y) = if inlet == "+y" {
                (y + 1.3, y - 0.3)
            } else {
                (y - 0.1, y + 1.5)
            };
            sensors.extend(rack_sensors(&id, x, cold_y, hot_y));
        }
    }
    let mut hall = study_hall(7.2, room_y, cracs, racks, sensors);
    if grilles {
        let far_y = if layout == Layout::AisleEnds {
            room_y - 1.0
        } else {
            5.2
        };
        hall["returns"] = json!([
            {"position_m": [2.4, 0.2], "size_m": [2.4, 0.6]},
            {"position_m": [2.4, far_y], "size_m": [2.4, 0.6]}
        ]);
    }
    hall
}

/// A 40U rack of five 8U servers of `server_type(k)`.
fn rack(
    id: &str,
    x: f64,
    y: f64,
    inlet: &str,
    server_type: impl Fn(usize) -> &'static str,
) -> Value {
    let servers: Vec<Value> = (0..5)
        .map(|k| {
            json!({"id": format!("{id}-{}", k + 1), "type": server_type(k),
                   "u": 1 + 8 * k, "height_u": 8})
        })
        .collect();
    json!({"id": id, "position_m": [x, y, 0.0], "size_m": [0.6, 1.2, 2.0],
           "inlet": inlet, "units": 40, "servers": servers})
}

/// A rack's three sensors: its cold aisle at 0.5 and 1.7 m, its hot aisle at 1.5 m.
fn rack_sensors(id: &str, x: f64, cold_y: f64, hot_y: f64) -> [Value; 3] {
    let at = |y: f64, z: f64| json!([x + 0.3, y, z]);
    [
        json!({"id": format!("c-{id}-lo"), "position_m": at(cold_y, 0.5), "aisle": "cold"}),
        json!({"id": format!("c-{id}-hi"), "position_m": at(cold_y, 1.7), "aisle": "cold"}),
        json!({"id": format!("h-{id}"), "position_m": at(hot_y, 1.5), "aisle": "hot"}),
    ]
}

/// The study's hall document, 3 m high, with its two server types.
fn study_hall(x_m: f64, y_m: f64, cracs: Value, racks: Vec<Value>, sensors: Vec<Value>) -> Value {
    json!({
        "schema": "kalibre.hall/1",
        "name": "front-supply study",
        "room": {"size_m": [x_m, y_m, 3.0]},
        "server_types": [
            {"id": "web", "alpha_cfm_per_w": {"initial": 0.12, "min": 0.03, "max": 0.4}},
            {"id": "db", "alpha_cfm_per_w": {"initial": 0.15, "min": 0.03, "max": 0.4}}
        ],
        "cracs": cracs,
        "racks": racks,
        "sensors": sensors,
    })
}

/// Six racks (y 3.0-4.2) drawing from -y, facing one CRAC on the y = 0 wall across their
/// cold aisle; a grille over the hot aisle behind them when `grilles`.
fn single_row_hall(grilles: bool) -> Value {
    let cracs = json!([{"id": "crac-s", "position_m": [2.4, 0.0, 0.0], "size_m": [2.4, 0.8, 2.0],
                        "rated_flow_m3_s": 1.6, "supply": "front"}]);
    let mut racks = Vec::new();
    let mut sensors = Vec::new();
    for i in 0..6 {
        let x = 1.8 + 0.6 * i as f64;
        let id = format!("A{}", i + 1);
        racks.push(rack(&id, x, 3.0, "-y", |_| "web"));
        sensors.extend(rack_sensors(&id, x, 2.9, 4.5));
    }
    let mut hall = study_hall(7.2, 6.0, cracs, racks, sensors);
    if grilles {
        hall["returns"] = json!([{"position_m": [1.8, 4.6], "size_m": [3.6, 0.6]}]);
    }
    hall
}

/// One snapshot: setpoints 18 C, fans at `fan`, servers at 450, 550 or 650 W in turn.
fn front_state(hall: &Hall, fan: f64) -> OperatingState {
    OperatingState {
        label: "t0".into(),
        setpoint_c: vec![18.0; hall.cracs.len()],
        fan_speed: vec![fan; hall.cracs.len()],
        power_w: (0..hall.server_count())
            .map(|i| [450.0, 550.0, 650.0][i % 3])
            .collect(),
    }
}

struct Options {
    work: PathBuf,
    out: PathBuf,
    np: u32,
    openfoam_from: Option<PathBuf>,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        work: PathBuf::from("out/front_supply_study"),
        out: PathBuf::from("docs/results/front_supply_study.json"),
        np: 1,
        openfoam_from: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args.next().ok_or(format!("{flag}: missing value"))?;
        match flag.as_str() {
            "--work" => o.work = PathBuf::from(value),
            "--out" => o.out = PathBuf::from(value),
            "--openfoam-from" => o.openfoam_from = Some(PathBuf::from(value)),
            "--np" => {
                o.np = value
                    .parse()
                    .map_err(|_| format!("--np: not a count: {value}"))?
            }
            _ => {
                return Err(format!(
                    "unknown argument `{flag}` (use --work DIR, --out FILE, --np N, \
                     --openfoam-from FILE)"
                ))
            }
        }
    }
    Ok(o)
}

/// Mean of `v` (NaN when empty).
fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn run(o: &Options) -> Result<(), String> {
    std::fs::create_dir_all(&o.work).map_err(|e| format!("{}: {e}", o.work.display()))?;
    let work = std::fs::canonicalize(&o.work).map_err(|e| e.to_string())?;
    let settings = OpenFoamSettings::default()
        .with_np(o.np)
        .with_cache_root(work.join("openfoam-cases"))
        .check()
        .map_err(|e| e.to_string())?;
    let stored: Option<Value> = match &o.openfoam_from {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
            Some(serde_json::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))?)
        }
        None => None,
    };
    let dev_text = std::fs::read_to_string(format!("{DEV}/hall.json"))
        .map_err(|e| format!("{DEV}/hall.json: {e}"))?;
    let dev: Value = serde_json::from_str(&dev_text).map_err(|e| e.to_string())?;
    let mut dev_bare = dev.clone();
    dev_bare.as_object_mut().map(|d| d.remove("returns"));
    // (name, hall, fan speed; none: the development data's first snapshot).
    let halls = [
        (
            "CRACs at the aisle ends, grilles",
            front_hall(Layout::AisleEnds, true),
            Some(0.8),
        ),
        (
            "CRACs at the aisle ends, no grilles",
            front_hall(Layout::AisleEnds, false),
            Some(0.8),
        ),
        (
            "CRACs behind a row, grilles",
            front_hall(Layout::BehindRow, true),
            Some(0.8),
        ),
        (
            "CRACs behind a row, no grilles",
            front_hall(Layout::BehindRow, false),
            Some(0.8),
        ),
        (
            "held out: aisle ends, fans 0.5, grilles",
            front_hall(Layout::AisleEnds, true),
            Some(0.5),
        ),
        (
            "held out: aisle ends, fans 0.5, no grilles",
            front_hall(Layout::AisleEnds, false),
            Some(0.5),
        ),
        (
            "held out: one row facing its CRAC, grilles",
            front_hall(Layout::SingleRow, true),
            Some(0.8),
        ),
        (
            "held out: one row facing its CRAC, no grilles",
            front_hall(Layout::SingleRow, false),
            Some(0.8),
        ),
        ("development hall (floor supply), grilles", dev, None),
        (
            "development hall (floor supply), no grilles",
            dev_bare,
            None,
        ),
    ];
    println!("| hall | MAE | cold aisle (bias) | hot aisle (bias) | hottest intake, built-in / OpenFOAM |");
    println!("|---|---|---|---|---|");
    let mut results = Vec::new();
    for (name, doc, fan) in halls {
        let text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
        let hall = Hall::from_json_str(&text, name).map_err(|e| e.to_string())?;
        let state = match fan {
            Some(fan) => front_state(&hall, fan),
            None => {
                let snaps = load_snapshots(&hall, &PathBuf::from(DEV).join("snapshots.csv"))
                    .map_err(|e| e.to_string())?;
                snaps[0].state.clone()
            }
        };
        let builtin = HallModel::new(&hall, SimConfig::default()).map_err(|e| e.to_string())?;
        let params = builtin.layout().space().initial();
        let solution = builtin
            .solve(&state, &params)
            .map_err(|e| format!("{name}: built-in: {e}"))?;
        let ours = solution.sensor_c().to_vec();
        let hottest_ours = server_air(&hall, &state, &solution)
            .map_err(|e| format!("{name}: server air: {e}"))?
            .iter()
            .map(|s| s.intake_c)
            .fold(f64::NEG_INFINITY, f64::max);
        let (theirs, hottest_theirs) = match &stored {
            Some(doc) => {
                let h = doc["halls"]
                    .as_array()
                    .and_then(|hs| hs.iter().find(|h| h["hall"] == name))
                    .ok_or(format!("{name}: not in --openfoam-from"))?;
                let values: Vec<f64> = h["openfoam_c"]
                    .as_array()
                    .ok_or(format!("{name}: no openfoam_c in --openfoam-from"))?
                    .iter()
                    .filter_map(Value::as_f64)
                    .collect();
                let hottest = h["hottest_intake_openfoam_c"]
                    .as_f64()
                    .ok_or(format!("{name}: no hottest intake in --openfoam-from"))?;
                (values, hottest)
            }
            None => {
                eprintln!("  {name}: OpenFOAM");
                let openfoam =
                    OpenFoamModel::new(&hall, settings.clone()).map_err(|e| e.to_string())?;
                let run = openfoam
                    .evaluate(&state, &params)
                    .map_err(|e| format!("{name}: OpenFOAM: {e}"))?;
                let hottest = run
                    .extras
                    .get(SERVER_INTAKE_KEY)
                    .ok_or(format!("{name}: OpenFOAM gave no server intakes"))?
                    .iter()
                    .copied()
                    .fold(f64::NEG_INFINITY, f64::max);
                (run.values, hottest)
            }
        };
        if theirs.len() != ours.len() {
            return Err(format!(
                "{name}: {} OpenFOAM readings for {} sensors",
                theirs.len(),
                ours.len()
            ));
        }
        let by = |aisle: Option<Aisle>| -> (f64, f64) {
            let d: Vec<f64> = hall
                .sensors
                .iter()
                .zip(ours.iter().zip(&theirs))
                .filter(|(s, _)| aisle.is_none_or(|a| s.aisle == a))
                .map(|(_, (a, b))| a - b)
                .collect();
            (
                mean(&d.iter().map(|x| x.abs()).collect::<Vec<_>>()),
                mean(&d),
            )
        };
        let ((all, _), (cold, cold_bias), (hot, hot_bias)) =
            (by(None), by(Some(Aisle::Cold)), by(Some(Aisle::Hot)));
        println!(
            "| {name} | {all:.2} | {cold:.2} ({cold_bias:+.2}) | {hot:.2} ({hot_bias:+.2}) | \
             {hottest_ours:.1} / {hottest_theirs:.1} C |"
        );
        results.push(json!({
            "hall": name, "mae_c": all, "cold_mae_c": cold, "cold_bias_c": cold_bias,
            "hot_mae_c": hot, "hot_bias_c": hot_bias,
            "hottest_intake_builtin_c": hottest_ours, "hottest_intake_openfoam_c": hottest_theirs,
            "builtin_c": ours, "openfoam_c": theirs,
        }));
    }
    if let Some(dir) = o.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(&json!({"study": "front_supply", "halls": results}))
        .map_err(|e| e.to_string())?;
    std::fs::write(&o.out, text).map_err(|e| format!("{}: {e}", o.out.display()))?;
    println!("\nwrote {}", o.out.display());
    Ok(())
}

fn main() {
    if let Err(e) = parse_args().and_then(|o| run(&o)) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
