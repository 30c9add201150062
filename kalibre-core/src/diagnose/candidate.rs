//! Candidate effects of any model: parameters it has but the calibration holds at the
//! value where their effect is absent (a fixed parameter of the space), which the
//! diagnosis asks whether the data want moved. In `model.toml` they are the `[[params]]`
//! with `absent = ...`; to add one, delete that line: the parameter is then calibrated,
//! and since the parameters' names and order stay, the journal's runs still count.

/// One effect the model can represent but the calibration leaves out: its parameters,
/// held at their `absent` values.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateEffect {
    /// The effect's name: `params[i].effect`, else the parameter's own name.
    pub name: String,
    /// Its parameters, in the file's order.
    pub params: Vec<CandidateParam>,
}

/// A parameter of a [`CandidateEffect`].
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateParam {
    /// The parameter's name (as the templates use it).
    pub name: String,
    /// Its index in the calibration's parameter space (where it is fixed at `absent`).
    pub index: usize,
    /// The value at which the effect is absent.
    pub absent: f64,
    /// Lower end of the plausible range (physical units).
    pub lower: f64,
    /// Upper end of the plausible range.
    pub upper: f64,
}

impl CandidateParam {
    /// The finite-difference step that linearises the effect at `absent`: `share` of the
    /// range, towards the range's larger side (an effect absent at its lower bound steps
    /// up, one absent at its upper bound steps down).
    pub fn step(&self, share: f64) -> f64 {
        let step = share * (self.upper - self.lower);
        if self.upper - self.absent >= self.absent - self.lower {
            step
        } else {
            -step
        }
    }
}

/// Groups candidate parameters into effects by name, first appearance first.
pub(crate) fn group_candidates(params: Vec<(String, CandidateParam)>) -> Vec<CandidateEffect> {
    let mut effects: Vec<CandidateEffect> = Vec::new();
    for (effect, p) in params {
        match effects.iter_mut().find(|e| e.name == effect) {
            Some(e) => e.params.push(p),
            None => effects.push(CandidateEffect {
                name: effect,
                params: vec![p],
            }),
        }
    }
    effects
}

#[cfg(test)]
mod tests {
    use super::*;

    fn param(name: &str, absent: f64, lower: f64, upper: f64) -> CandidateParam {
        CandidateParam {
            name: name.into(),
            index: 0,
            absent,
            lower,
            upper,
        }
    }

    #[test]
    fn the_step_goes_into_the_larger_side_of_the_range() {
        assert_eq!(param("loss", 0.0, 0.0, 500.0).step(0.05), 25.0);
        assert_eq!(param("offset", 0.0, -2.0, 2.0).step(0.25), 1.0);
        assert_eq!(param("fouling", 1.0, 0.5, 1.0).step(0.1), -0.05);
    }

    #[test]
    fn parameters_of_one_effect_are_grouped_in_order() {
        let grouped = group_candidates(vec![
            ("leak".into(), param("a", 0.0, 0.0, 1.0)),
            ("bias".into(), param("b", 0.0, -1.0, 1.0)),
            ("leak".into(), param("c", 0.0, 0.0, 1.0)),
        ]);
        let names: Vec<(&str, Vec<&str>)> = grouped
            .iter()
            .map(|e| {
                (
                    e.name.as_str(),
                    e.params.iter().map(|p| p.name.as_str()).collect(),
                )
            })
            .collect();
        assert_eq!(names, vec![("leak", vec!["a", "c"]), ("bias", vec!["b"])]);
    }
}
