//! Tile jets: can lifting the floor supply up the cold aisle stand in for the jets'
//! momentum, which the built-in model (potential flow) does not have?
//!
//! OpenFOAM's row-end low inlets read 3-4 C warmer than the built-in model's on the
//! development halls (`docs/performance.md`, "Realism against OpenFOAM"). The tile jets
//! carry the supply upward and draw room air in along the floor; in the built-in model
//! the supply enters in the floor layer and the nearest inlets take it. This study
//! releases each tile's supply higher up the column above the tile (one forced link per
//! tile, `sim::AirLink`) and scores the built-in model against OpenFOAM at the true
//! alphas, on:
//! - two halls: the development hall (tiles 0.8 m deep, jets at 1.5 m/s) and the same
//!   hall with tiles spanning the whole 1.2 m aisle (1.0 m/s);
//! - four operating states: the development snapshots t0-t2 (fan 0.9-1.0, supply 92-104 %
//!   of the servers' draw) and t1 at fan 0.8 (83 %);
//! - two kinds of release: a fixed lift, and (session 28) a jet consumed from below;
//! - the 24 development sensors, and 27 probes: three columns of seven heights in front
//!   of racks A1, A3 and A5, and three heights at each end of the cold aisle.
//!
//! `cargo run --release --example tile_jet_study -- [--work DIR] [--np N] [--out FILE]`
//! (run from the workspace root; OpenFOAM on the PATH; 8 OpenFOAM solves of about 10-30 s,
//! cached in `--work`, default `out/tile_jet_study/`; `--out` default
//! `docs/results/tile_jet_study.json`).

use std::path::{Path, PathBuf};

use kalibre::dc::openfoam::{OpenFoamModel, OpenFoamSettings};
use kalibre_core::Model;
use kalibre_dc::hall::{Aabb, Hall};
use kalibre_dc::sim::{jets, tile_flows_m3_s, AirLink, SimConfig, SimMods, Simulator};
use kalibre_dc::snapshots::{load_snapshots, OperatingState};
use serde_json::{json, Value};

/// The development data this study starts from.
const DEV: &str = "data/openfoam/of-dev-clean";

/// Where a rule releases each tile's supply.
#[derive(Clone, Copy)]
enum Release {
    /// The model's own floor injection.
    Floor,
    /// A link takes the supply's flow from the tile's cells up to `from_top_m` and
    /// releases it over `to_bottom_m` to `to_top_m` (`None`: the tallest rack's height).
    Lift {
        from_top_m: f64,
        to_bottom_m: f64,
        to_top_m: Option<f64>,
    },
    /// A jet consumed from below (session 28): from this height up, each band releases
    /// what the facing racks' intakes draw there, until the tile's supply runs out; what
    /// is left rises over the racks (released in the 0.4 m above the tallest rack).
    DrawMatched { from_m: f64 },
}

struct Rule {
    name: &'static str,
    release: Release,
}

fn rules() -> Vec<Rule> {
    let lift = |from_top_m, to_bottom_m, to_top_m| Release::Lift {
        from_top_m,
        to_bottom_m,
        to_top_m,
    };
    let draw_matched = |from_m| Release::DrawMatched { from_m };
    [
        ("floor (the model)", Release::Floor),
        ("0-rack top", lift(0.2, 0.0, None)),
        ("0.2 m-rack top", lift(0.2, 0.2, None)),
        ("0.4 m-rack top", lift(0.2, 0.4, None)),
        ("0.8-1.6 m (from 0-0.4 m)", lift(0.4, 0.8, Some(1.6))),
        ("draw-matched from 0 m", draw_matched(0.0)),
        ("draw-matched from 0.2 m", draw_matched(0.2)),
        ("draw-matched from 0.4 m", draw_matched(0.4)),
    ]
    .into_iter()
    .map(|(name, release)| Rule { name, release })
    .collect()
}

/// The development hall, or the variant with tiles spanning the cold aisle, with probes.
fn hall_variant(name: &str) -> Result<Value, String> {
    let text = std::fs::read_to_string(Path::new(DEV).join("hall.json"))
        .map_err(|e| format!("{DEV}/hall.json: {e}"))?;
    let mut h: Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    h["name"] = json!(format!("jet-study-{name}"));
    if name == "wide tiles" {
        for t in h["tiles"].as_array_mut().ok_or("hall.json: no tiles")? {
            t["position_m"][1] = json!(1.8);
            t["size_m"][1] = json!(1.2);
        }
    }
    let sensors = h["sensors"].as_array_mut().ok_or("hall.json: no sensors")?;
    for x in [2.7, 3.9, 5.1] {
        for z in [0.3, 0.7, 0.9, 1.1, 1.3, 1.5, 1.9] {
            sensors.push(
                json!({"id": format!("p-{x}-{z}"), "position_m": [x, 1.9, z], "aisle": "cold"}),
            );
        }
    }
    for x in [2.1, 5.7] {
        for z in [0.3, 1.1, 1.7] {
            sensors.push(
                json!({"id": format!("end-{x}-{z}"), "position_m": [x, 2.5, z], "aisle": "cold"}),
            );
        }
    }
    Ok(h)
}

/// The true alpha (cfm/W) of the development data's server types.
fn true_alpha(server_type: &str) -> f64 {
    match server_type {
        "web" => 0.13,
        "db" => 0.17,
        _ => 0.12,
    }
}

/// One forced link per tile lifting its share of the supply, for `state`.
fn lifted_supply(
    hall: &Hall,
    state: &OperatingState,
    from_top_m: f64,
    to_bottom_m: f64,
    to_top_m: Option<f64>,
) -> SimMods {
    let rack_top_m = hall.racks.iter().map(|r| r.size_m[2]).fold(0.0, f64::max);
    let tile_flow_m3_s = tile_flows_m3_s(hall, state, 0.0);
    let mut mods = SimMods::new(hall.cracs.len());
    for (t, flow_m3_s) in hall.tiles.iter().zip(tile_flow_m3_s) {
        let ([x, y], [sx, sy]) = (t.position_m, t.size_m);
        mods.air_links.push(AirLink {
            from: Aabb {
                min: [x, y, 0.0],
                max: [x + sx, y + sy, from_top_m],
            },
            to: Aabb {
                min: [x, y, to_bottom_m],
                max: [x + sx, y + sy, to_top_m.unwrap_or(rack_top_m)],
            },
            flow_m3_s,
        });
    }
    mods
}

/// The jet consumed from below ([`jets::draw_matched_links`]) as a run's modifications.
fn draw_matched_supply(hall: &Hall, state: &OperatingState, alpha: &[f64], from_m: f64) -> SimMods {
    let mut mods = SimMods::new(hall.cracs.len());
    mods.air_links = jets::draw_matched_links(hall, state, alpha, from_m, 0.0);
    mods
}

struct Options {
    work: PathBuf,
    out: PathBuf,
    np: u32,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        work: PathBuf::from("out/tile_jet_study"),
        out: PathBuf::from("docs/results/tile_jet_study.json"),
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

fn run(o: &Options) -> Result<(), String> {
    std::fs::create_dir_all(&o.work).map_err(|e| format!("{}: {e}", o.work.display()))?;
    let work = std::fs::canonicalize(&o.work).map_err(|e| e.to_string())?;
    let settings = OpenFoamSettings::default()
        .with_np(o.np)
        .with_cache_root(work.join("openfoam-cases"))
        .check()
        .map_err(|e| e.to_string())?;
    let mut results = Vec::new();
    println!("| hall | supply released | t0 | t1 | t2 | t1, fan 0.8 | probes, all states |");
    println!("|---|---|---|---|---|---|---|");
    for variant in ["development", "wide tiles"] {
        let path = work.join(format!("{}.json", variant.replace(' ', "-")));
        let doc =
            serde_json::to_string_pretty(&hall_variant(variant)?).map_err(|e| e.to_string())?;
        std::fs::write(&path, doc).map_err(|e| format!("{}: {e}", path.display()))?;
        let hall = Hall::load(&path).map_err(|e| e.to_string())?;
        let snaps = load_snapshots(&hall, &Path::new(DEV).join("snapshots.csv"))
            .map_err(|e| e.to_string())?;
        let mut states: Vec<OperatingState> = snaps.iter().map(|s| s.state.clone()).collect();
        let mut low_fan = states[1].clone();
        low_fan.label = "t1-fan0.8".into();
        low_fan.fan_speed = vec![0.8; hall.cracs.len()];
        states.push(low_fan);
        let alpha: Vec<f64> = hall
            .servers()
            .map(|s| true_alpha(&s.server.server_type))
            .collect();
        let model = OpenFoamModel::new(&hall, settings.clone()).map_err(|e| e.to_string())?;
        let space = model.layout().space();
        let params: Vec<f64> = space
            .names()
            .iter()
            .zip(space.initial())
            .map(|(n, init)| n.strip_prefix("alpha/").map_or(init, true_alpha))
            .collect();
        let openfoam: Vec<Vec<f64>> = states
            .iter()
            .map(|s| {
                eprintln!("  {variant} {}: OpenFOAM", s.label);
                model
                    .evaluate(s, &params)
                    .map(|r| r.values)
                    .map_err(|e| format!("{variant}, {}: {e}", s.label))
            })
            .collect::<Result<_, _>>()?;
        let sim = Simulator::new(&hall, SimConfig::default()).map_err(|e| e.to_string())?;
        let is_probe: Vec<bool> = hall
            .sensors
            .iter()
            .map(|s| !s.id.starts_with(['c', 'h']))
            .collect();
        for rule in rules() {
            let mut dev_mae = Vec::new();
            let (mut probe_sum, mut probe_n) = (0.0, 0.0);
            let mut columns = Vec::new();
            for (state, of) in states.iter().zip(&openfoam) {
                let mods = match rule.release {
                    Release::Floor => SimMods::new(hall.cracs.len()),
                    Release::Lift {
                        from_top_m,
                        to_bottom_m,
                        to_top_m,
                    } => lifted_supply(&hall, state, from_top_m, to_bottom_m, to_top_m),
                    Release::DrawMatched { from_m } => {
                        draw_matched_supply(&hall, state, &alpha, from_m)
                    }
                };
                let sol = sim
                    .solve_with_mods(state, &alpha, &mods)
                    .map_err(|e| e.to_string())?;
                let (mut dev_sum, mut dev_n) = (0.0, 0.0);
                let mut column = serde_json::Map::new();
                for (i, (p, t)) in sol.sensor_c().iter().zip(of).enumerate() {
                    if is_probe[i] {
                        probe_sum += (p - t).abs();
                        probe_n += 1.0;
                        column.insert(hall.sensors[i].id.clone(), json!([p, t]));
                    } else {
                        dev_sum += (p - t).abs();
                        dev_n += 1.0;
                    }
                }
                dev_mae.push(dev_sum / dev_n);
                columns.push(json!({"state": state.label, "probes_model_openfoam_c": column}));
            }
            let cells: Vec<String> = dev_mae.iter().map(|m| format!("{m:.2}")).collect();
            println!(
                "| {variant} | {} | {} | {:.2} |",
                rule.name,
                cells.join(" | "),
                probe_sum / probe_n
            );
            results.push(json!({
                "hall": variant,
                "supply_released": rule.name,
                "dev_sensor_mae_c": states.iter().map(|s| s.label.clone()).zip(dev_mae.iter().map(|m| json!(m))).collect::<serde_json::Map<_, _>>(),
                "probe_mae_c": probe_sum / probe_n,
                "states": columns,
            }));
        }
    }
    let doc = json!({
        "what": "built-in model against OpenFOAM at the true alphas, with each tile's supply released as the rule says",
        "results": results,
    });
    let text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
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
