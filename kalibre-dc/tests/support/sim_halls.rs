//! Halls built in code for the simulator's physics tests and benchmark (shared through
//! `#[path]`): a demo-sized hall (two rows, 308 servers, 4 CRACs, 24 sensors) and a
//! hall-a-sized one (8 rows with hot-aisle containment, 2,240 servers, 10 CRACs).
#![allow(dead_code)]

use kalibre_dc::hall::{
    Aisle, AlphaBounds, CalibrateSpec, Containment, ContainmentKind, Crac, Hall, Rack,
    ReturnGrille, Room, Sensor, Server, ServerType, Side, SupplyKind, Tile,
};
use kalibre_dc::snapshots::OperatingState;

/// A rack row: racks along x from `x0`, `count` racks of 0.6 m, depth 1.2 m at `y0`.
pub struct Row {
    pub name: &'static str,
    pub x0: f64,
    pub count: usize,
    pub y0: f64,
    pub inlet: Side,
}

fn server_types() -> Vec<ServerType> {
    ["1u-compute", "2u-storage", "gpu"]
        .iter()
        .map(|id| ServerType {
            id: id.to_string(),
            alpha_cfm_per_w: AlphaBounds {
                initial: 0.12,
                min: 0.01,
                max: 3.0,
                extra: None,
            },
            extra: None,
        })
        .collect()
}

fn racks(rows: &[Row], servers_per_rack: u32, height_u: u32) -> Vec<Rack> {
    let mut out = Vec::new();
    for row in rows {
        for r in 0..row.count {
            let id = format!("{}{:02}", row.name, r + 1);
            let servers = (0..servers_per_rack)
                .map(|s| Server {
                    id: format!("{id}-{:02}", s + 1),
                    server_type: ["1u-compute", "2u-storage", "gpu"][(s as usize + r) % 3]
                        .to_string(),
                    u: 1 + s * height_u,
                    height_u,
                    extra: None,
                })
                .collect();
            out.push(Rack {
                id,
                position_m: [row.x0 + 0.6 * r as f64, row.y0, 0.0],
                size_m: [0.6, 1.2, 2.0],
                inlet: row.inlet,
                units: 42,
                servers,
                extra: None,
            });
        }
    }
    out
}

/// Sensors in front of (cold) and behind (hot) every `step`-th rack of each row.
fn sensors(rows: &[Row], step: usize, zs: &[f64]) -> Vec<Sensor> {
    let mut out = Vec::new();
    for row in rows {
        let (_, sign) = row.inlet.axis_sign();
        let (y_in, y_out) = if sign > 0.0 {
            (row.y0 + 1.3, row.y0 - 0.3)
        } else {
            (row.y0 - 0.1, row.y0 + 1.5)
        };
        for r in (step / 2..row.count).step_by(step) {
            let x = row.x0 + 0.6 * r as f64 + 0.3;
            for (zi, z) in zs.iter().enumerate() {
                out.push(Sensor {
                    id: format!("c-{}{:02}-{zi}", row.name, r + 1),
                    position_m: [x, y_in, *z],
                    aisle: Aisle::Cold,
                    extra: None,
                });
                out.push(Sensor {
                    id: format!("h-{}{:02}-{zi}", row.name, r + 1),
                    position_m: [x, y_out, *z],
                    aisle: Aisle::Hot,
                    extra: None,
                });
            }
        }
    }
    out
}

fn crac(id: &str, x: f64, y: f64, rated: f64) -> Crac {
    Crac {
        id: id.into(),
        position_m: [x, y, 0.0],
        size_m: [0.9, 1.8, 2.0],
        rated_flow_m3_s: rated,
        supply: SupplyKind::Floor,
        extra: None,
    }
}

/// Demo-sized hall: 12 x 8.4 x 3 m, rows A (inlet +y) and B (inlet -y) of 14 racks with
/// 11 servers each, a cold aisle with 14 tiles between them, returns over both hot
/// aisles, 4 floor CRACs, 24 sensors.
pub fn demo_hall() -> Hall {
    let rows = [
        Row {
            name: "A",
            x0: 1.8,
            count: 14,
            y0: 1.8,
            inlet: Side::PlusY,
        },
        Row {
            name: "B",
            x0: 1.8,
            count: 14,
            y0: 4.2,
            inlet: Side::MinusY,
        },
    ];
    let tiles = (0..14)
        .map(|i| Tile {
            position_m: [1.8 + 0.6 * i as f64, 3.3],
            size_m: [0.6, 0.6],
            open_fraction: 0.25,
            extra: None,
        })
        .collect();
    Hall {
        schema: "kalibre.hall/1".into(),
        name: "sim-demo".into(),
        room: Room {
            size_m: [12.0, 8.4, 3.0],
            extra: None,
        },
        server_types: server_types(),
        cracs: vec![
            crac("crac-1", 0.0, 0.8, 2.2),
            crac("crac-2", 0.0, 5.8, 2.2),
            crac("crac-3", 11.1, 0.8, 2.2),
            crac("crac-4", 11.1, 5.8, 2.2),
        ],
        tiles,
        returns: vec![
            ReturnGrille {
                position_m: [1.8, 0.6],
                size_m: [8.4, 0.6],
                extra: None,
            },
            ReturnGrille {
                position_m: [1.8, 7.2],
                size_m: [8.4, 0.6],
                extra: None,
            },
        ],
        racks: racks(&rows, 11, 3),
        containment: vec![],
        sensors: sensors(&rows, 3, &[0.5, 1.5])[..24].to_vec(),
        calibrate: CalibrateSpec::default(),
        effects: vec![],
        extra: None,
    }
}

/// Hall-a-sized hall: 30 x 21.6 x 3 m, 8 rows of 40 racks with 7 servers each (2,240),
/// hot aisles contained to the ceiling with returns above them, 5 cold aisles with
/// tiles, 10 floor CRACs, 64 sensors.
pub fn hall_a() -> Hall {
    let mut rows = Vec::new();
    let mut tiles = Vec::new();
    let mut returns = Vec::new();
    let mut containment = Vec::new();
    let names = ["A", "B", "C", "D", "E", "F", "G", "H"];
    for p in 0..4 {
        let y = 2.0 + 4.8 * p as f64;
        rows.push(Row {
            name: names[2 * p],
            x0: 3.0,
            count: 40,
            y0: y,
            inlet: Side::MinusY,
        });
        rows.push(Row {
            name: names[2 * p + 1],
            x0: 3.0,
            count: 40,
            y0: y + 2.4,
            inlet: Side::PlusY,
        });
        returns.push(ReturnGrille {
            position_m: [3.0, y + 1.2],
            size_m: [24.0, 1.2],
            extra: None,
        });
        containment.push(Containment {
            kind: ContainmentKind::HotAisle,
            min_m: [3.0, y + 1.2, 0.0],
            max_m: [27.0, y + 2.4, 3.0],
            extra: None,
        });
    }
    for a in 0..5 {
        let y = 0.8 + 4.8 * a as f64 + 0.3;
        for i in 0..20 {
            tiles.push(Tile {
                position_m: [3.0 + 1.2 * i as f64, y],
                size_m: [0.6, 0.6],
                open_fraction: 0.3,
                extra: None,
            });
        }
    }
    let cracs = (0..10)
        .map(|k| {
            let x = if k < 5 { 0.0 } else { 29.1 };
            crac(
                &format!("crac-{}", k + 1),
                x,
                1.0 + 4.2 * (k % 5) as f64,
                4.0,
            )
        })
        .collect();
    let s = sensors(&rows, 10, &[1.0]);
    Hall {
        schema: "kalibre.hall/1".into(),
        name: "sim-hall-a".into(),
        room: Room {
            size_m: [30.0, 21.6, 3.0],
            extra: None,
        },
        server_types: server_types(),
        cracs,
        tiles,
        returns,
        racks: racks(&rows, 7, 6),
        containment,
        sensors: s,
        calibrate: CalibrateSpec::default(),
        effects: vec![],
        extra: None,
    }
}

/// Every CRAC at `setpoint_c` and `fan`, every server at `power_w`.
pub fn uniform_state(hall: &Hall, setpoint_c: f64, fan: f64, power_w: f64) -> OperatingState {
    OperatingState {
        label: "t0".into(),
        setpoint_c: vec![setpoint_c; hall.cracs.len()],
        fan_speed: vec![fan; hall.cracs.len()],
        power_w: vec![power_w; hall.server_count()],
    }
}

/// Power per server varying smoothly across the hall (deterministic).
pub fn varied_state(hall: &Hall, setpoint_c: f64, fan: f64, mean_power_w: f64) -> OperatingState {
    let mut s = uniform_state(hall, setpoint_c, fan, mean_power_w);
    for (i, p) in s.power_w.iter_mut().enumerate() {
        *p = mean_power_w * (1.0 + 0.3 * ((i as f64) * 0.7).sin());
    }
    s
}

/// Mirrors a hall in x (x -> Lx - x), swapping `+x`/`-x` inlets.
pub fn mirror_x(hall: &Hall) -> Hall {
    let lx = hall.room.size_m[0];
    let mut h = hall.clone();
    for r in &mut h.racks {
        r.position_m[0] = lx - r.position_m[0] - r.size_m[0];
        r.inlet = match r.inlet {
            Side::PlusX => Side::MinusX,
            Side::MinusX => Side::PlusX,
            s => s,
        };
    }
    for c in &mut h.cracs {
        c.position_m[0] = lx - c.position_m[0] - c.size_m[0];
    }
    for t in &mut h.tiles {
        t.position_m[0] = lx - t.position_m[0] - t.size_m[0];
    }
    for r in &mut h.returns {
        r.position_m[0] = lx - r.position_m[0] - r.size_m[0];
    }
    for c in &mut h.containment {
        let (a, b) = (lx - c.max_m[0], lx - c.min_m[0]);
        c.min_m[0] = a;
        c.max_m[0] = b;
    }
    for s in &mut h.sensors {
        s.position_m[0] = lx - s.position_m[0];
    }
    h
}

/// A small contained hall: 9.6 x 7.2 x 3 m, rows A (inlet -y) and B (inlet +y) of 10
/// racks (5 servers each) around a hot aisle contained to the ceiling with a return
/// above it, cold aisles with tiles outside, 2 floor CRACs, 20 sensors. With
/// `cold_return`, a second return over the row-B cold aisle gives the room side its own
/// exit, so that leakage through the panels competes with it.
pub fn contained_hall(cold_return: bool) -> Hall {
    let rows = [
        Row {
            name: "A",
            x0: 1.8,
            count: 10,
            y0: 1.8,
            inlet: Side::MinusY,
        },
        Row {
            name: "B",
            x0: 1.8,
            count: 10,
            y0: 4.2,
            inlet: Side::PlusY,
        },
    ];
    let mut tiles = Vec::new();
    for i in 0..10 {
        for y in [0.9, 5.7] {
            tiles.push(Tile {
                position_m: [1.8 + 0.6 * i as f64, y],
                size_m: [0.6, 0.6],
                open_fraction: 0.25,
                extra: None,
            });
        }
    }
    Hall {
        schema: "kalibre.hall/1".into(),
        name: "sim-contained".into(),
        room: Room {
            size_m: [9.6, 7.2, 3.0],
            extra: None,
        },
        server_types: server_types(),
        cracs: vec![crac("crac-1", 0.0, 0.2, 2.5), crac("crac-2", 0.0, 5.2, 2.5)],
        tiles,
        returns: if cold_return {
            vec![
                ReturnGrille {
                    position_m: [1.8, 3.0],
                    size_m: [6.0, 1.2],
                    extra: None,
                },
                ReturnGrille {
                    position_m: [1.8, 6.0],
                    size_m: [6.0, 0.6],
                    extra: None,
                },
            ]
        } else {
            vec![ReturnGrille {
                position_m: [1.8, 3.0],
                size_m: [6.0, 1.2],
                extra: None,
            }]
        },
        racks: racks(&rows, 5, 8),
        containment: vec![Containment {
            kind: ContainmentKind::HotAisle,
            min_m: [1.8, 3.0, 0.0],
            max_m: [7.8, 4.2, 3.0],
            extra: None,
        }],
        sensors: sensors(&rows, 2, &[1.0]),
        calibrate: CalibrateSpec::default(),
        effects: vec![],
        extra: None,
    }
}
