//! The ambiguity check: two explanations of different footprints that fit equally well
//! leave the diagnosis undecided; one that is clearly better, or two of the same
//! footprint, or two that change the same readings alike (as a bypass behind the next
//! rack), do not.

use kalibre_core::diagnose::{
    diagnose, DiagnoseSettings, Diagnosis, Hypothesis, HypothesisParam, Residuals, RowInfo,
};
use ndarray::Array2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

const SNAPSHOTS: usize = 3;
const OUTPUTS: usize = 30;
const SIGMA: f64 = 0.1;

fn rows() -> Vec<RowInfo> {
    (0..SNAPSHOTS * OUTPUTS)
        .map(|i| RowInfo {
            output: format!("s{}", i % OUTPUTS),
            group: "cold".into(),
            snapshot: format!("t{}", i / OUTPUTS),
        })
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `v` with its components along each of `basis` (orthonormal) removed.
fn orthogonalise(v: &mut [f64], basis: &[Vec<f64>]) {
    for q in basis {
        let c = dot(v, q);
        v.iter_mut().zip(q).for_each(|(x, q)| *x -= c * q);
    }
}

fn normalised(mut v: Vec<f64>) -> Vec<f64> {
    let n = dot(&v, &v).sqrt();
    v.iter_mut().for_each(|x| *x /= n);
    v
}

/// One calibrated column `j` and two footprints `a`, `b`, mutually orthogonal and of
/// equal norm, and noise orthogonal to all three: whatever explains `a` leaves exactly
/// what explains `b` does, by symmetry.
struct Setup {
    j: Vec<f64>,
    a: Vec<f64>,
    b: Vec<f64>,
    noise: Vec<f64>,
}

fn setup(seed: u64) -> Setup {
    let n = SNAPSHOTS * OUTPUTS;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut draw = || -> Vec<f64> { (0..n).map(|_| normal.sample(&mut rng)).collect() };
    let j = normalised(draw());
    let mut a = draw();
    orthogonalise(&mut a, std::slice::from_ref(&j));
    let a = normalised(a);
    let mut b = draw();
    orthogonalise(&mut b, &[j.clone(), a.clone()]);
    let b = normalised(b);
    let mut noise = draw();
    orthogonalise(&mut noise, &[j.clone(), a.clone(), b.clone()]);
    let scale = SIGMA * (n as f64).sqrt() / dot(&noise, &noise).sqrt();
    noise.iter_mut().for_each(|x| *x *= scale);
    Setup { j, a, b, noise }
}

fn column(v: &[f64]) -> Array2<f64> {
    Array2::from_shape_fn((v.len(), 1), |(i, _)| v[i])
}

fn hyp(name: &str, col: &[f64]) -> Hypothesis {
    Hypothesis::new(
        name,
        vec![HypothesisParam::bounded(format!("{name}/q"), -10.0, 10.0)],
        column(col),
    )
}

/// Residuals `-(ka a + kb b) + noise`, and the current parameter a little off.
fn residuals(s: &Setup, ka: f64, kb: f64) -> Residuals {
    let r: Vec<f64> = (0..s.j.len())
        .map(|i| 0.2 * s.j[i] - ka * s.a[i] - kb * s.b[i] + s.noise[i])
        .collect();
    Residuals::new(rows(), r, column(&s.j), vec!["alpha".into()]).unwrap()
}

fn settings(check: bool) -> DiagnoseSettings {
    // Least squares, so that equal sums of squares give equal BICs exactly.
    DiagnoseSettings::new()
        .with_robust_nu(None)
        .with_single_output_check(false)
        .with_ambiguity_check(check)
}

fn get<'a>(d: &'a Diagnosis, name: &str) -> &'a kalibre_core::diagnose::HypothesisResult {
    d.hypotheses.iter().find(|h| h.name == name).unwrap()
}

#[test]
fn two_footprints_that_fit_equally_leave_it_undecided() {
    let s = setup(3);
    let res = residuals(&s, 1.0, 1.0);
    let hyps = [hyp("a", &s.a), hyp("b", &s.b)];
    let off = diagnose(&res, &hyps, &settings(false)).unwrap();
    // Without the check both are significant, at the same BIC.
    assert!(get(&off, "a").significant && get(&off, "b").significant);
    assert!((get(&off, "a").delta_bic - get(&off, "b").delta_bic).abs() < 1e-6);
    assert!(get(&off, "a").delta_bic < -10.0);
    let on = diagnose(&res, &hyps, &settings(true)).unwrap();
    assert_eq!(on.significant().count(), 0, "{on:#?}");
    assert_eq!(get(&on, "a").ambiguous_with, ["b"]);
    assert_eq!(get(&on, "b").ambiguous_with, ["a"]);
}

#[test]
fn a_clearly_better_explanation_is_still_named() {
    let s = setup(5);
    // Both significant alone, but `b` explains four times the sum of squares.
    let res = residuals(&s, 2.0, 4.0);
    let hyps = [hyp("a", &s.a), hyp("b", &s.b)];
    let off = diagnose(&res, &hyps, &settings(false)).unwrap();
    assert!(get(&off, "a").significant, "{off:#?}");
    assert!(get(&off, "b").delta_bic < get(&off, "a").delta_bic - 6.0);
    let on = diagnose(&res, &hyps, &settings(true)).unwrap();
    let named: Vec<&str> = on.significant().map(|h| h.name.as_str()).collect();
    assert_eq!(named.first(), Some(&"b"), "{on:#?}");
    assert!(on.hypotheses.iter().all(|h| h.ambiguous_with.is_empty()));
}

#[test]
fn two_placements_of_one_footprint_are_not_ambiguous() {
    let s = setup(7);
    let res = residuals(&s, 0.0, 1.0);
    // `b2` is `b` at twice the size: the same footprint, so the two are collinear and
    // the more modest fit is kept (its fitted change is the smaller share of its range).
    let b2: Vec<f64> = s.b.iter().map(|x| 2.0 * x).collect();
    let hyps = [hyp("b", &s.b), hyp("b2", &b2)];
    let on = diagnose(&res, &hyps, &settings(true)).unwrap();
    let named: Vec<&str> = on.significant().map(|h| h.name.as_str()).collect();
    assert_eq!(named, ["b2"], "{on:#?}");
    assert!(on.hypotheses.iter().all(|h| h.ambiguous_with.is_empty()));
}

/// Two explanations at `angle_cos` to each other (not collinear), with the residual
/// half-way between them: both fit equally, each explaining `angle_cos` of what the
/// other does.
fn two_at_angle(angle_cos: f64) -> Diagnosis {
    let s = setup(11);
    let sin = (1.0 - angle_cos * angle_cos).sqrt();
    let near: Vec<f64> =
        s.b.iter()
            .zip(&s.a)
            .map(|(b, a)| angle_cos * b + sin * a)
            .collect();
    let mid = normalised(s.b.iter().zip(&near).map(|(b, n)| b + n).collect());
    let r: Vec<f64> = (0..s.j.len())
        .map(|i| 0.2 * s.j[i] - 2.0 * mid[i] + s.noise[i])
        .collect();
    let res = Residuals::new(rows(), r, column(&s.j), vec!["alpha".into()]).unwrap();
    let hyps = [hyp("here", &s.b), hyp("next door", &near)];
    let d = diagnose(&res, &hyps, &settings(true)).unwrap();
    assert!(
        (get(&d, "here").delta_bic - get(&d, "next door").delta_bic).abs() < 1.0,
        "{d:#?}"
    );
    assert!(get(&d, "here").delta_bic < -10.0, "{d:#?}");
    assert!(get(&d, "here").collinear_with.is_empty(), "{d:#?}");
    d
}

#[test]
fn explanations_that_change_the_same_readings_alike_are_one_footprint() {
    // At cosine 0.95 both say the same readings moved the same way: one is named.
    let alike = two_at_angle(0.95);
    assert_eq!(alike.significant().count(), 2, "{alike:#?}");
    assert!(alike.hypotheses.iter().all(|h| h.ambiguous_with.is_empty()));
    // At 0.7 they tell different stories about the data: undecided.
    let apart = two_at_angle(0.7);
    assert_eq!(apart.significant().count(), 0, "{apart:#?}");
    assert_eq!(get(&apart, "here").ambiguous_with, ["next door"]);
}
