//! Geometry steps: when the corrected surrogate has nothing more to say (its optimum is
//! the best run itself), the loop runs the model one step from the best point along the
//! direction its earlier runs covered least, so the next linear correction learns the
//! model's slope there (as derivative-free trust-region methods improve their sample
//! geometry).

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
    // Orthonormal basis of the explored directions (modified Gram-Schmidt).
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
    let candidates: Vec<Vec<f64>> = if d <= AXIS_CANDIDATES_MAX_DIM {
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
    };
    let uncovered = |e: &Vec<f64>| {
        let mut r = e.clone();
        for q in &basis {
            let p: f64 = r.iter().zip(q).map(|(a, b)| a * b).sum();
            r.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
        }
        r.iter().map(|x| x * x).sum::<f64>()
    };
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
}
