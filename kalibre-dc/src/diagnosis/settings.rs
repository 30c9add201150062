//! The settings of a hall diagnosis, and their ranges.

use kalibre_core::diagnose::DiagnoseSettings;

use crate::sim::SimConfig;
use crate::Result;

#[cfg(doc)]
use super::{diagnose_hall, EffectSolver};
#[cfg(doc)]
use kalibre_core::diagnose::Diagnosis;

/// Settings of a hall diagnosis.
///
/// | Name | Default | Meaning |
/// |---|---|---|
/// | `sim` | [`SimConfig::default`] | the built-in simulator, when it supplies the Jacobians ([`diagnose_hall`]) |
/// | `unit_step` | 0.01 | finite-difference step of calibrated parameters (unit box) |
/// | `effect_step` | 0.05 | finite-difference step of effect parameters (share of their range) |
/// | `refine_factor` | 0.5 | the model's own discretisation error, estimated by one more solve per snapshot on a grid this much finer, is each sensor's model uncertainty (no hypothesis earns credit for what the grid alone could produce); none: no such solve (nor when the solver offers no finer grid) |
/// | `model_form` | true | each sensor's model uncertainty also counts what the solver's model-form variants ([`EffectSolver::model_form_variants`]; the built-in simulator: its tile jets carried up the cold aisle) read beyond it at the calibrated parameters, one solve per snapshot and variant, by the share of that variance the residuals bear out ([`Diagnosis::model_form_share`](kalibre_core::diagnose::Diagnosis::model_form_share): near 0 where the model reproduces the data) |
/// | `refit_top` | 0 | how many leading one-parameter hypotheses are refit with the solver itself (secant steps at their fitted point; `refit` module) before the final ranking |
/// | `refit_iterations` | 4 | runs per refit hypothesis (one solve per snapshot each): a step towards its fitted point, halved after a run that reads worse than its best point |
/// | `diagnose` | [`DiagnoseSettings::default`] | ranking, significance, held-out check |
#[derive(Debug, Clone)]
pub struct HallDiagnosisSettings {
    /// Built-in simulator configuration.
    pub sim: SimConfig,
    /// Step of calibrated parameters in the unit box.
    pub unit_step: f64,
    /// Step of effect parameters as a share of their range.
    pub effect_step: f64,
    /// Cell size of the refined grid relative to `sim.cell_m` (in (0, 1)), or none.
    pub refine_factor: Option<f64>,
    /// Whether the solver's model-form variants
    /// ([`EffectSolver::model_form_variants`]) add to each sensor's model uncertainty
    /// (by the share of their variance the residuals bear out).
    pub model_form: bool,
    /// How many leading hypotheses are refit with the solver (0: none).
    pub refit_top: usize,
    /// Secant steps per refit hypothesis.
    pub refit_iterations: usize,
    /// The generic diagnosis settings.
    pub diagnose: DiagnoseSettings,
}

impl Default for HallDiagnosisSettings {
    fn default() -> Self {
        HallDiagnosisSettings {
            sim: SimConfig::default(),
            unit_step: 0.01,
            effect_step: 0.05,
            refine_factor: Some(0.5),
            model_form: true,
            refit_top: 0,
            refit_iterations: 4,
            diagnose: DiagnoseSettings::default(),
        }
    }
}

impl HallDiagnosisSettings {
    /// Checks every setting against its range, naming the first offender.
    pub fn check(&self) -> Result<()> {
        self.sim.check()?;
        let bad = |name: &str, value: f64, range: &str| -> Result<()> {
            Err(kalibre_core::Error::InvalidSetting {
                name: name.to_string(),
                reason: format!("{} is outside {range}", crate::snapshots::number(value)),
            }
            .into())
        };
        // A step of 0 differences round-off; one past half the box leaves no room.
        if !(self.unit_step > 0.0 && self.unit_step <= 0.5) {
            return bad("unit_step", self.unit_step, "(0, 0.5]");
        }
        if !(self.effect_step > 0.0 && self.effect_step <= 1.0) {
            return bad("effect_step", self.effect_step, "(0, 1]");
        }
        if let Some(f) = self.refine_factor.filter(|f| !(*f > 0.0 && *f < 1.0)) {
            return bad("refine_factor", f, "(0, 1)");
        }
        self.diagnose.check()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Error;

    #[test]
    fn steps_out_of_range_are_refused_by_name() {
        HallDiagnosisSettings::default().check().expect("defaults");
        type Set = fn(&mut HallDiagnosisSettings);
        let cases: [(&str, Set); 7] = [
            ("unit_step", |s| s.unit_step = 0.0),
            ("unit_step", |s| s.unit_step = -5.0),
            ("unit_step", |s| s.unit_step = f64::NAN),
            ("effect_step", |s| s.effect_step = 0.0),
            ("effect_step", |s| s.effect_step = f64::NAN),
            ("refine_factor", |s| s.refine_factor = Some(1.0)),
            ("refine_factor", |s| s.refine_factor = Some(f64::NAN)),
        ];
        for (field, set) in cases {
            let mut s = HallDiagnosisSettings::default();
            set(&mut s);
            match s.check() {
                Err(Error::Core(kalibre_core::Error::InvalidSetting { name, .. })) => {
                    assert_eq!(name, field)
                }
                other => panic!("{field}: expected InvalidSetting, got {other:?}"),
            }
        }
    }
}
