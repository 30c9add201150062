//! The loops that touch every coordinate at every iteration (differential evolution's
//! crossover, Adam's update, the gradient check), written to vectorise. On x86-64 CPUs
//! with AVX2 the same code is compiled a second time for 4-wide vectors and chosen at
//! run time; it performs the same IEEE operations (no FMA), so results are bit-identical.

use rand::RngCore;

/// A member and the three others its mutant `a + weight (b - c)` is made of.
pub(crate) struct Mutation<'a> {
    pub parent: &'a [f64],
    pub a: &'a [f64],
    pub b: &'a [f64],
    pub c: &'a [f64],
    pub weight: f64,
}

/// Fills `draws` (length a multiple of 4) with 16-bit uniforms, four per 64-bit draw.
pub(crate) fn fill_draws<R: RngCore + Clone>(rng: &mut R, draws: &mut [u16]) {
    // A local copy of the generator keeps its state in registers.
    let mut local = rng.clone();
    for chunk in draws.chunks_exact_mut(4) {
        let bits = local.next_u64();
        for (k, r) in chunk.iter_mut().enumerate() {
            *r = (bits >> (16 * k)) as u16;
        }
    }
    *rng = local;
}

/// Bounces a mutant coordinate `m` outside `[0, 1]` back to the point `u` of the way
/// from the parent coordinate `p` to the violated bound; `m` itself when inside.
#[inline(always)]
pub(crate) fn bounce(m: f64, p: f64, u: f64) -> f64 {
    let low = p * (1.0 - u);
    let high = p + u * (1.0 - p);
    if m < 0.0 {
        low
    } else if m > 1.0 {
        high
    } else {
        m
    }
}

/// Writes the trial: coordinate `j` comes from the (repaired) mutant when
/// `draws[j] < threshold`, else from the parent. A taken coordinate's draw is uniform
/// below the threshold, so `draw / threshold` is a fresh uniform for its repair.
pub(crate) fn crossover(out: &mut [f64], mutation: &Mutation<'_>, draws: &[u16], threshold: u32) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above. The same IEEE operations
        // run 4 wide instead of 2 (no FMA), so the result is bit-identical.
        unsafe { crossover_avx2(out, mutation, draws, threshold) };
        return;
    }
    crossover_portable(out, mutation, draws, threshold);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn crossover_avx2(out: &mut [f64], mutation: &Mutation<'_>, draws: &[u16], threshold: u32) {
    crossover_portable(out, mutation, draws, threshold);
}

#[inline(always)]
fn crossover_portable(out: &mut [f64], mutation: &Mutation<'_>, draws: &[u16], threshold: u32) {
    let Mutation {
        parent,
        a,
        b,
        c,
        weight: f,
    } = *mutation;
    let thr = f64::from(threshold);
    let inv = if threshold > 0 { 1.0 / thr } else { 0.0 };
    // Branch-free select and repair, so that the loop vectorises.
    for (((((o, &p), &ai), &bi), &ci), &r) in
        out.iter_mut().zip(parent).zip(a).zip(b).zip(c).zip(draws)
    {
        let r = f64::from(r);
        let m = bounce(ai + f * (bi - ci), p, r * inv);
        *o = if r < thr { m } else { p };
    }
}

/// Adam's coefficients for one step.
pub(crate) struct AdamStep {
    /// Learning rate over the first moment's bias correction.
    pub lr_c1: f64,
    /// Inverse of the second moment's bias correction.
    pub inv_c2: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
}

/// One Adam update of `x`, moments `m`, `v` from gradient `g`, clipped into `[0, 1]`.
pub(crate) fn adam_update(x: &mut [f64], m: &mut [f64], v: &mut [f64], g: &[f64], k: &AdamStep) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { adam_update_avx2(x, m, v, g, k) };
        return;
    }
    adam_update_portable(x, m, v, g, k);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn adam_update_avx2(x: &mut [f64], m: &mut [f64], v: &mut [f64], g: &[f64], k: &AdamStep) {
    adam_update_portable(x, m, v, g, k);
}

#[inline(always)]
fn adam_update_portable(x: &mut [f64], m: &mut [f64], v: &mut [f64], g: &[f64], k: &AdamStep) {
    let AdamStep {
        lr_c1,
        inv_c2,
        beta1,
        beta2,
        epsilon,
    } = *k;
    for (((xi, mi), vi), &gi) in x.iter_mut().zip(m).zip(v).zip(g) {
        *mi = beta1 * *mi + (1.0 - beta1) * gi;
        *vi = beta2 * *vi + (1.0 - beta2) * gi * gi;
        let step = lr_c1 * *mi / ((*vi * inv_c2).sqrt() + epsilon);
        *xi = (*xi - step).clamp(0.0, 1.0);
    }
}

/// Euclidean norm of `g`, and whether every entry is finite, in one pass.
pub(crate) fn norm_and_finite(g: &[f64]) -> (f64, bool) {
    // Four running sums break the addition chain; `gi * 0` is 0 for a finite entry
    // and NaN otherwise, so `bad` stays 0 only when all are finite.
    let mut sq = [0.0f64; 4];
    let mut bad = [0.0f64; 4];
    let chunks = g.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for k in 0..4 {
            sq[k] += c[k] * c[k];
            bad[k] += c[k] * 0.0;
        }
    }
    for (k, &gi) in rest.iter().enumerate() {
        sq[k] += gi * gi;
        bad[k] += gi * 0.0;
    }
    let norm = ((sq[0] + sq[1]) + (sq[2] + sq[3])).sqrt();
    let finite = (bad[0] + bad[1] + bad[2] + bad[3]) == 0.0;
    (norm, finite)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn members(rng: &mut Xoshiro256PlusPlus, d: usize) -> Vec<Vec<f64>> {
        (0..4)
            .map(|_| (0..d).map(|_| rng.random::<f64>()).collect())
            .collect()
    }

    #[test]
    fn dispatched_kernel_is_bit_identical_to_portable_one_and_stays_in_box() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for d in [1usize, 3, 4, 7, 64, 1001] {
            let rows = members(&mut rng, d);
            let mut draws = vec![0u16; d.div_ceil(4) * 4];
            fill_draws(&mut rng, &mut draws);
            for (weight, threshold) in [(0.8, 39322), (2.0, 65536), (0.5, 0), (1.7, 30000)] {
                let m = Mutation {
                    parent: &rows[0],
                    a: &rows[1],
                    b: &rows[2],
                    c: &rows[3],
                    weight,
                };
                let (mut fast, mut portable) = (vec![0.0; d], vec![0.0; d]);
                crossover(&mut fast, &m, &draws, threshold);
                crossover_portable(&mut portable, &m, &draws, threshold);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&fast), bits(&portable), "d {d}");
                assert!(fast.iter().all(|v| (0.0..=1.0).contains(v)), "d {d}");
                for j in 0..d {
                    let taken = u32::from(draws[j]) < threshold;
                    if !taken {
                        assert_eq!(fast[j], rows[0][j]);
                    }
                }
            }
        }
    }

    #[test]
    fn adam_kernel_is_bit_identical_to_portable_one() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for d in [1usize, 5, 333] {
            let mut draw = |s: f64| (0..d).map(|_| s * rng.random::<f64>()).collect::<Vec<_>>();
            let (x0, m0, v0, g) = (draw(1.0), draw(1.0), draw(1.0), draw(40.0));
            let k = AdamStep {
                lr_c1: 0.7,
                inv_c2: 3.0,
                beta1: 0.9,
                beta2: 0.999,
                epsilon: 1e-8,
            };
            let (mut x1, mut m1, mut v1) = (x0.clone(), m0.clone(), v0.clone());
            let (mut x2, mut m2, mut v2) = (x0.clone(), m0.clone(), v0.clone());
            adam_update(&mut x1, &mut m1, &mut v1, &g, &k);
            adam_update_portable(&mut x2, &mut m2, &mut v2, &g, &k);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&x1), bits(&x2));
            assert_eq!(bits(&m1), bits(&m2));
            assert_eq!(bits(&v1), bits(&v2));
            assert!(x1.iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }

    #[test]
    fn norm_and_finite_flags_any_non_finite_entry() {
        let g = vec![3.0, 4.0, 0.0, 0.0, 12.0];
        let (n, ok) = norm_and_finite(&g);
        assert!((n - 13.0).abs() < 1e-12 && ok);
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for pos in 0..5 {
                let mut h = g.clone();
                h[pos] = bad;
                assert!(!norm_and_finite(&h).1, "{bad} at {pos}");
            }
        }
        assert_eq!(norm_and_finite(&[]), (0.0, true));
    }

    #[test]
    fn bounce_lands_between_parent_and_violated_bound() {
        assert_eq!(bounce(0.3, 0.9, 0.5), 0.3);
        assert!((bounce(-0.2, 0.4, 0.25) - 0.3).abs() < 1e-15);
        assert!((bounce(1.4, 0.6, 0.5) - 0.8).abs() < 1e-15);
        assert_eq!(bounce(-1.0, 0.0, 0.7), 0.0);
        assert_eq!(bounce(2.0, 1.0, 0.7), 1.0);
    }
}
