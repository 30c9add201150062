//! The true server air flows and the operating states of a synthetic hall.

use rand::seq::SliceRandom;
use rand::Rng;

use super::catalogue::TypeTemplate;
use crate::hall::Hall;
use crate::snapshots::OperatingState;

/// m3/s per cfm.
pub(crate) const M3_S_PER_CFM: f64 = 4.71947e-4;
/// Range of true per-type alpha (cfm/W): temperature rises of about 9 to 20 C.
pub(crate) const ALPHA_TRUE_RANGE: (f64, f64) = (0.09, 0.20);
/// Half-width of the per-server jitter on alpha (+-3 %).
pub(crate) const ALPHA_JITTER: f64 = 0.03;
/// Range of the per-snapshot power scale (fraction of nominal).
const POWER_SCALE: (f64, f64) = (0.85, 1.1);
/// Half-width of the per-server, per-snapshot load variation.
const POWER_VARIATION: f64 = 0.1;
/// Range of the snapshot's base CRAC setpoint (C).
const SETPOINT_C: (f64, f64) = (16.0, 21.0);
/// Half-width of the per-CRAC setpoint spread around the snapshot's base (C).
const SETPOINT_SPREAD_C: f64 = 0.5;
/// Range of the ratio of CRAC supply to true server draw: below 1 the servers recirculate
/// hot air, above 1 cold air bypasses them (the OpenFOAM data runs at 1.04-1.08).
const SUPPLY_RATIO: (f64, f64) = (0.94, 1.08);
/// Half-width of the relative fan-speed spread between CRACs of one snapshot.
const FAN_SPREAD: f64 = 0.06;
/// Fan speeds stay within this range.
const FAN_RANGE: (f64, f64) = (0.5, 1.0);
/// Total rated CRAC flow as a multiple of the nominal true server draw, so that the fan
/// speeds needed land around 0.67-0.99.
const RATED_OVER_DRAW: f64 = 1.2;

/// True alpha: a base per type and a jittered value per server.
#[derive(Debug, Clone)]
pub(crate) struct TrueAlpha {
    /// Base per type, in `hall.server_types` order.
    pub per_type: Vec<f64>,
    /// Per server, hall order.
    pub per_server: Vec<f64>,
}

/// Rounds to a decimal `step` (0.1, 0.01, ...).
pub(crate) fn round_to(x: f64, step: f64) -> f64 {
    // Multiply by the integer inverse so that 18.3 comes out as the double nearest 18.3.
    let inv = (1.0 / step).round();
    (x * inv).round() / inv
}

/// Draws the true alphas.
pub(crate) fn draw_true_alpha<R: Rng>(rng: &mut R, hall: &Hall) -> TrueAlpha {
    let per_type: Vec<f64> = hall
        .server_types
        .iter()
        .map(|_| {
            round_to(
                rng.random_range(ALPHA_TRUE_RANGE.0..ALPHA_TRUE_RANGE.1),
                0.001,
            )
        })
        .collect();
    let per_server = hall
        .server_type_indices()
        .into_iter()
        .map(|t| {
            let base = per_type[t.unwrap_or(0)];
            base * (1.0 + rng.random_range(-ALPHA_JITTER..ALPHA_JITTER))
        })
        .collect();
    TrueAlpha {
        per_type,
        per_server,
    }
}

/// Nominal (full-load) power per server, drawn within its type's range (W).
pub(crate) fn draw_nominal_power<R: Rng>(
    rng: &mut R,
    hall: &Hall,
    types: &[TypeTemplate],
) -> Vec<f64> {
    hall.server_type_indices()
        .into_iter()
        .map(|t| {
            let (lo, hi) = types[t.unwrap_or(0)].power_w;
            rng.random_range(lo..hi)
        })
        .collect()
}

/// Sets every CRAC's rated flow so that the fans run at 0.67-0.99 across the snapshots.
pub(crate) fn set_rated_flows(hall: &mut Hall, alpha: &[f64], nominal_power_w: &[f64]) {
    let draw: f64 = alpha
        .iter()
        .zip(nominal_power_w)
        .map(|(a, p)| a * p * M3_S_PER_CFM)
        .sum();
    let n = hall.cracs.len().max(1) as f64;
    let rated = round_to(RATED_OVER_DRAW * draw / n, 0.01);
    for c in &mut hall.cracs {
        c.rated_flow_m3_s = rated;
    }
}

/// `count` stratified draws in `[lo, hi)` in random order, so that snapshots always
/// spread over the range.
fn stratified<R: Rng>(rng: &mut R, count: usize, (lo, hi): (f64, f64)) -> Vec<f64> {
    let mut v: Vec<f64> = (0..count)
        .map(|k| lo + (hi - lo) * (k as f64 + rng.random::<f64>()) / count as f64)
        .collect();
    v.shuffle(rng);
    v
}

/// Draws `count` operating states labelled `t0, t1, ...`: power scale, setpoints and the
/// supply-to-draw ratio vary between them; fan speeds follow from the ratio.
pub(crate) fn draw_states<R: Rng>(
    rng: &mut R,
    hall: &Hall,
    alpha: &[f64],
    nominal_power_w: &[f64],
    count: usize,
) -> Vec<OperatingState> {
    let scales = stratified(rng, count, POWER_SCALE);
    let setpoints = stratified(rng, count, SETPOINT_C);
    let ratios = stratified(rng, count, SUPPLY_RATIO);
    let rated_total: f64 = hall.cracs.iter().map(|c| c.rated_flow_m3_s).sum();
    (0..count)
        .map(|k| {
            let power_w: Vec<f64> = nominal_power_w
                .iter()
                .map(|p| {
                    let v = 1.0 + rng.random_range(-POWER_VARIATION..POWER_VARIATION);
                    (p * scales[k] * v).round()
                })
                .collect();
            let draw: f64 = alpha
                .iter()
                .zip(&power_w)
                .map(|(a, p)| a * p * M3_S_PER_CFM)
                .sum();
            let fan_mean = ratios[k] * draw / rated_total;
            let fan_speed = hall
                .cracs
                .iter()
                .map(|_| {
                    let f = fan_mean * (1.0 + rng.random_range(-FAN_SPREAD..FAN_SPREAD));
                    round_to(f.clamp(FAN_RANGE.0, FAN_RANGE.1), 0.01)
                })
                .collect();
            let setpoint_c = hall
                .cracs
                .iter()
                .map(|_| {
                    let s = setpoints[k] + rng.random_range(-SETPOINT_SPREAD_C..SETPOINT_SPREAD_C);
                    round_to(s, 0.1)
                })
                .collect();
            OperatingState {
                label: format!("t{k}"),
                setpoint_c,
                fan_speed,
                power_w,
            }
        })
        .collect()
}
