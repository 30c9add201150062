//! Grid consistency of containment panels (`SimConfig::containment_panel_m`).
//!
//! A one-cell-thick panel (the default) has a resistance proportional to the cell size,
//! so halving the cells lets more air through it; a panel of fixed thickness keeps its
//! resistance. The hall here draws more air through its servers than the CRAC supplies,
//! so the missing air leaks out of the hot-aisle containment and round the row ends to
//! the intakes: the path that moved the synthetic demo's row-end sensor by 3.4 C.

use kalibre_dc::hall::{
    Aisle, AlphaBounds, CalibrateSpec, Containment, ContainmentKind, Crac, Hall, Rack,
    ReturnGrille, Room, Sensor, Server, ServerType, Side, SupplyKind, Tile,
};
use kalibre_dc::sim::{SimConfig, SimMods, Simulator, Solution, WallOpening, WallSide};
use kalibre_dc::snapshots::OperatingState;

const CONTAINMENT: ([f64; 3], [f64; 3]) = ([1.8, 2.4, 0.0], [4.2, 3.6, 2.6]);

/// 6 x 6 x 2.6 m: rows A (y 1.2-2.4, inlet -y) and B (y 3.6-4.8, inlet +y) of 4 racks
/// around a hot aisle contained to the ceiling with a return above it, one floor CRAC
/// at the -x wall, a tile before each rack, cold-aisle sensors before every rack at
/// three heights (the first rack's upper one at the row end, like the demo's
/// `c-A01-17`).
fn hall() -> Hall {
    let mut racks = Vec::new();
    let mut tiles = Vec::new();
    let mut sensors = Vec::new();
    for (row, y0, inlet) in [("A", 1.2, Side::MinusY), ("B", 3.6, Side::PlusY)] {
        for i in 0..4 {
            let id = format!("{row}{:02}", i + 1);
            let x = 1.8 + 0.6 * i as f64;
            racks.push(Rack {
                id: id.clone(),
                position_m: [x, y0, 0.0],
                size_m: [0.6, 1.2, 2.0],
                inlet,
                units: 42,
                servers: (0..8)
                    .map(|s| Server {
                        id: format!("{id}-{:02}", s + 1),
                        server_type: "1u".into(),
                        u: 1 + 4 * s,
                        height_u: 4,
                        extra: None,
                    })
                    .collect(),
                extra: None,
            });
            let (tile_y, sensor_y) = if inlet == Side::MinusY {
                (y0 - 0.6, y0 - 0.1)
            } else {
                (y0 + 1.2, y0 + 1.3)
            };
            tiles.push(Tile {
                position_m: [x, tile_y],
                size_m: [0.6, 0.6],
                open_fraction: 0.35,
                extra: None,
            });
            for z in [0.5, 1.1, 1.7] {
                sensors.push(Sensor {
                    id: format!("c-{id}-{}", (z * 10.0) as u32),
                    position_m: [x + 0.3, sensor_y, z],
                    aisle: Aisle::Cold,
                    extra: None,
                });
            }
        }
    }
    Hall {
        schema: "kalibre.hall/1".into(),
        name: "grid-consistency".into(),
        room: Room {
            size_m: [6.0, 6.0, 2.6],
            extra: None,
        },
        server_types: vec![ServerType {
            id: "1u".into(),
            alpha_cfm_per_w: AlphaBounds {
                initial: 0.12,
                min: 0.01,
                max: 3.0,
                extra: None,
            },
            extra: None,
        }],
        cracs: vec![Crac {
            id: "crac-1".into(),
            position_m: [0.0, 2.1, 0.0],
            size_m: [0.8, 1.8, 2.0],
            rated_flow_m3_s: 1.2,
            supply: SupplyKind::Floor,
            extra: None,
        }],
        tiles,
        returns: vec![ReturnGrille {
            position_m: [1.8, 2.7],
            size_m: [2.4, 0.6],
            extra: None,
        }],
        racks,
        containment: vec![Containment {
            kind: ContainmentKind::HotAisle,
            min_m: CONTAINMENT.0,
            max_m: CONTAINMENT.1,
            extra: None,
        }],
        sensors,
        calibrate: CalibrateSpec::default(),
        effects: vec![],
        extra: None,
    }
}

/// 64 servers at 400 W and 0.12 cfm/W draw 1.45 m3/s; the CRAC supplies 1.2 m3/s.
fn state(hall: &Hall) -> OperatingState {
    OperatingState {
        label: "s".into(),
        setpoint_c: vec![18.0],
        fan_speed: vec![1.0],
        power_w: vec![400.0; hall.server_count()],
    }
}

/// Solves at `cell_m` with panels of `panel_m` and the given wall openings.
fn solve(hall: &Hall, cell_m: f64, panel_m: Option<f64>, mods: &SimMods) -> (Solution, Simulator) {
    let cfg = SimConfig::default()
        .with_cell_m(cell_m)
        .with_containment_panel_m(panel_m);
    let sim = Simulator::new(hall, cfg).unwrap();
    let alpha = vec![0.12; hall.server_count()];
    let sol = sim.solve_with_mods(&state(hall), &alpha, mods).unwrap();
    (sol, sim)
}

/// Air leaving the containment through each vertical side (m3/s, net; -x, +x, -y, +y).
fn leak_out(sim: &Simulator, sol: &Solution) -> [f64; 4] {
    let g = sim.grid();
    let (lo, hi) = CONTAINMENT;
    let mut out = [0.0; 4];
    for a in 0..2 {
        let t = 1 - a;
        for (side, (x, sign)) in [(lo[a], -1.0), (hi[a], 1.0)].into_iter().enumerate() {
            let f = (x / g.d[a]).round() as usize;
            for k in g.range_in(2, lo[2], hi[2]) {
                for it in g.range_in(t, lo[t], hi[t]) {
                    let mut ijk = [0; 3];
                    ijk[a] = f - 1;
                    ijk[t] = it;
                    ijk[2] = k;
                    out[2 * a + side] +=
                        sign * sol.face_flux_m3_s[a][g.idx(ijk[0], ijk[1], ijk[2])];
                }
            }
        }
    }
    out
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn fixed_panels_keep_leakage_and_readings_when_the_cells_halve() {
    let hall = hall();
    let none = SimMods::new(1);
    // Per panel model: relative change of the outflow through the two end doors, and
    // the largest sensor change, from 0.2 m to 0.1 m.
    let mut figures = Vec::new();
    for panel_m in [None, Some(0.2)] {
        let (coarse, sim_c) = solve(&hall, 0.2, panel_m, &none);
        let (fine, sim_f) = solve(&hall, 0.1, panel_m, &none);
        let (lc, lf) = (leak_out(&sim_c, &coarse), leak_out(&sim_f, &fine));
        // The air the servers draw beyond the supply leaves through the end doors.
        assert!(lc[0] > 0.05 && lc[1] > 0.05, "{panel_m:?}: leak {lc:?}");
        let dt = max_abs_diff(coarse.sensor_c(), fine.sensor_c());
        eprintln!("{panel_m:?}: door outflow 0.2 m {lc:.4?}, 0.1 m {lf:.4?}; sensors max change {dt:.3} C");
        figures.push((lf[0] / lc[0] - 1.0, lf[1] / lc[1] - 1.0, dt));
    }
    let (cell_minus, cell_plus, dt_cell) = figures[0];
    let (panel_minus, panel_plus, dt_panel) = figures[1];
    // One-cell panels leak more through the doors on the finer grid (measured +17 %).
    assert!(cell_minus > 0.1 && cell_plus > 0.1, "{figures:?}");
    // Fixed panels: within 3 % (measured -0.4 %), and the sensors move less.
    assert!(
        panel_minus.abs() < 0.03 && panel_plus.abs() < 0.03,
        "{figures:?}"
    );
    assert!(dt_panel < 0.75 * dt_cell, "{figures:?}");
}

#[test]
fn fixed_panels_at_the_cell_size_reproduce_the_default() {
    let hall = hall();
    let mut opened = SimMods::new(1);
    opened.wall_openings.push(WallOpening {
        containment: 0,
        sides: vec![WallSide::MinusX],
        open_fraction: 0.3,
    });
    for mods in [SimMods::new(1), opened] {
        let (a, _) = solve(&hall, 0.2, None, &mods);
        let (b, _) = solve(&hall, 0.2, Some(0.2), &mods);
        let d = max_abs_diff(a.sensor_c(), b.sensor_c());
        assert!(d < 1e-6, "{d}");
    }
}

#[test]
fn opened_doors_leak_alike_on_both_grids_with_fixed_panels() {
    let hall = hall();
    let mut mods = SimMods::new(1);
    mods.wall_openings.push(WallOpening {
        containment: 0,
        sides: vec![WallSide::MinusX],
        open_fraction: 0.1,
    });
    let (coarse, sim_c) = solve(&hall, 0.2, Some(0.2), &mods);
    let (fine, sim_f) = solve(&hall, 0.1, Some(0.2), &mods);
    let (lc, lf) = (leak_out(&sim_c, &coarse), leak_out(&sim_f, &fine));
    assert!((lf[0] / lc[0] - 1.0).abs() < 0.05, "leak {lc:?} -> {lf:?}");
    let d = max_abs_diff(coarse.sensor_c(), fine.sensor_c());
    assert!(d < 0.3, "{d}");
}

#[test]
fn panel_thickness_is_optional_in_files_and_checked() {
    let default_json = serde_json::to_string(&SimConfig::default()).unwrap();
    assert!(
        !default_json.contains("containment_panel_m"),
        "{default_json}"
    );
    let parsed: SimConfig = serde_json::from_str(&default_json).unwrap();
    assert_eq!(parsed, SimConfig::default());
    assert_eq!(parsed.containment_panel_m, Some(0.2));
    // One-cell panels (kalibre before 0.2 m panels) are written as null and read back.
    let with = SimConfig::default().with_containment_panel_m(None);
    let text = serde_json::to_string(&with).unwrap();
    assert!(text.contains("\"containment_panel_m\":null"), "{text}");
    assert_eq!(serde_json::from_str::<SimConfig>(&text).unwrap(), with);
    let thick = SimConfig::default().with_containment_panel_m(Some(0.3));
    let text = serde_json::to_string(&thick).unwrap();
    assert!(text.contains("\"containment_panel_m\":0.3"), "{text}");
    assert_eq!(serde_json::from_str::<SimConfig>(&text).unwrap(), thick);
    for bad in [0.0, -0.1, 5.5, f64::NAN, f64::INFINITY] {
        let err = SimConfig::default()
            .with_containment_panel_m(Some(bad))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("containment_panel_m"), "{bad}: {err}");
    }
    assert!(with.check().is_ok());
}

/// On grids the layout does not fall on, a tile's snapped footprint can reach a cell of
/// the rack it abuts (the synthetic `hall-a` at 0.16 m and 0.19 m: "tile 48 lies under a
/// rack or CRAC" until session 14). The tile then blows through its other cells with its
/// whole share, and the hall solves with energy and mass balanced.
#[test]
fn tiles_abutting_racks_solve_on_grids_their_edges_miss() {
    let hall = kalibre_dc::synth::generate_hall(&kalibre_dc::synth::SynthOptions::new(
        kalibre_dc::synth::Preset::HallA,
        1,
    ))
    .unwrap();
    let state = OperatingState {
        label: "s".into(),
        setpoint_c: vec![18.0; hall.cracs.len()],
        fan_speed: vec![1.0; hall.cracs.len()],
        power_w: vec![300.0; hall.server_count()],
    };
    for cell_m in [0.16, 0.19] {
        let sim = Simulator::new(&hall, SimConfig::default().with_cell_m(cell_m))
            .unwrap_or_else(|e| panic!("grid {cell_m} m: {e}"));
        let alpha = vec![0.15; hall.server_count()];
        let sol = sim
            .solve_with_mods(&state, &alpha, &SimMods::default())
            .unwrap();
        assert!(
            sol.energy_balance_error().abs() < 1e-4,
            "grid {cell_m} m: energy balance off by {:e}",
            sol.energy_balance_error()
        );
        let imbalance = sol.mass_imbalance_m3_s(sim.grid());
        let worst = imbalance.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(
            worst < 1e-6,
            "grid {cell_m} m: cell imbalance {worst:e} m3/s"
        );
    }
}

/// A tile that overlaps a rack's footprint is the hall's error, named by its pointer,
/// not something a grid may paper over.
#[test]
fn a_tile_under_a_rack_is_refused_by_the_hall() {
    let mut hall = hall();
    hall.tiles[0].position_m[1] += 0.3; // half of it under rack A01
    let err = hall.validate("hall.json").unwrap_err().to_string();
    assert!(
        err.contains("/tiles/0") && err.contains("lies under rack `A01`"),
        "{err}"
    );
}

/// Cells too small for the room are refused before anything is allocated: 0.5 mm cells
/// over this 6 x 6 x 2.6 m hall would be 7.5e11 of them.
#[test]
fn a_grid_too_fine_for_the_room_is_refused_by_name() {
    let hall = hall();
    let config = SimConfig::default().with_cell_m(0.0005);
    let err = Simulator::new(&hall, config).unwrap_err().to_string();
    assert!(
        err.contains("cells of 0.0005 m") && err.contains("at most 30000000"),
        "{err}"
    );
    // An ordinary grid of the same hall still builds.
    assert!(Simulator::new(&hall, SimConfig::default().with_cell_m(0.1)).is_ok());
}
