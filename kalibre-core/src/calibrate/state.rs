//! What the loop accumulates: run counts, training samples, which points ran and failed,
//! and the best point so far.

use super::report::PassedOver;
use super::runner::RunResult;
use super::RunCounts;
use crate::{Observations, Regularizer, Result, Sample, Validation, Validator};

/// The best point so far.
pub(crate) struct BestPoint {
    pub(crate) iteration: usize,
    pub(crate) unit: Vec<f64>,
    pub(crate) params: Vec<f64>,
    pub(crate) score: f64,
    /// What points are compared by: the score, plus the weighted prior when
    /// [`crate::Settings::prior_in_best`] is set.
    pub(crate) rank: f64,
    pub(crate) validation: Validation,
    pub(crate) outputs: Vec<Vec<f64>>,
}

impl BestPoint {
    /// What its runs gave, as [`State::absorb`] returned it: a best point ran at every one
    /// of the `n_snap` snapshots.
    pub(crate) fn eval(&self, n_snap: usize) -> PointEval {
        PointEval {
            validation: Some(self.validation.clone()),
            score: Some(self.score),
            ok_runs: n_snap,
        }
    }
}

/// What one point's runs gave.
pub(crate) struct PointEval {
    pub(crate) validation: Option<Validation>,
    pub(crate) score: Option<f64>,
    pub(crate) ok_runs: usize,
}

/// Everything the loop accumulates.
#[derive(Default)]
pub(crate) struct State<'r> {
    pub(crate) samples: Vec<Sample>,
    pub(crate) ok_units: Vec<Vec<f64>>,
    /// Per successful point (as `ok_units`): physical parameters and outputs per snapshot.
    pub(crate) ok_runs: Vec<(Vec<f64>, Vec<Vec<f64>>)>,
    pub(crate) failed_units: Vec<Vec<f64>>,
    pub(crate) best: Option<BestPoint>,
    pub(crate) counts: RunCounts,
    /// While set, `absorb` books runs but leaves the best point to [`State::promote`]:
    /// the weighted polish's optimum is not the lowest MAE.
    pub(crate) best_held: bool,
    /// The regulariser and its weight, when the best point is judged with the prior.
    pub(crate) prior: Option<(&'r dyn Regularizer, f64)>,
    /// The lowest-score complete run: iteration, score and rank (what the report says
    /// when the prior passed it over).
    pub(crate) lowest: Option<(usize, f64, f64)>,
}

impl<'r> State<'r> {
    /// An empty state whose best run is judged with `prior` (regulariser, weight) too.
    pub(crate) fn judged_with(prior: Option<(&'r dyn Regularizer, f64)>) -> Self {
        State {
            prior,
            ..State::default()
        }
    }

    /// The lowest-score run when the prior passed it over for `best`.
    pub(crate) fn passed_over(&self, best: &BestPoint) -> Option<PassedOver> {
        let (iteration, score, rank) = self.lowest?;
        (score < best.score && rank > best.rank && rank.is_finite()).then_some(PassedOver {
            iteration,
            score,
            prior: rank - score,
        })
    }

    /// The weighted prior at `params` when it judges the best point (0 otherwise; not
    /// finite there: infinite), in the score's units: what [`Self::rank`] adds.
    pub(crate) fn prior_cost(&self, params: &[f64]) -> f64 {
        self.rank(0.0, params)
    }

    /// A point's rank: its score plus, when the prior judges too, the weighted prior at
    /// its parameters (both in the score's units for the DC prior: kelvin). A prior that
    /// is not finite there ranks the point last.
    fn rank(&self, score: f64, params: &[f64]) -> f64 {
        match self.prior {
            Some((r, w)) if w > 0.0 => {
                let prior = w * r.value(params);
                if prior.is_finite() {
                    score + prior
                } else {
                    f64::INFINITY
                }
            }
            _ => score,
        }
    }

    /// Books one point's runs: counts, training samples, validation and the best point.
    pub(crate) fn absorb<S, V: Validator>(
        &mut self,
        validator: &V,
        obs: &Observations<S>,
        iteration: usize,
        unit: &[f64],
        params: &[f64],
        results: Vec<RunResult>,
    ) -> Result<PointEval> {
        let mut outputs = Vec::with_capacity(results.len());
        let mut ok_runs = 0;
        for (s, r) in results.into_iter().enumerate() {
            self.counts.total += 1;
            if r.cached {
                self.counts.cached += 1;
            } else {
                self.counts.new += 1;
            }
            match r.result {
                Ok(o) => {
                    ok_runs += 1;
                    self.samples.push(Sample {
                        snapshot: s,
                        params: params.to_vec(),
                        outputs: o.values.clone(),
                        weight: 1.0,
                    });
                    outputs.push(o.values);
                }
                Err(_) => self.counts.failed += 1,
            }
        }
        if ok_runs < obs.snapshots().len() {
            self.failed_units.push(unit.to_vec());
            return Ok(PointEval {
                validation: None,
                score: None,
                ok_runs,
            });
        }
        self.ok_units.push(unit.to_vec());
        self.ok_runs.push((params.to_vec(), outputs.clone()));
        let validation = validator.validate(obs, &outputs)?;
        let score = validator.score(&validation);
        let rank = self.rank(score, params);
        if score.is_finite() && self.lowest.is_none_or(|(_, s, _)| score < s) {
            self.lowest = Some((iteration, score, rank));
        }
        if !self.best_held && score.is_finite() && self.best.as_ref().is_none_or(|b| rank < b.rank)
        {
            self.best = Some(BestPoint {
                iteration,
                unit: unit.to_vec(),
                params: params.to_vec(),
                score,
                rank,
                validation: validation.clone(),
                outputs,
            });
        }
        Ok(PointEval {
            validation: Some(validation),
            score: Some(score),
            ok_runs,
        })
    }

    /// Makes a point that ran at every snapshot the best one whatever its score: the
    /// weighted polish's optimum, which minimises a weighted misfit rather than the MAE.
    pub(crate) fn promote<S, V: Validator>(
        &mut self,
        validator: &V,
        obs: &Observations<S>,
        iteration: usize,
        unit: &[f64],
        params: &[f64],
        outputs: Vec<Vec<f64>>,
    ) -> Result<()> {
        if self.best.as_ref().is_some_and(|b| b.unit == unit) {
            return Ok(());
        }
        let validation = validator.validate(obs, &outputs)?;
        let score = validator.score(&validation);
        let rank = self.rank(score, params);
        self.best = Some(BestPoint {
            iteration,
            unit: unit.to_vec(),
            params: params.to_vec(),
            score,
            rank,
            validation,
            outputs,
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ErrorMetrics, OutputInfo, Snapshot};

    /// A prior that costs 10 K per unit of the first parameter above 0.5.
    struct Above;
    impl Regularizer for Above {
        fn value_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
            let over = (p[0] - 0.5).max(0.0);
            (10.0 * over, vec![if over > 0.0 { 10.0 } else { 0.0 }])
        }
    }

    fn run(value: f64) -> Vec<RunResult> {
        vec![RunResult {
            result: Ok(vec![value].into()),
            cached: false,
        }]
    }

    /// Books a low-error run where the prior binds, then a worse one where it does not;
    /// returns the best point's iteration.
    fn best_iteration(prior: Option<(&dyn Regularizer, f64)>) -> (usize, f64, f64) {
        let obs = Observations::new(
            vec![OutputInfo {
                name: "s".into(),
                group: "cold".into(),
            }],
            vec![Snapshot {
                label: "t0".into(),
                scenario: (),
                measured: vec![Some(20.0)],
            }],
        )
        .unwrap();
        let mut state = State::judged_with(prior);
        // MAE 0.5 at a parameter 0.1 above the prior's edge (1 K of prior).
        state
            .absorb(&ErrorMetrics, &obs, 1, &[0.6], &[0.6], run(20.5))
            .unwrap();
        // MAE 0.8 within the prior.
        state
            .absorb(&ErrorMetrics, &obs, 2, &[0.4], &[0.4], run(19.2))
            .unwrap();
        let b = state.best.as_ref().unwrap();
        let passed = state.passed_over(b);
        if b.iteration == 2 {
            let p = passed.expect("the lower-error run was passed over");
            assert_eq!(p.iteration, 1);
            assert!((p.score - 0.5).abs() < 1e-12 && (p.prior - 1.0).abs() < 1e-9);
        } else {
            assert!(passed.is_none());
        }
        (b.iteration, b.score, b.rank)
    }

    #[test]
    fn the_prior_judges_the_best_run_only_when_asked() {
        let (it, score, rank) = best_iteration(None);
        assert_eq!(it, 1);
        assert!((score - 0.5).abs() < 1e-12 && (rank - score).abs() < 1e-12);
        let (it, score, rank) = best_iteration(Some((&Above, 1.0)));
        assert_eq!(it, 2, "0.5 C + 1 K of prior loses to 0.8 C");
        assert!((score - 0.8).abs() < 1e-12 && (rank - 0.8).abs() < 1e-12);
        // A light prior leaves the lower error the best: 0.5 + 0.2 < 0.8.
        let (it, _, rank) = best_iteration(Some((&Above, 0.2)));
        assert_eq!(it, 1);
        assert!((rank - 0.7).abs() < 1e-12);
    }
}
