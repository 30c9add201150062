//! Programmatic hall fixtures for the thermal graph tests and bench: rows of racks in
//! pairs around contained hot aisles, CRACs on the end walls, sensors in every aisle.
#![allow(dead_code)]

use kalibre_dc::hall::*;
use kalibre_dc::snapshots::OperatingState;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Shape of a generated hall.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    /// Row pairs (each pair shares one hot aisle).
    pub row_pairs: usize,
    pub racks_per_row: usize,
    pub servers_per_rack: usize,
    pub types: usize,
    /// CRACs per end wall.
    pub cracs_per_wall: usize,
    pub hot_sensors_per_aisle: usize,
    pub cold_sensors_per_aisle: usize,
}

/// hall-a size: 8 rows x 14 racks x 20 servers = 2,240 servers, 8 CRACs, 10 types,
/// 32 hot-aisle and 30 cold-aisle sensors (62).
pub const HALL_A: Shape = Shape {
    row_pairs: 4,
    racks_per_row: 14,
    servers_per_rack: 20,
    types: 10,
    cracs_per_wall: 4,
    hot_sensors_per_aisle: 8,
    cold_sensors_per_aisle: 6,
};

/// A small hall for gradient checks: 2 rows x 3 racks x 4 servers, 3 types, 2 CRACs.
pub const SMALL: Shape = Shape {
    row_pairs: 1,
    racks_per_row: 3,
    servers_per_rack: 4,
    types: 3,
    cracs_per_wall: 1,
    hot_sensors_per_aisle: 3,
    cold_sensors_per_aisle: 2,
};

pub fn hall(shape: Shape, mode: AlphaMode) -> Hall {
    let rack_w = 0.6;
    let depth = 1.2;
    let aisle = 1.2;
    let pitch = 2.0 * depth + 2.0 * aisle;
    let x0 = 2.0;
    let room_x = x0 + shape.racks_per_row as f64 * rack_w + 2.0;
    let room_y = aisle + shape.row_pairs as f64 * pitch;
    let height = 3.0;
    let server_types = (0..shape.types)
        .map(|t| ServerType {
            id: format!("type-{t}"),
            alpha_cfm_per_w: AlphaBounds {
                initial: 0.12,
                min: 0.01,
                max: 3.0,
                extra: None,
            },
            extra: None,
        })
        .collect();
    let mut cracs = Vec::new();
    for wall in 0..2 {
        for c in 0..shape.cracs_per_wall {
            let y = (c as f64 + 0.5) * room_y / shape.cracs_per_wall as f64 - 1.0;
            cracs.push(Crac {
                id: format!("crac-{}", cracs.len() + 1),
                position_m: [if wall == 0 { 0.0 } else { room_x - 0.9 }, y.max(0.0), 0.0],
                size_m: [0.9, 2.0, 2.0],
                rated_flow_m3_s: 8.0,
                supply: SupplyKind::Floor,
                extra: None,
            });
        }
    }
    let mut racks = Vec::new();
    let mut tiles = Vec::new();
    let mut containment = Vec::new();
    let mut sensors = Vec::new();
    let x_end = x0 + shape.racks_per_row as f64 * rack_w;
    let mut cold_aisles = vec![0.0];
    for p in 0..shape.row_pairs {
        let y = aisle + p as f64 * pitch;
        cold_aisles.push(y + 2.0 * depth + aisle);
        for (side, (ry, inlet)) in [(y, Side::MinusY), (y + depth + aisle, Side::PlusY)]
            .into_iter()
            .enumerate()
        {
            for r in 0..shape.racks_per_row {
                let rack_index = racks.len();
                let servers = (0..shape.servers_per_rack)
                    .map(|s| Server {
                        id: format!("P{p}S{side}R{r:02}-{s:02}"),
                        server_type: format!(
                            "type-{}",
                            (rack_index + s / (shape.servers_per_rack / 4).max(1)) % shape.types
                        ),
                        u: 1 + 2 * s as u32,
                        height_u: 2,
                        extra: None,
                    })
                    .collect();
                racks.push(Rack {
                    id: format!("P{p}S{side}R{r:02}"),
                    position_m: [x0 + r as f64 * rack_w, ry, 0.0],
                    size_m: [rack_w, depth, 2.0],
                    inlet,
                    units: 2 * shape.servers_per_rack as u32,
                    servers,
                    extra: None,
                });
            }
        }
        containment.push(Containment {
            kind: ContainmentKind::HotAisle,
            min_m: [x0, y + depth, 0.0],
            max_m: [x_end, y + depth + aisle, 2.0],
            extra: None,
        });
        for s in 0..shape.hot_sensors_per_aisle {
            let x = x0 + (s as f64 + 0.5) * (x_end - x0) / shape.hot_sensors_per_aisle as f64;
            sensors.push(Sensor {
                id: format!("h{p}-{s}"),
                position_m: [x, y + depth + 0.5 * aisle, 1.0 + 0.5 * (s % 2) as f64],
                aisle: Aisle::Hot,
                extra: None,
            });
        }
    }
    for (a, &y) in cold_aisles.iter().enumerate() {
        for r in 0..shape.racks_per_row {
            tiles.push(Tile {
                position_m: [x0 + r as f64 * rack_w, y + 0.3],
                size_m: [0.6, 0.6],
                open_fraction: 0.25,
                extra: None,
            });
        }
        let per = if a == 0 || a == cold_aisles.len() - 1 {
            shape.cold_sensors_per_aisle / 2
        } else {
            shape.cold_sensors_per_aisle
        }
        .max(1);
        for s in 0..per {
            let x = x0 + (s as f64 + 0.5) * (x_end - x0) / per as f64;
            sensors.push(Sensor {
                id: format!("c{a}-{s}"),
                position_m: [x, y + 0.5 * aisle, 1.0],
                aisle: Aisle::Cold,
                extra: None,
            });
        }
    }
    Hall {
        schema: HALL_SCHEMA.to_string(),
        name: "fixture".into(),
        room: Room {
            size_m: [room_x, room_y, height],
            extra: None,
        },
        server_types,
        cracs,
        tiles,
        returns: Vec::new(),
        racks,
        containment,
        sensors,
        calibrate: CalibrateSpec {
            alpha: mode,
            extra: None,
        },
        effects: Vec::new(),
        extra: None,
    }
}

/// A seeded operating state: setpoints 17-21 C, fan speeds 0.6-0.95, powers 150-450 W.
pub fn state(hall: &Hall, label: &str, seed: u64) -> OperatingState {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    OperatingState {
        label: label.to_string(),
        setpoint_c: (0..hall.cracs.len())
            .map(|_| rng.random_range(17.0..21.0))
            .collect(),
        fan_speed: (0..hall.cracs.len())
            .map(|_| rng.random_range(0.6..0.95))
            .collect(),
        power_w: (0..hall.server_count())
            .map(|_| rng.random_range(150.0..450.0))
            .collect(),
    }
}
