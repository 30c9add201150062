//! Seeds, the initial design, the first fit's augmentation, and moving proposals off
//! failed points. Everything here is a pure function of its seed.

use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::{Error, ParamSpace, Result, Sample};

/// Random streams derived from the calibration seed.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Stream {
    Augment = 1,
    Fit = 2,
    Search = 3,
    Perturb = 4,
    Explore = 5,
    Geometry = 6,
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The seed of one stream at one iteration: a resumed calibration derives the same ones.
pub(crate) fn derive_seed(seed: u64, iteration: usize, stream: Stream) -> u64 {
    splitmix64(seed ^ splitmix64((iteration as u64) << 8 | stream as u64))
}

/// Folds a coordinate back into `[0, 1]` by reflection (clamping would pile noise on the bounds).
fn reflect(u: f64) -> f64 {
    let m = u.rem_euclid(2.0);
    if m > 1.0 {
        2.0 - m
    } else {
        m
    }
}

/// Refuses a run budget smaller than the initial design (`points` x `snapshots` runs).
pub(crate) fn check_budget(
    max_model_runs: Option<usize>,
    points: usize,
    snapshots: usize,
) -> Result<()> {
    let design_runs = points * snapshots;
    match max_model_runs {
        Some(budget) if budget < design_runs => Err(Error::InvalidSetting {
            name: "max_model_runs".into(),
            reason: format!(
                "{budget} is smaller than the initial design's {design_runs} runs ({points} \
                 points x {snapshots} snapshots)"
            ),
        }),
        _ => Ok(()),
    }
}

/// Lower bounds, upper bounds, midpoint (unit box), then the initial values unless they
/// coincide with one of those. Returns the points (unit box) and the index of the initial one.
/// With `bounds` (physical lower and upper values within the space), the first three
/// points span that box instead of the whole space: a domain's plausible range, where
/// the surrogate's first fit matters, rather than its hard limits.
pub(crate) fn initial_design(
    space: &ParamSpace,
    bounds: Option<&(Vec<f64>, Vec<f64>)>,
) -> Result<(Vec<Vec<f64>>, usize)> {
    let d = space.dim();
    let initial = space.to_unit(&space.initial())?;
    let mut points = match bounds {
        None => vec![vec![0.0; d], vec![1.0; d], vec![0.5; d]],
        Some((lower, upper)) => {
            check_bounds(space, lower, upper)?;
            let (lo, hi) = (space.to_unit(lower)?, space.to_unit(upper)?);
            let mid = lo.iter().zip(&hi).map(|(a, b)| 0.5 * (a + b)).collect();
            vec![lo, hi, mid]
        }
    };
    let phys: Vec<Vec<f64>> = points
        .iter()
        .map(|u| space.from_unit(u))
        .collect::<Result<_>>()?;
    let init_phys = space.initial();
    let idx = match phys.iter().position(|p| *p == init_phys) {
        Some(i) => i,
        None => {
            points.push(initial);
            points.len() - 1
        }
    };
    Ok((points, idx))
}

/// Design bounds must be finite, inside the space's bounds and increasing, per parameter.
fn check_bounds(space: &ParamSpace, lower: &[f64], upper: &[f64]) -> Result<()> {
    let bad = |reason: String| {
        Err(Error::InvalidSetting {
            name: "design_bounds".into(),
            reason,
        })
    };
    if lower.len() != space.dim() || upper.len() != space.dim() {
        return bad(format!(
            "{} lower and {} upper values for {} parameters",
            lower.len(),
            upper.len(),
            space.dim()
        ));
    }
    for ((p, &lo), &hi) in space.params().iter().zip(lower).zip(upper) {
        if !(lo.is_finite() && hi.is_finite() && lo < hi && lo >= p.lower && hi <= p.upper) {
            return bad(format!(
                "`{}`: [{lo}, {hi}] is not an increasing range within its bounds [{}, {}]",
                p.name, p.lower, p.upper
            ));
        }
    }
    Ok(())
}

/// The first fit's training set: per run, the run itself plus `copies - 1` copies with
/// Gaussian noise on the parameters (unit box, reflected at the bounds), outputs kept.
pub(crate) fn augment(
    space: &ParamSpace,
    runs: &[(Vec<f64>, Sample)],
    copies: usize,
    sigma: f64,
    seed: u64,
) -> Result<Vec<Sample>> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut out = Vec::with_capacity(runs.len() * copies);
    for (unit, sample) in runs {
        out.push(sample.clone());
        for _ in 1..copies {
            let u: Vec<f64> = unit
                .iter()
                .map(|&u| reflect(u + sigma * rng.sample::<f64, _>(StandardNormal)))
                .collect();
            out.push(Sample {
                snapshot: sample.snapshot,
                params: space.from_unit(&u)?,
                outputs: sample.outputs.clone(),
                weight: sample.weight,
            });
        }
    }
    Ok(out)
}

/// Max-norm distance in the unit box.
pub(crate) fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Moves `unit` with seeded Gaussian noise until it is farther than `tol` from every
/// failed point (at most 100 draws; noise makes a repeat all but impossible).
pub(crate) fn perturb(
    unit: &[f64],
    failed: &[Vec<f64>],
    tol: f64,
    sigma: f64,
    seed: u64,
) -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut u = unit.to_vec();
    for _ in 0..100 {
        u = unit
            .iter()
            .map(|&x| reflect(x + sigma * rng.sample::<f64, _>(StandardNormal)))
            .collect();
        if failed.iter().all(|f| distance(f, &u) > tol) {
            break;
        }
    }
    u
}

/// Weights samples by how close their run came to the measurements of its snapshot: a
/// run whose MAE is `m` times the best run's weighs `exp(-((m - 1) / width)^2 / 2)`, so
/// far-off runs (an initial design at extreme bounds) stop dominating the fit while the
/// runs near the answer shape it.
pub(crate) fn focus<S>(
    obs: &crate::Observations<S>,
    samples: &[Sample],
    width: f64,
) -> Vec<Sample> {
    let mae = |s: &Sample| {
        let measured = &obs.snapshots()[s.snapshot].measured;
        let (sum, n) = s
            .outputs
            .iter()
            .zip(measured)
            .filter_map(|(o, m)| m.map(|m| (o - m).abs()))
            .fold((0.0, 0usize), |(a, n), e| (a + e, n + 1));
        if n == 0 {
            f64::NAN
        } else {
            sum / n as f64
        }
    };
    let errors: Vec<f64> = samples.iter().map(mae).collect();
    let mut best = vec![f64::INFINITY; obs.snapshots().len()];
    for (s, e) in samples.iter().zip(&errors) {
        if e.is_finite() {
            best[s.snapshot] = best[s.snapshot].min(*e);
        }
    }
    samples
        .iter()
        .zip(&errors)
        .map(|(s, &e)| {
            let b = best[s.snapshot].max(1e-12);
            let w = if e.is_finite() {
                let m = (e / b - 1.0) / width;
                (-0.5 * m * m).exp()
            } else {
                0.0
            };
            Sample {
                weight: s.weight * w,
                ..s.clone()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_stays_in_box_and_is_identity_inside() {
        for &x in &[-2.7, -0.3, 0.0, 0.25, 1.0, 1.4, 3.9] {
            let r = reflect(x);
            assert!((0.0..=1.0).contains(&r), "{x} -> {r}");
        }
        assert_eq!(reflect(0.25), 0.25);
        assert!((reflect(1.25) - 0.75).abs() < 1e-15);
        assert!((reflect(-0.25) - 0.25).abs() < 1e-15);
    }

    #[test]
    fn seeds_differ_by_stream_and_iteration() {
        let a = derive_seed(7, 1, Stream::Fit);
        assert_ne!(a, derive_seed(7, 1, Stream::Search));
        assert_ne!(a, derive_seed(7, 2, Stream::Fit));
        assert_ne!(a, derive_seed(8, 1, Stream::Fit));
        assert_eq!(a, derive_seed(7, 1, Stream::Fit));
    }

    #[test]
    fn design_dedupes_an_initial_value_at_the_midpoint() {
        use crate::Scale;
        let s = ParamSpace::new()
            .with("a", 0.0, 2.0, 1.0, Scale::Linear)
            .unwrap();
        let (pts, idx) = initial_design(&s, None).unwrap();
        assert_eq!(pts.len(), 3);
        assert_eq!(idx, 2);
        let s = ParamSpace::new()
            .with("a", 0.0, 2.0, 0.3, Scale::Linear)
            .unwrap();
        let (pts, idx) = initial_design(&s, None).unwrap();
        assert_eq!((pts.len(), idx), (4, 3));
    }

    #[test]
    fn design_bounds_set_the_span_and_bad_ones_name_the_parameter() {
        use crate::Scale;
        let s = ParamSpace::new()
            .with("alpha", 0.01, 3.0, 0.2, Scale::Log)
            .unwrap()
            .with("offset", -1.0, 1.0, 0.0, Scale::Linear)
            .unwrap();
        let bounds = (vec![0.1, -1.0], vec![0.4, 1.0]);
        let (pts, idx) = initial_design(&s, Some(&bounds)).unwrap();
        assert_eq!((pts.len(), idx), (4, 3));
        let phys: Vec<Vec<f64>> = pts.iter().map(|u| s.from_unit(u).unwrap()).collect();
        for (got, want) in phys[..2].iter().zip([&bounds.0, &bounds.1]) {
            assert!(got.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12));
        }
        // The midpoint is the unit-box (here: geometric) middle of the box.
        assert!((phys[2][0] - (0.1f64 * 0.4).sqrt()).abs() < 1e-12);
        assert!(phys[2][1].abs() < 1e-12);
        for bad in [
            (vec![0.4, -1.0], vec![0.1, 1.0]),      // inverted
            (vec![0.001, -1.0], vec![0.4, 1.0]),    // below the bound
            (vec![f64::NAN, -1.0], vec![0.4, 1.0]), // not a number
        ] {
            let e = initial_design(&s, Some(&bad)).unwrap_err().to_string();
            assert!(e.contains("design_bounds") && e.contains("`alpha`"), "{e}");
        }
        let e = initial_design(&s, Some(&(vec![0.1], vec![0.4])))
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 parameters"), "{e}");
    }

    #[test]
    fn perturb_leaves_the_failed_point() {
        let failed = vec![vec![0.5, 0.5]];
        let u = perturb(&[0.5, 0.5], &failed, 1e-9, 0.05, 3);
        assert!(distance(&u, &failed[0]) > 1e-9);
        assert!(u.iter().all(|x| (0.0..=1.0).contains(x)));
    }
}
