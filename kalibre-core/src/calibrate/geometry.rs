//! Geometry steps: when the corrected surrogate has nothing more to say (its optimum is
//! the best run itself), the loop runs the model one step from the best point along the
//! direction its earlier runs covered least, so the next linear correction learns the
//! model's slope there (as derivative-free trust-region methods improve their sample
//! geometry). Or, with `Settings::stall_toward_data`, along the direction where the
//! fitted surrogate's slopes say the measurements pull hardest: the corrected surrogate
//! can hold a wall along a direction its few runs mis-slope, and a run there settles it.

use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Coordinates up to which the candidate directions are the coordinate axes; above it,
/// seeded random directions (every axis would cost too many projections and tell little).
const AXIS_CANDIDATES_MAX_DIM: usize = 256;
/// Random candidate directions above [`AXIS_CANDIDATES_MAX_DIM`].
const RANDOM_CANDIDATES: usize = 32;

/// The best point moved by `step` (max norm, unit box) along the candidate direction with
/// the largest part orthogonal to the runs near it (`explored`: unit points whose root-mean
/// -square distance from `anchor` is at most `near_rms`).
pub(crate) fn least_covered_step(
    anchor: &[f64],
    explored: &[Vec<f64>],
    near_rms: f64,
    step: f64,
    seed: u64,
) -> Vec<f64> {
    let d = anchor.len();
    let basis = explored_basis(anchor, explored, near_rms);
    let candidates = candidate_directions(d, seed);
    let uncovered = |e: &Vec<f64>| uncovered_part(&basis, e);
    let mut best = 0;
    let mut best_score = f64::NEG_INFINITY;
    for (i, e) in candidates.iter().enumerate() {
        let s = uncovered(e);
        // Strictly greater: ties keep the lowest index (deterministic).
        if s > best_score + 1e-12 {
            best = i;
            best_score = s;
        }
    }
    let e = &candidates[best];
    let scale = step / e.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    // Go the way that leaves more room in the box.
    let room: f64 = e.iter().zip(anchor).map(|(ei, a)| ei * (0.5 - a)).sum();
    let sign = if room >= 0.0 { 1.0 } else { -1.0 };
    anchor
        .iter()
        .zip(e)
        .map(|(a, ei)| (a + sign * scale * ei).clamp(0.0, 1.0))
        .collect()
}

/// Orthonormal basis (modified Gram-Schmidt) of the directions from `anchor` to the
/// `explored` points within `near_rms` (root-mean-square distance, unit box) of it.
pub(crate) fn explored_basis(
    anchor: &[f64],
    explored: &[Vec<f64>],
    near_rms: f64,
) -> Vec<Vec<f64>> {
    let d = anchor.len();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for u in explored {
        if u.len() != d {
            continue;
        }
        let mut v: Vec<f64> = u.iter().zip(anchor).map(|(a, b)| a - b).collect();
        let norm0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm0 <= 0.0 || norm0 / (d as f64).sqrt() > near_rms {
            continue;
        }
        for q in &basis {
            let p: f64 = v.iter().zip(q).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-6 * norm0 {
            basis.push(v.iter().map(|x| x / norm).collect());
        }
        if basis.len() >= d {
            break;
        }
    }
    basis
}

/// The squared norm of the part of `e` orthogonal to `basis` (1 for a unit `e` no explored
/// direction covers, 0 for one they span).
pub(crate) fn uncovered_part(basis: &[Vec<f64>], e: &[f64]) -> f64 {
    let mut r = e.to_vec();
    for q in basis {
        let p: f64 = r.iter().zip(q).map(|(a, b)| a * b).sum();
        r.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
    }
    r.iter().map(|x| x * x).sum::<f64>()
}

/// Unit directions to choose from: the coordinate axes up to
/// [`AXIS_CANDIDATES_MAX_DIM`], seeded random directions above.
fn candidate_directions(d: usize, seed: u64) -> Vec<Vec<f64>> {
    if d <= AXIS_CANDIDATES_MAX_DIM {
        (0..d)
            .map(|i| (0..d).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
            .collect()
    } else {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        (0..RANDOM_CANDIDATES)
            .map(|_| {
                let v: Vec<f64> = (0..d).map(|_| rng.sample(StandardNormal)).collect();
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
                v.iter().map(|x| x / n).collect()
            })
            .collect()
    }
}

/// How far `anchor + t e` (t >= 0) stays in the unit box.
fn room(anchor: &[f64], e: &[f64]) -> f64 {
    anchor.iter().zip(e).fold(f64::INFINITY, |t, (a, ei)| {
        if *ei > 0.0 {
            t.min((1.0 - a) / ei)
        } else if *ei < 0.0 {
            t.min(a / -ei)
        } else {
            t
        }
    })
}

/// Central-difference step (unit box) of the slopes in [`toward_data_step`].
const SLOPE_STEP_UNIT: f64 = 1e-3;

/// The best point moved by `step` (max norm, unit box) along the candidate direction where
/// the measurements pull hardest, by the linearisation of `predict` (the fitted
/// surrogate's outputs at a unit point, in the order of `residual`, the best run's model
/// minus measurement): the direction `e` whose best one-dimensional move most lowers
/// `|r + t g|^2`, `g` the outputs' slope along `e`, i.e. the largest `(g.r)^2 / |g|^2`,
/// taken the way that lowers it. A direction with less than half the step of room that
/// way is skipped. None when no direction lowers the misfit (slopes zero, not finite, or
/// blocked by the box).
pub(crate) fn toward_data_step(
    anchor: &[f64],
    residual: &[f64],
    predict: impl Fn(&[f64]) -> Option<Vec<f64>>,
    weight: impl Fn(&[f64]) -> f64,
    step: f64,
    seed: u64,
) -> Option<Vec<f64>> {
    let d = anchor.len();
    let mut best: Option<(f64, Vec<f64>)> = None;
    for e in candidate_directions(d, seed) {
        let neg: Vec<f64> = e.iter().map(|x| -x).collect();
        let (h_up, h_down) = (
            room(anchor, &e).min(SLOPE_STEP_UNIT),
            room(anchor, &neg).min(SLOPE_STEP_UNIT),
        );
        if h_up + h_down <= 0.0 {
            continue;
        }
        let at = |t: f64| -> Vec<f64> { anchor.iter().zip(&e).map(|(a, ei)| a + t * ei).collect() };
        let (Some(up), Some(down)) = (predict(&at(h_up)), predict(&at(-h_down))) else {
            continue;
        };
        if up.len() != residual.len() || down.len() != residual.len() {
            continue;
        }
        let g: Vec<f64> = up
            .iter()
            .zip(&down)
            .map(|(u, v)| (u - v) / (h_up + h_down))
            .collect();
        let gr: f64 = g.iter().zip(residual).map(|(a, b)| a * b).sum();
        let gg: f64 = g.iter().map(|x| x * x).sum();
        let gain = weight(&e) * gr * gr / gg;
        if !gain.is_finite() || gain <= 0.0 {
            continue;
        }
        // Move against the slope's projection on the residual: that lowers the misfit.
        let dir = if gr > 0.0 { neg } else { e };
        let scale = step / dir.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
        if room(anchor, &dir) < 0.5 * scale {
            continue;
        }
        // Strictly greater: ties keep the first candidate (deterministic).
        let better = match &best {
            Some((b, _)) => gain > *b,
            None => true,
        };
        if better {
            let moved = anchor
                .iter()
                .zip(&dir)
                .map(|(a, di)| (a + scale * di).clamp(0.0, 1.0))
                .collect();
            best = Some((gain, moved));
        }
    }
    best.map(|(_, moved)| moved)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_the_axis_no_run_explored() {
        let anchor = [0.5, 0.5, 0.8];
        let explored = vec![vec![0.55, 0.5, 0.8], vec![0.5, 0.45, 0.8]];
        let p = least_covered_step(&anchor, &explored, 1.0, 0.05, 0);
        assert_eq!(p[0], 0.5);
        assert_eq!(p[1], 0.5);
        // Towards the interior: 0.8 - 0.05.
        assert!((p[2] - 0.75).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn far_runs_do_not_count_and_results_are_deterministic() {
        let anchor = [0.2, 0.5];
        let explored = vec![vec![1.0, 0.5]];
        // The far run is ignored: axis 0 is still uncovered and wins the tie.
        let p = least_covered_step(&anchor, &explored, 0.1, 0.1, 3);
        assert!((p[0] - 0.3).abs() < 1e-12 && p[1] == 0.5, "{p:?}");
        let big = vec![0.5; 300];
        let a = least_covered_step(&big, &[], 0.1, 0.05, 7);
        let b = least_covered_step(&big, &[], 0.1, 0.05, 7);
        assert_eq!(a, b);
        let moved = a
            .iter()
            .zip(&big)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!((moved - 0.05).abs() < 1e-12);
    }

    /// Outputs `y = J u` with two outputs and three parameters.
    fn linear(u: &[f64]) -> Option<Vec<f64>> {
        Some(vec![2.0 * u[0] + 0.1 * u[2], 0.5 * u[1] - 0.1 * u[2]])
    }

    #[test]
    fn steps_along_the_axis_the_residual_pulls_hardest_and_the_way_that_lowers_it() {
        let anchor = [0.5, 0.5, 0.5];
        // Model minus measurement: output 1 reads 0.4 too high, output 0 is right.
        // Gains (g.r)^2/|g|^2: axis 0 0, axis 1 0.16, axis 2 0.0008.
        let r = [0.0, 0.4];
        let p = toward_data_step(&anchor, &r, linear, |_| 1.0, 0.05, 0).expect("a step");
        assert_eq!((p[0], p[2]), (0.5, 0.5), "{p:?}");
        // Reading too high with a positive slope: the step goes down.
        assert!((p[1] - 0.45).abs() < 1e-12, "{p:?}");
        // Flip the residual: the same axis, the other way.
        let p = toward_data_step(&anchor, &[0.0, -0.4], linear, |_| 1.0, 0.05, 0).expect("a step");
        assert!((p[1] - 0.55).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn a_direction_blocked_by_the_box_or_without_pull_is_not_taken() {
        // Axis 1 pulls hardest but down, and the anchor sits on its lower bound: axis 2
        // (the only other with a pull) is taken instead.
        let anchor = [0.5, 0.0, 0.5];
        let p = toward_data_step(&anchor, &[0.0, 0.4], linear, |_| 1.0, 0.05, 0).expect("a step");
        assert_eq!((p[0], p[1]), (0.5, 0.0), "{p:?}");
        // Slope -0.1 on output 1, residual +0.4: up lowers it.
        assert!((p[2] - 0.55).abs() < 1e-12, "{p:?}");
        // No residual: nothing pulls.
        assert!(toward_data_step(&[0.5; 3], &[0.0, 0.0], linear, |_| 1.0, 0.05, 0).is_none());
        // A prediction that fails everywhere: no step.
        assert!(toward_data_step(&[0.5; 3], &[0.1, 0.4], |_| None, |_| 1.0, 0.05, 0).is_none());
        // Above 256 parameters: random directions, deterministic per seed, of the step's
        // max-norm length.
        let big = vec![0.5; 300];
        let pred = |u: &[f64]| Some(vec![u.iter().take(10).sum::<f64>()]);
        let a = toward_data_step(&big, &[1.0], pred, |_| 1.0, 0.05, 7).expect("a step");
        assert_eq!(
            Some(a.clone()),
            toward_data_step(&big, &[1.0], pred, |_| 1.0, 0.05, 7)
        );
        let moved = a
            .iter()
            .zip(&big)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!((moved - 0.05).abs() < 1e-12);
        // The step lowers the linearised misfit: the first ten coordinates' sum drops.
        assert!(a.iter().take(10).sum::<f64>() < 5.0);
    }
}
