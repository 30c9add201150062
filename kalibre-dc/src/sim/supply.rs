//! How the supply enters the room: each CRAC delivers its rated flow times its fan speed;
//! the floor CRACs blow into one plenum, whose flow the tiles share by open area, less
//! what supply openings (bypass effects) take; front-supply CRACs blow through their own
//! fronts. The simulator and the tile jets ([`super::jets`]) both split it here, so the
//! jets release what the simulator's tiles deliver.

use crate::hall::{Hall, SupplyKind};
use crate::snapshots::OperatingState;

/// Each CRAC's flow (m3/s) in `state`, hall order.
pub(super) fn crac_flows_m3_s(hall: &Hall, state: &OperatingState) -> Vec<f64> {
    hall.cracs
        .iter()
        .zip(&state.fan_speed)
        .map(|(c, f)| c.rated_flow_m3_s * f)
        .collect()
}

/// The floor CRACs' part (m3/s) of `crac_flows_m3_s`: what the plenum receives.
pub(super) fn floor_flow_m3_s(hall: &Hall, crac_flows_m3_s: &[f64]) -> f64 {
    hall.cracs
        .iter()
        .zip(crac_flows_m3_s)
        .filter(|(c, _)| c.supply == SupplyKind::Floor)
        .map(|(_, q)| q)
        .sum()
}

/// Each tile's flow (m3/s) in `state`, hall order: the floor CRACs' flow less the share
/// `opening_share` that supply openings take ([`super::SimMods::supply_opening_share`]),
/// split by open area.
pub fn tile_flows_m3_s(hall: &Hall, state: &OperatingState, opening_share: f64) -> Vec<f64> {
    let floor = floor_flow_m3_s(hall, &crac_flows_m3_s(hall, state));
    split_over_tiles(hall, floor, opening_share)
}

/// [`tile_flows_m3_s`] from the plenum's flow `floor_flow_m3_s`.
pub(super) fn split_over_tiles(hall: &Hall, floor_flow_m3_s: f64, opening_share: f64) -> Vec<f64> {
    let through_tiles_m3_s = (1.0 - opening_share) * floor_flow_m3_s;
    let total_open_m2: f64 = hall.tiles.iter().map(|t| t.open_area_m2()).sum();
    hall.tiles
        .iter()
        .map(|t| {
            if total_open_m2 > 0.0 {
                through_tiles_m3_s * (t.open_area_m2() / total_open_m2)
            } else {
                0.0
            }
        })
        .collect()
}
