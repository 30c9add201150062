//! The geometry of a synthetic hall: rows of 42U racks in pairs around hot aisles, CRACs
//! at the row ends, a raised floor with a perforated tile before each rack, ceiling
//! returns over the hot aisles, and sensors at rack inlets and behind exhausts.

use rand::Rng;

use super::catalogue::{draw_types, TypeTemplate};
use super::preset::LayoutSpec;
use crate::hall::Aisle;
use crate::hall::{
    AlphaBounds, CalibrateSpec, Containment, ContainmentKind, Crac, Hall, Rack, ReturnGrille, Room,
    Sensor, Server, ServerType, Side, SupplyKind, Tile, HALL_SCHEMA,
};
use crate::{Error, Result};

/// Rack footprint and height (m): 0.6 wide, 1.2 deep, 2.0 tall, 42 units.
pub(crate) const RACK_SIZE_M: [f64; 3] = [0.6, 1.2, 2.0];
/// Units per rack.
pub(crate) const RACK_UNITS: u32 = 42;
/// Units kept free at the top of each rack (top-of-rack switch, cable management).
const RESERVED_UNITS: u32 = 2;
/// Room height (m).
const ROOM_HEIGHT_M: f64 = 3.0;
/// Width of the hot aisle between the two rows of a pair (m).
const HOT_AISLE_M: f64 = 1.2;
/// CRAC box (m).
const CRAC_SIZE_M: [f64; 3] = [1.0, 2.4, 2.0];
/// Cold-aisle sensor distance in front of the rack inlet (m).
const COLD_SENSOR_OFFSET_M: f64 = 0.1;
/// Hot-aisle sensor distance behind the rack exhaust (m).
const HOT_SENSOR_OFFSET_M: f64 = 0.3;
/// Cold-aisle sensor heights (m): low, middle and high inlets.
const COLD_HEIGHTS_M: [f64; 3] = [0.5, 1.1, 1.7];
/// Hot-aisle sensor heights (m).
const HOT_HEIGHTS_M: [f64; 2] = [1.1, 1.7];
/// Open fractions of perforated tiles found in one hall (25 % to 56 % open tiles).
const TILE_OPEN_FRACTIONS: [f64; 4] = [0.25, 0.35, 0.45, 0.56];

/// A generated layout: the hall (CRAC rated flows and alpha guesses still to be set)
/// and the catalogue entry of each server type, in `hall.server_types` order.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// The hall.
    pub hall: Hall,
    /// Catalogue entry per server type.
    pub types: Vec<TypeTemplate>,
}

/// Options of the geometry that are not fixed by the preset.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LayoutOptions {
    /// Hot-aisle containment on or off.
    pub containment: bool,
}

/// Rounds to the 0.1 m lattice the layout lives on (removes floating-point dust).
fn snap(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// Builds the layout for `spec` from `rng`.
pub(crate) fn build<R: Rng>(
    name: &str,
    spec: &LayoutSpec,
    options: LayoutOptions,
    rng: &mut R,
) -> Result<Layout> {
    let n_types = rng.random_range(spec.types.0..=spec.types.1);
    let types = draw_types(rng, n_types);
    let rows = 2 * spec.row_pairs;
    let row_len = spec.racks_per_row as f64 * RACK_SIZE_M[0];
    let x0 = CRAC_SIZE_M[0] + spec.end_clearance_m;
    let room_x = snap(2.0 * x0 + row_len);
    let pair_w = 2.0 * RACK_SIZE_M[1] + HOT_AISLE_M;
    let room_y = snap(
        2.0 * spec.outer_cold_m
            + spec.row_pairs as f64 * pair_w
            + (spec.row_pairs - 1) as f64 * spec.inner_cold_m,
    );

    // Rows: row 2p exhausts +y into the pair's hot aisle, row 2p+1 exhausts -y into it.
    let mut row_y = Vec::with_capacity(rows);
    let mut hot_aisles = Vec::with_capacity(spec.row_pairs);
    let mut y = spec.outer_cold_m;
    for _ in 0..spec.row_pairs {
        row_y.push((snap(y), Side::MinusY));
        hot_aisles.push((
            snap(y + RACK_SIZE_M[1]),
            snap(y + RACK_SIZE_M[1] + HOT_AISLE_M),
        ));
        row_y.push((snap(y + RACK_SIZE_M[1] + HOT_AISLE_M), Side::PlusY));
        y += pair_w + spec.inner_cold_m;
    }

    let (racks, tiles) = build_racks(spec, &types, &row_y, x0, rng)?;

    let cracs = build_cracs(spec.cracs, room_x, room_y);
    let returns = hot_aisles
        .iter()
        .map(|&(y0, y1)| ReturnGrille {
            position_m: [snap(x0), snap(0.5 * (y0 + y1) - 0.3)],
            size_m: [snap(row_len), 0.6],
            extra: None,
        })
        .collect();
    let containment = if options.containment {
        hot_aisles
            .iter()
            .map(|&(y0, y1)| Containment {
                kind: ContainmentKind::HotAisle,
                min_m: [snap(x0), y0, 0.0],
                max_m: [snap(x0 + row_len), y1, ROOM_HEIGHT_M],
                extra: None,
            })
            .collect()
    } else {
        Vec::new()
    };
    let sensors = build_sensors(spec, &racks, rng);

    let hall = Hall {
        schema: HALL_SCHEMA.to_string(),
        name: name.to_string(),
        room: Room {
            size_m: [room_x, room_y, ROOM_HEIGHT_M],
            extra: None,
        },
        server_types: types
            .iter()
            .map(|t| ServerType {
                id: t.id.to_string(),
                alpha_cfm_per_w: AlphaBounds {
                    initial: 0.12,
                    min: 0.01,
                    max: 3.0,
                    extra: None,
                },
                extra: None,
            })
            .collect(),
        cracs,
        tiles,
        returns,
        racks,
        containment,
        sensors,
        calibrate: CalibrateSpec::default(),
        effects: Vec::new(),
        extra: None,
    };
    Ok(Layout { hall, types })
}

/// Row letter(s) for row `r`: A..Z.
fn row_letter(r: usize) -> char {
    (b'A' + (r % 26) as u8) as char
}

/// Racks with their servers, and one tile in front of each rack.
fn build_racks<R: Rng>(
    spec: &LayoutSpec,
    types: &[TypeTemplate],
    row_y: &[(f64, Side)],
    x0: f64,
    rng: &mut R,
) -> Result<(Vec<Rack>, Vec<Tile>)> {
    let n_racks = row_y.len() * spec.racks_per_row;
    // Each rack holds mostly one primary type; taller types are rarer primaries so
    // that the hall reaches its server count.
    let weights: Vec<f64> = types.iter().map(|t| 1.0 / t.height_u as f64).collect();
    let total_w: f64 = weights.iter().sum();
    let pick = |rng: &mut R| -> usize {
        let mut u = rng.random::<f64>() * total_w;
        for (i, w) in weights.iter().enumerate() {
            if u < *w {
                return i;
            }
            u -= w;
        }
        weights.len() - 1
    };
    let usable = RACK_UNITS - RESERVED_UNITS;
    let mut sequences: Vec<Vec<usize>> = Vec::with_capacity(n_racks);
    let mut capacity = Vec::with_capacity(n_racks);
    for _ in 0..n_racks {
        let primary = pick(rng);
        let secondary = rng.random_range(0..types.len());
        let mut seq = Vec::new();
        let mut used = 0;
        loop {
            let t = if rng.random::<f64>() < 0.8 {
                primary
            } else {
                secondary
            };
            if used + types[t].height_u > usable {
                break;
            }
            used += types[t].height_u;
            seq.push(t);
        }
        capacity.push(seq.len());
        sequences.push(seq);
    }
    let total_capacity: usize = capacity.iter().sum();
    if total_capacity < spec.servers {
        return Err(Error::Mismatch(format!(
            "synthetic layout: racks hold at most {total_capacity} servers, fewer than the {} asked",
            spec.servers
        )));
    }
    // Server counts per rack: around the mean, then nudged one at a time to the exact
    // total (seeded choice of rack) so that the preset's count holds.
    let mean = spec.servers as f64 / n_racks as f64;
    let mut counts: Vec<usize> = capacity
        .iter()
        .map(|&c| ((mean * rng.random_range(0.8..1.2)).round() as usize).clamp(1, c))
        .collect();
    let mut sum: usize = counts.iter().sum();
    while sum != spec.servers {
        let r = rng.random_range(0..n_racks);
        if sum < spec.servers && counts[r] < capacity[r] {
            counts[r] += 1;
            sum += 1;
        } else if sum > spec.servers && counts[r] > 1 {
            counts[r] -= 1;
            sum -= 1;
        }
    }

    let mut racks = Vec::with_capacity(n_racks);
    let mut tiles = Vec::with_capacity(n_racks);
    for (r, &(y, inlet)) in row_y.iter().enumerate() {
        for i in 0..spec.racks_per_row {
            let k = r * spec.racks_per_row + i;
            let id = format!("{}{:02}", row_letter(r), i + 1);
            let x = snap(x0 + i as f64 * RACK_SIZE_M[0]);
            let mut u = 1;
            let servers = sequences[k][..counts[k]]
                .iter()
                .map(|&t| {
                    let s = Server {
                        id: format!("{id}-{u:02}"),
                        server_type: types[t].id.to_string(),
                        u,
                        height_u: types[t].height_u,
                        extra: None,
                    };
                    u += types[t].height_u;
                    s
                })
                .collect();
            let tile_y = match inlet {
                Side::MinusY => snap(y - 0.6),
                _ => snap(y + RACK_SIZE_M[1]),
            };
            tiles.push(Tile {
                position_m: [x, tile_y],
                size_m: [0.6, 0.6],
                open_fraction: TILE_OPEN_FRACTIONS[rng.random_range(0..TILE_OPEN_FRACTIONS.len())],
                extra: None,
            });
            racks.push(Rack {
                id,
                position_m: [x, y, 0.0],
                size_m: RACK_SIZE_M,
                inlet,
                units: RACK_UNITS,
                servers,
                extra: None,
            });
        }
    }
    Ok((racks, tiles))
}

/// CRACs against the two end walls (x = 0 and x = room length), spread along y, with a
/// floor (plenum) supply.
fn build_cracs(n: usize, room_x: f64, room_y: f64) -> Vec<Crac> {
    let left = n.div_ceil(2);
    let mut cracs = Vec::with_capacity(n);
    for (end, count) in [(0usize, left), (1, n - left)] {
        for i in 0..count {
            let yc = room_y * (i as f64 + 0.5) / count as f64;
            // Keep on the 0.2 m lattice.
            let y0 = ((yc - 0.5 * CRAC_SIZE_M[1]) / 0.2).round() * 0.2;
            let y0 = snap(y0.clamp(0.0, room_y - CRAC_SIZE_M[1]));
            let x = if end == 0 {
                0.0
            } else {
                snap(room_x - CRAC_SIZE_M[0])
            };
            cracs.push(Crac {
                id: format!("crac-{}", cracs.len() + 1),
                position_m: [x, y0, 0.0],
                size_m: CRAC_SIZE_M,
                rated_flow_m3_s: 1.0,
                supply: SupplyKind::Floor,
                extra: None,
            });
        }
    }
    cracs
}

/// Sensors per row: cold-aisle sensors 0.1 m before the inlets of racks spread along the
/// row at the three inlet heights, hot-aisle sensors 0.3 m behind the exhausts.
fn build_sensors<R: Rng>(spec: &LayoutSpec, racks: &[Rack], rng: &mut R) -> Vec<Sensor> {
    let mut sensors = Vec::new();
    for row in racks.chunks(spec.racks_per_row) {
        let mut height_turn = rng.random_range(0..COLD_HEIGHTS_M.len());
        for (aisle, count) in [
            (Aisle::Cold, spec.cold_sensors_per_row),
            (Aisle::Hot, spec.hot_sensors_per_row),
        ] {
            for rack in spread_pick(row, count, rng) {
                let (axis, sign) = rack.inlet.axis_sign();
                debug_assert_eq!(axis, 1);
                let inlet_y = if sign > 0.0 {
                    rack.position_m[1] + rack.size_m[1]
                } else {
                    rack.position_m[1]
                };
                let exhaust_y = if sign > 0.0 {
                    rack.position_m[1]
                } else {
                    rack.position_m[1] + rack.size_m[1]
                };
                let x = snap(rack.position_m[0] + 0.5 * rack.size_m[0]);
                let (y, z, prefix) = match aisle {
                    Aisle::Cold => {
                        let z = COLD_HEIGHTS_M[height_turn % COLD_HEIGHTS_M.len()];
                        height_turn += 1;
                        (inlet_y + sign * COLD_SENSOR_OFFSET_M, z, 'c')
                    }
                    Aisle::Hot => {
                        let z = HOT_HEIGHTS_M[rng.random_range(0..HOT_HEIGHTS_M.len())];
                        (exhaust_y - sign * HOT_SENSOR_OFFSET_M, z, 'h')
                    }
                };
                sensors.push(Sensor {
                    id: format!("{prefix}-{}-{:02}", rack.id, (z * 10.0).round() as u32),
                    position_m: [x, snap(y), z],
                    aisle,
                    extra: None,
                });
            }
        }
    }
    sensors
}

/// Picks `count` racks of a row, one from each of `count` equal stretches of the row.
fn spread_pick<'a, R: Rng>(row: &'a [Rack], count: usize, rng: &mut R) -> Vec<&'a Rack> {
    let count = count.min(row.len());
    (0..count)
        .map(|i| {
            let lo = i * row.len() / count;
            let hi = ((i + 1) * row.len() / count).max(lo + 1);
            &row[rng.random_range(lo..hi)]
        })
        .collect()
}
