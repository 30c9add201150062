//! A trust region for the search: the surrogate is searched only within a box around the
//! best point, which grows after a step that improved the model and shrinks after one
//! that did not (trust-region model management).

use std::time::Instant;

use crate::{Objective, Result, SearchOutcome, Searcher};

/// Searches `objective` from `start` (unit box) until `deadline`: within the box of
/// half-width `radius` around `centre` when `region` gives them, the whole box otherwise;
/// the outcome's point is in whole-box coordinates either way.
pub(crate) fn search_within(
    searcher: &dyn Searcher,
    objective: &dyn Objective,
    start: &[f64],
    region: Option<(&[f64], f64)>,
    seed: u64,
    deadline: Option<Instant>,
) -> Result<SearchOutcome> {
    let Some((centre, radius)) = region else {
        return searcher.search_until(objective, start, seed, deadline);
    };
    let sub = SubBox::around(objective, centre, radius);
    let mut o = searcher.search_until(&sub, &sub.to_inner(start), seed, deadline)?;
    if o.best_unit.len() == start.len() {
        o.best_unit = sub.to_outer(&o.best_unit);
    }
    Ok(o)
}

/// The objective restricted to `[lo, hi]`, seen by the searcher as the unit box.
pub(crate) struct SubBox<'o> {
    inner: &'o dyn Objective,
    lo: Vec<f64>,
    span: Vec<f64>,
}

impl<'o> SubBox<'o> {
    /// The box of half-width `radius` around `centre`, clipped to the unit box.
    pub(crate) fn around(inner: &'o dyn Objective, centre: &[f64], radius: f64) -> Self {
        let lo: Vec<f64> = centre.iter().map(|c| (c - radius).max(0.0)).collect();
        let span = centre
            .iter()
            .zip(&lo)
            .map(|(c, l)| (c + radius).min(1.0) - l)
            .collect();
        SubBox { inner, lo, span }
    }

    /// Inner (searcher) coordinates to unit-box coordinates.
    pub(crate) fn to_outer(&self, v: &[f64]) -> Vec<f64> {
        v.iter()
            .zip(&self.lo)
            .zip(&self.span)
            .map(|((v, l), s)| (l + v.clamp(0.0, 1.0) * s).clamp(0.0, 1.0))
            .collect()
    }

    /// Unit-box coordinates to inner coordinates.
    pub(crate) fn to_inner(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .zip(&self.lo)
            .zip(&self.span)
            .map(|((u, l), s)| {
                if *s > 0.0 {
                    ((u - l) / s).clamp(0.0, 1.0)
                } else {
                    0.5
                }
            })
            .collect()
    }
}

impl Objective for SubBox<'_> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }

    fn cost(&self, x: &[f64]) -> f64 {
        self.inner.cost(&self.to_outer(x))
    }

    fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
        let (c, g) = self.inner.cost_and_gradient(&self.to_outer(x));
        (c, g.iter().zip(&self.span).map(|(g, s)| g * s).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Sphere;
    impl Objective for Sphere {
        fn dim(&self) -> usize {
            2
        }
        fn cost(&self, x: &[f64]) -> f64 {
            x.iter().map(|v| (v - 0.9) * (v - 0.9)).sum()
        }
        fn cost_and_gradient(&self, x: &[f64]) -> (f64, Vec<f64>) {
            (self.cost(x), x.iter().map(|v| 2.0 * (v - 0.9)).collect())
        }
    }

    #[test]
    fn sub_box_maps_and_scales_the_gradient() {
        let b = SubBox::around(&Sphere, &[0.5, 0.95], 0.1);
        let u = b.to_outer(&[0.0, 1.0]);
        assert!((u[0] - 0.4).abs() < 1e-12 && (u[1] - 1.0).abs() < 1e-12);
        let v = b.to_inner(&[0.45, 0.9]);
        assert!((v[0] - 0.25).abs() < 1e-12);
        // Gradient against finite differences in inner coordinates.
        let x = [0.3, 0.6];
        let (_, g) = b.cost_and_gradient(&x);
        for i in 0..2 {
            let mut p = x;
            let mut m = x;
            p[i] += 1e-6;
            m[i] -= 1e-6;
            let fd = (b.cost(&p) - b.cost(&m)) / 2e-6;
            assert!((fd - g[i]).abs() < 1e-6, "{fd} vs {}", g[i]);
        }
    }
}
