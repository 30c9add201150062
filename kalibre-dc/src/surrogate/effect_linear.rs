//! The learned linear term of one effect parameter ([`crate::effects::SurrogateTerm::LearnedLinear`]).
//!
//! The thermal graph knows alpha only; an effect parameter reaches the surrogate's output
//! through this term: its feature is the parameter's value, the same for every sensor,
//! and each sensor's trained weight learns how far that sensor moves per unit of the
//! parameter from the model runs (the loop's design varies every parameter).

use super::term::SurrogateTerm;
use crate::snapshots::OperatingState;

/// A linear term in one parameter of the hall parameter vector.
#[derive(Debug, Clone)]
pub struct EffectLinearTerm {
    name: String,
    index: usize,
}

impl EffectLinearTerm {
    /// The term of the parameter at `index` of the hall parameter vector, named `name`
    /// (the layout's name, e.g. `bypass/fraction`).
    pub fn new(name: impl Into<String>, index: usize) -> Self {
        EffectLinearTerm {
            name: name.into(),
            index,
        }
    }
}

impl SurrogateTerm for EffectLinearTerm {
    fn name(&self) -> &str {
        &self.name
    }

    fn features(&self, _scenario: &OperatingState, params: &[f64], out: &mut [f64]) {
        out.fill(params[self.index]);
    }

    fn features_vjp(
        &self,
        _scenario: &OperatingState,
        _params: &[f64],
        cotangent: &[f64],
        grad: &mut [f64],
    ) {
        grad[self.index] += cotangent.iter().sum::<f64>();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vjp_matches_finite_differences() {
        let t = EffectLinearTerm::new("bypass/fraction", 1);
        let s = OperatingState {
            label: "t0".into(),
            setpoint_c: vec![18.0],
            fan_speed: vec![1.0],
            power_w: vec![100.0],
        };
        let p = [0.1, 0.2, 0.3];
        let ct = [0.5, -1.5, 2.0];
        let mut grad = [0.0; 3];
        t.features_vjp(&s, &p, &ct, &mut grad);
        let h = 1e-6;
        for i in 0..3 {
            let (mut lo, mut hi) = (p, p);
            lo[i] -= h;
            hi[i] += h;
            let (mut fl, mut fh) = ([0.0; 3], [0.0; 3]);
            t.features(&s, &lo, &mut fl);
            t.features(&s, &hi, &mut fh);
            let fd: f64 = (0..3).map(|k| ct[k] * (fh[k] - fl[k]) / (2.0 * h)).sum();
            assert!(
                (fd - grad[i]).abs() < 1e-6,
                "param {i}: {fd} vs {}",
                grad[i]
            );
        }
    }
}
