//! Tile jets: the supply carried up the cold aisle by the tiles' momentum.
//!
//! The simulator's flow is potential flow: each tile's supply enters in the floor layer,
//! and the nearest intakes take it. In a real hall (and in OpenFOAM) a tile's jet rises
//! and the racks facing it draw from it band by band. [`draw_matched_links`] models that
//! with forced links ([`AirLink`]): from `from_m` up, each 0.2 m band above a tile
//! receives what the facing servers draw there, until the tile's supply runs out; what is
//! left rises over the racks. Measured against OpenFOAM (`docs/performance.md`, "Tile
//! jets") it halves the model's error on the development snapshots and is worse at low
//! fan speed and on wide tiles, so it is not the model's physics: the diagnosis uses the
//! difference it makes as one sensor's model-form uncertainty.

use crate::hall::{face_centre, Aabb, Hall};
use crate::sim::{tile_flows_m3_s, AirLink, M3_S_PER_CFM};
use crate::snapshots::OperatingState;

/// Height of one release band (m).
const BAND_M: f64 = 0.2;
/// How far (m) beyond a tile's edge a server's intake face still draws from its jet.
const FACING_M: f64 = 0.5;

/// The jet consumed from below, as forced links for `state` at `alpha_per_server`
/// (cfm/W): per tile and 0.2 m band from `from_m` to the tallest rack's top, a link from
/// the tile's floor layer releasing what the servers facing the tile draw in that band
/// (their flow spread evenly over their height, shared between the tiles in front of
/// them by overlap along the row), while the tile's supply (as the simulator splits it,
/// [`tile_flows_m3_s`], with `opening_share` of the supply taken by openings) lasts; the
/// rest in the 0.4 m above the tallest rack.
pub fn draw_matched_links(
    hall: &Hall,
    state: &OperatingState,
    alpha_per_server: &[f64],
    from_m: f64,
    opening_share: f64,
) -> Vec<AirLink> {
    let rack_top_m = hall.racks.iter().map(|r| r.size_m[2]).fold(0.0, f64::max);
    let overlap = |a0: f64, a1: f64, b0: f64, b1: f64| (a1.min(b1) - a0.max(b0)).max(0.0);
    let n_bands = ((rack_top_m - from_m) / BAND_M).round().max(1.0) as usize;
    let mut links = Vec::new();
    for (t, mut left) in hall
        .tiles
        .iter()
        .zip(tile_flows_m3_s(hall, state, opening_share))
    {
        let ([x, y], [sx, sy]) = (t.position_m, t.size_m);
        let mut draw = vec![0.0; n_bands];
        for s in hall.servers() {
            let b = s.bounds();
            let face = face_centre(&b, s.rack.inlet);
            let (axis, _) = s.rack.inlet.axis_sign();
            let along = 1 - axis;
            let (t0, t1) = if axis == 1 { (y, y + sy) } else { (x, x + sx) };
            let near = face[axis] >= t0 - FACING_M && face[axis] <= t1 + FACING_M;
            let (o0, o1) = if along == 0 { (x, x + sx) } else { (y, y + sy) };
            let width = b.max[along] - b.min[along];
            let share = if width > 0.0 {
                overlap(b.min[along], b.max[along], o0, o1) / width
            } else {
                0.0
            };
            if !near || share <= 0.0 {
                continue;
            }
            let (Some(alpha), Some(power)) =
                (alpha_per_server.get(s.index), state.power_w.get(s.index))
            else {
                continue;
            };
            let q = alpha * power * M3_S_PER_CFM * share;
            let h = b.max[2] - b.min[2];
            if h <= 0.0 {
                continue;
            }
            for (k, d) in draw.iter_mut().enumerate() {
                let z0 = from_m + k as f64 * BAND_M;
                *d += q * overlap(b.min[2], b.max[2], z0, z0 + BAND_M) / h;
            }
        }
        let floor_box = Aabb {
            min: [x, y, 0.0],
            max: [x + sx, y + sy, BAND_M],
        };
        for (k, d) in draw.iter().enumerate() {
            let q = d.min(left);
            if q <= 0.0 {
                break;
            }
            left -= q;
            let z0 = from_m + k as f64 * BAND_M;
            links.push(AirLink {
                from: floor_box,
                to: Aabb {
                    min: [x, y, z0],
                    max: [x + sx, y + sy, z0 + BAND_M],
                },
                flow_m3_s: q,
            });
        }
        if left > 0.0 {
            links.push(AirLink {
                from: floor_box,
                to: Aabb {
                    min: [x, y, rack_top_m],
                    max: [x + sx, y + sy, (rack_top_m + 0.4).min(hall.room.size_m[2])],
                },
                flow_m3_s: left,
            });
        }
    }
    links
}
