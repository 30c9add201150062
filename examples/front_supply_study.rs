//! Front-supply CRACs: how far is the built-in model (potential flow, no momentum or
//! buoyancy) from OpenFOAM where the supply blows through a CRAC's face?
//!
//! Four halls of 40 servers in two rows of four racks with two `front` CRACs (24 kW),
//! either at the aisle ends blowing down the cold aisle or on the wall behind a row
//! blowing at its back, each with ceiling grilles over the hot aisles and without (the
//! CRACs then draw at their tops); and, for scale, the development hall (floor supply)
//! with and without its grilles. One snapshot each, at the halls' initial alphas, on the
//! 0.2 m grid: the MAE of the built-in model's readings against OpenFOAM's, by aisle,
//! and the hottest server intake of each (docs/models.md, "Front-supply CRACs and halls
//! without grilles").
//!
//! `cargo run --release --example front_supply_study -- [--work DIR] [--np N] [--out FILE]`
//! (run from the workspace root; OpenFOAM on the PATH; 6 solves of about 15 s with
//! `--np 2`, cached in `--work`, default `out/front_supply_study/`; `--out` default
//! `docs/results/front_supply_study.json`).

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

/// Where the two `front` CRACs stand.
#[derive(Clone, Copy, PartialEq)]
enum Layout {
    /// At both ends of the cold aisle, blowing down it.
    AisleEnds,
    /// On the wall behind row B, blowing at its back.
    BehindRow,
}

/// A front-supply hall: rows A (y 1.2-2.4, drawing from +y) and B (y 3.6-4.8, from -y)
/// of four 40U racks with five 8U servers each, three sensors per rack (cold aisle at
/// 0.5 and 1.7 m, its hot aisle at 1.5 m), grilles over both hot aisles when `grilles`.
fn front_hall(layout: Layout, grilles: bool) -> Value {
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
        Layout::BehindRow => (
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
            let servers: Vec<Value> = (0..5)
                .map(|k| {
                    json!({"id": format!("{id}-{}", k + 1),
                           "type": if (i + k) % 2 == 0 { "web" } else { "db" },
                           "u": 1 + 8 * k, "height_u": 8})
                })
                .collect();
            racks.push(
                json!({"id": id, "position_m": [x, y, 0.0], "size_m": [0.6, 1.2, 2.0],
                              "inlet": inlet, "units": 40, "servers": servers}),
            );
            let (cold_y, hot_y) = if inlet == "+y" {
                (y + 1.3, y - 0.3)
            } else {
                (y - 0.1, y + 1.5)
            };
            let at = |y: f64, z: f64| json!([x + 0.3, y, z]);
            sensors.push(
                json!({"id": format!("c-{id}-lo"), "position_m": at(cold_y, 0.5), "aisle": "cold"}),
            );
            sensors.push(
                json!({"id": format!("c-{id}-hi"), "position_m": at(cold_y, 1.7), "aisle": "cold"}),
            );
            sensors.push(
                json!({"id": format!("h-{id}"), "position_m": at(hot_y, 1.5), "aisle": "hot"}),
            );
        }
    }
    let mut hall = json!({
        "schema": "kalibre.hall/1",
        "name": "front-supply study",
        "room": {"size_m": [7.2, room_y, 3.0]},
        "server_types": [
            {"id": "web", "alpha_cfm_per_w": {"initial": 0.12, "min": 0.03, "max": 0.4}},
            {"id": "db", "alpha_cfm_per_w": {"initial": 0.15, "min": 0.03, "max": 0.4}}
        ],
        "cracs": cracs,
        "racks": racks,
        "sensors": sensors,
    });
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

/// One snapshot: setpoints 18 C, fans at 0.8, servers at 450, 550 or 650 W in turn.
fn front_state(hall: &Hall) -> OperatingState {
    OperatingState {
        label: "t0".into(),
        setpoint_c: vec![18.0; hall.cracs.len()],
        fan_speed: vec![0.8; hall.cracs.len()],
        power_w: (0..hall.server_count())
            .map(|i| [450.0, 550.0, 650.0][i % 3])
            .collect(),
    }
}

struct Options {
    work: PathBuf,
    out: PathBuf,
    np: u32,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        work: PathBuf::from("out/front_supply_study"),
        out: PathBuf::from("docs/results/front_supply_study.json"),
        np: 1,
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args.next().ok_or(format!("{flag}: missing value"))?;
        match flag.as_str() {
            "--work" => o.work = PathBuf::from(value),
            "--out" => o.out = PathBuf::from(value),
            "--np" => {
                o.np = value
                    .parse()
                    .map_err(|_| format!("--np: not a count: {value}"))?
            }
            _ => {
                return Err(format!(
                    "unknown argument `{flag}` (use --work DIR, --out FILE, --np N)"
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
    let dev_text = std::fs::read_to_string(format!("{DEV}/hall.json"))
        .map_err(|e| format!("{DEV}/hall.json: {e}"))?;
    let dev: Value = serde_json::from_str(&dev_text).map_err(|e| e.to_string())?;
    let mut dev_bare = dev.clone();
    dev_bare.as_object_mut().map(|d| d.remove("returns"));
    let halls = [
        (
            "CRACs at the aisle ends, grilles",
            front_hall(Layout::AisleEnds, true),
        ),
        (
            "CRACs at the aisle ends, no grilles",
            front_hall(Layout::AisleEnds, false),
        ),
        (
            "CRACs behind a row, grilles",
            front_hall(Layout::BehindRow, true),
        ),
        (
            "CRACs behind a row, no grilles",
            front_hall(Layout::BehindRow, false),
        ),
        ("development hall (floor supply), grilles", dev),
        ("development hall (floor supply), no grilles", dev_bare),
    ];
    println!("| hall | MAE | cold aisle (bias) | hot aisle (bias) | hottest intake, built-in / OpenFOAM |");
    println!("|---|---|---|---|---|");
    let mut results = Vec::new();
    for (name, doc) in halls {
        let text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
        let hall = Hall::from_json_str(&text, name).map_err(|e| e.to_string())?;
        let state = if name.starts_with("development") {
            let snaps = load_snapshots(&hall, &PathBuf::from(DEV).join("snapshots.csv"))
                .map_err(|e| e.to_string())?;
            snaps[0].state.clone()
        } else {
            front_state(&hall)
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
        eprintln!("  {name}: OpenFOAM");
        let openfoam = OpenFoamModel::new(&hall, settings.clone()).map_err(|e| e.to_string())?;
        let run = openfoam
            .evaluate(&state, &params)
            .map_err(|e| format!("{name}: OpenFOAM: {e}"))?;
        let hottest_theirs = run
            .extras
            .get(SERVER_INTAKE_KEY)
            .ok_or(format!("{name}: OpenFOAM gave no server intakes"))?
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let theirs = run.values;
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
