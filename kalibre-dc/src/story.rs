//! The user's whole path on one hall, as a library: calibrate, see where the model still
//! fails, learn which effect is missing, add it, recalibrate, and watch the error fall.
//!
//! [`run_story`] runs calibrations ([`calibrate_hall`]) and diagnoses ([`diagnose_hall`])
//! in turn, adding the top significant suggestion after each diagnosis (up to
//! [`StorySettings::max_effects`]), and stops honestly: when nothing is significant it says
//! so and adds nothing. Each new calibration starts where the diagnosis predicted its MAE:
//! the previous one's best alphas moved by the diagnosis's joint refit, and the
//! suggestion's fitted effect values ([`with_effect_refitted`]; a warm start: the user's
//! next run would do
//! the same). With an output directory it writes `story.json` (schema
//! [`STORY_SCHEMA`]), `hall-with-effect.json`, per step `step-N/report.json`, per
//! diagnosis `diagnosis-N.json`, and `report.html`.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use kalibre_core::calibrate::{NamedValues, Report};
use serde::{Deserialize, Serialize};

use crate::calibration::{calibrate_hall, HallCalibration, HallCalibrationSettings};
use crate::diagnosis::{diagnose_hall, HallDiagnosis, HallDiagnosisSettings};
use crate::effects::EffectRegistry;
use crate::hall::{EffectSpec, Hall};
pub use crate::next_hall::{with_effect_from_report, with_effect_refitted};
use crate::report::{ThermalPlane, INLET_HEIGHT_M};
use crate::sim::{intake_error, RackHeat};
use crate::snapshots::HallSnapshot;
use crate::{Error, Result};

/// The schema tag of `story.json`.
pub const STORY_SCHEMA: &str = "kalibre.story/1";

/// Hypotheses kept per diagnosis in `story.json` and the report (the full ranking goes
/// to `diagnosis-N.json`).
const KEPT_HYPOTHESES: usize = 8;

/// What shapes a story.
///
/// | Name | Default | Meaning |
/// |---|---|---|
/// | `calibration` | [`HallCalibrationSettings::default`] | every calibration of the story |
/// | `diagnosis` | [`HallDiagnosisSettings::default`] | every diagnosis; its `sim` is replaced by the calibration's, so the Jacobians are of the calibrated model |
/// | `max_effects` | 1 | effects added at most (one calibration more each) |
/// | `thermal_z_m` | 1.2 | height of the thermal planes (m) |
/// | `thermal_snapshot` | 0 | snapshot of the thermal planes |
/// | `reference_mae_c` | none | the MAE of a complete model at the true parameters, when known (synthetic halls): drawn as the floor |
/// | `true_intakes_c` | none | each server's true intake air per snapshot (in the snapshots' order, by server id), when known (synthetic halls): each calibration's model is scored against it where no sensor measures |
#[derive(Debug, Clone)]
pub struct StorySettings {
    /// Settings of each calibration.
    pub calibration: HallCalibrationSettings,
    /// Settings of each diagnosis.
    pub diagnosis: HallDiagnosisSettings,
    /// Effects added at most.
    pub max_effects: usize,
    /// Height of the thermal planes (m).
    pub thermal_z_m: f64,
    /// Snapshot (index) of the thermal planes.
    pub thermal_snapshot: usize,
    /// The floor a complete model reaches, when known (C).
    pub reference_mae_c: Option<f64>,
    /// True server intakes per snapshot, by server id, when known (C).
    pub true_intakes_c: Option<Vec<BTreeMap<String, f64>>>,
}

impl Default for StorySettings {
    fn default() -> Self {
        StorySettings {
            calibration: HallCalibrationSettings::default(),
            diagnosis: HallDiagnosisSettings::default(),
            max_effects: 1,
            thermal_z_m: INLET_HEIGHT_M,
            thermal_snapshot: 0,
            reference_mae_c: None,
            true_intakes_c: None,
        }
    }
}

/// One calibration of the story.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// What the step did, e.g. `calibrate alpha`.
    pub name: String,
    /// The hall's effects during this calibration.
    pub effects: Vec<EffectSpec>,
    /// MAE of the model at the step's initial parameters (C).
    pub mae_before_c: Option<f64>,
    /// Best MAE the calibration reached (C).
    pub mae_after_c: f64,
    /// Model runs of the calibration.
    pub model_runs: usize,
    /// Wall time of the calibration (s).
    pub wall_s: f64,
    /// The best parameters.
    pub best_params: NamedValues,
    /// The calibration report.
    pub report: Report,
    /// Its model's server intakes against the true ones, when those are known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intakes: Option<StepIntakes>,
}

/// A calibrated model's server intakes against the true ones: where no sensor measures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepIntakes {
    /// Mean absolute error over every server and snapshot (C).
    pub mae_c: f64,
    /// The server with the warmest true intake, and its snapshot.
    pub warmest_server: String,
    /// The snapshot of that intake.
    pub warmest_snapshot: String,
    /// Its true intake (C).
    pub warmest_true_c: f64,
    /// The model's intake there (C).
    pub warmest_model_c: f64,
    /// The server where the model is furthest from the truth, and its snapshot.
    pub worst_server: String,
    /// The snapshot of that intake.
    pub worst_snapshot: String,
    /// Model minus truth there (C).
    pub worst_error_c: f64,
}

/// One hypothesis of a diagnosis, as the story keeps it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Suggestion {
    /// Candidate name, e.g. `rack_recirculation(rack=A05)`.
    pub name: String,
    /// Share of the residual it explains when refit with the current parameters.
    pub explained_fraction: f64,
    /// Predicted MAE after adding it (C).
    pub predicted_mae_c: f64,
    /// Significant (penalised fit and held-out check both improve).
    pub significant: bool,
    /// The outputs hardly move with it.
    pub inert: bool,
    /// Distinguishable from what the model already has.
    pub identifiable: bool,
    /// Every fitted value lies in its parameter's range (a story written before this
    /// field was recorded reads as in range).
    #[serde(default = "in_range_default")]
    pub in_range: bool,
    /// The BIC change it brings (negative: better supported), by which the hypotheses are
    /// ordered after the significant ones (a story written before this field was
    /// recorded has none).
    #[serde(default)]
    pub delta_bic: Option<f64>,
    /// The `effects` entry to paste into `hall.json`; `None` (`null`) for a fit outside
    /// its range, which no entry gives.
    pub entry: Option<EffectSpec>,
}

fn in_range_default() -> bool {
    true
}

/// One diagnosis of the story (after calibration `after_step`, 0-based).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisStep {
    /// Index of the calibration it diagnoses.
    pub after_step: usize,
    /// MAE of the calibrated model (C).
    pub mae_c: f64,
    /// The best hypotheses, best first.
    pub hypotheses: Vec<Suggestion>,
    /// Wall time (s).
    pub wall_s: f64,
}

impl DiagnosisStep {
    /// The first significant hypothesis, if any (a significant one is fitted in its
    /// range, so it has an entry).
    pub fn top_significant(&self) -> Option<&Suggestion> {
        self.hypotheses
            .iter()
            .find(|h| h.significant && h.entry.is_some())
    }

    /// For `h`, a significant hypothesis below [`Self::top_significant`]: that it reads
    /// the same part of the residual as the top one
    /// ([`crate::diagnosis::alternative_note`]), if it does.
    pub fn alternative_note(&self, h: &Suggestion) -> Option<String> {
        let best = self
            .top_significant()
            .filter(|b| h.significant && b.name != h.name)?;
        let above = (h.delta_bic.zip(best.delta_bic)).map_or(f64::NAN, |(a, b)| a - b);
        crate::diagnosis::alternative_note(
            &best.name,
            best.explained_fraction,
            h.explained_fraction,
            above,
        )
    }
}

/// How the story ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StoryOutcome {
    /// The first diagnosis found no significant missing effect: nothing was added.
    NothingSignificant,
    /// Every added effect lowered the calibrated error.
    Improved,
    /// The last added effect did not lower the calibrated error.
    NotImproved,
}

/// Everything a story did (`story.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoryReport {
    /// Always [`STORY_SCHEMA`].
    pub schema: String,
    /// The hall's name.
    pub hall: String,
    /// The calibrations, in order.
    pub steps: Vec<Step>,
    /// The diagnoses, in order (one after each calibration).
    pub diagnoses: Vec<DiagnosisStep>,
    /// Effects added, in order.
    pub added: Vec<EffectSpec>,
    /// How it ended.
    pub outcome: StoryOutcome,
    /// The floor of a complete model, when known (C).
    pub reference_mae_c: Option<f64>,
    /// Why the diagnosis after the last calibration failed, when it did (it only
    /// informs, so the story goes on without it).
    pub final_diagnosis_error: Option<String>,
    /// Total wall time (s).
    pub wall_s: f64,
    /// The simulator's temperature at inlet height before calibration (the hall's initial
    /// parameters) and after the last calibration (not in `story.json`).
    #[serde(skip)]
    pub thermal: Vec<ThermalPlane>,
}

impl StoryReport {
    /// MAE after the first calibration and after the last (C).
    pub fn first_and_last_mae_c(&self) -> Option<(f64, f64)> {
        Some((
            self.steps.first()?.mae_after_c,
            self.steps.last()?.mae_after_c,
        ))
    }
}

/// What happened, for progress output (library code never prints).
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub enum StoryEvent<'a> {
    /// A calibration starts.
    CalibrationStarted {
        /// Its index.
        index: usize,
        /// What it does.
        name: &'a str,
    },
    /// A calibration finished.
    CalibrationDone {
        /// Its index.
        index: usize,
        /// The step.
        step: &'a Step,
    },
    /// A diagnosis starts.
    DiagnosisStarted {
        /// The calibration it diagnoses.
        after_step: usize,
    },
    /// A diagnosis finished.
    DiagnosisDone {
        /// The summary the story keeps.
        step: &'a DiagnosisStep,
        /// The full diagnosis.
        full: &'a HallDiagnosis,
        /// The calibration it diagnoses (its residuals show where the model fails).
        calibration: &'a Report,
        /// Every rack's part of every sensor's warming in the calibrated model's flow at
        /// the first snapshot ([`crate::HallModel::rack_heat`]).
        heat: &'a [RackHeat],
    },
    /// The diagnosis after the last calibration failed (the story goes on).
    DiagnosisFailed {
        /// The calibration it diagnoses.
        after_step: usize,
        /// Why.
        error: &'a str,
    },
    /// An effect was added to the hall.
    EffectAdded {
        /// The entry.
        entry: &'a EffectSpec,
        /// The hall with it (and warm-started initial values).
        hall: &'a Hall,
    },
}

/// Runs the story on `hall` and `snaps`; see the module documentation. `observer` sees
/// every [`StoryEvent`] as it happens.
pub fn run_story(
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &StorySettings,
    out_dir: Option<&Path>,
    observer: &(dyn Fn(&StoryEvent<'_>) + Sync),
) -> Result<StoryReport> {
    if settings.thermal_snapshot >= snaps.len() {
        return Err(Error::Mismatch(format!(
            "story: thermal_snapshot {} but only {} snapshot(s)",
            settings.thermal_snapshot,
            snaps.len()
        )));
    }
    if let Some(dir) = out_dir {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let registry = EffectRegistry::builtin();
    let diag_settings = HallDiagnosisSettings {
        sim: settings.calibration.sim.clone(),
        ..settings.diagnosis.clone()
    };
    let started = Instant::now();
    let mut current = hall.clone();
    let mut steps: Vec<Step> = Vec::new();
    let mut diagnoses = Vec::new();
    let mut added = Vec::new();
    let mut thermal = Vec::new();
    let mut final_diagnosis_error = None;
    let mut name = "calibrate alpha".to_string();
    let outcome = loop {
        let index = steps.len();
        observer(&StoryEvent::CalibrationStarted { index, name: &name });
        let t = Instant::now();
        let cal = calibrate_hall(&current, snaps, &settings.calibration, None, Vec::new())?;
        let step = Step {
            name: name.clone(),
            effects: current.effects.clone(),
            mae_before_c: cal.report.initial.mae_c,
            mae_after_c: cal.report.best.mae_c,
            model_runs: cal.report.runs.total,
            wall_s: t.elapsed().as_secs_f64(),
            best_params: cal.report.best.params.clone(),
            report: cal.report.clone(),
            intakes: match &settings.true_intakes_c {
                Some(truth) => Some(step_intakes(
                    &cal,
                    snaps,
                    &cal.report.best.params.values(),
                    truth,
                )?),
                None => None,
            },
        };
        if index == 0 {
            let initial = cal.model.layout().space().initial();
            thermal.push(plane(
                &cal,
                snaps,
                settings,
                &initial,
                "before calibration",
            )?);
        }
        if let Some(dir) = out_dir {
            write_json(
                &dir.join(format!("step-{}", index + 1)),
                "report.json",
                &step.report,
            )?;
        }
        observer(&StoryEvent::CalibrationDone { index, step: &step });
        let improved = steps
            .last()
            .is_none_or(|p| step.mae_after_c < p.mae_after_c);
        steps.push(step);
        let best = cal.report.best.params.values();
        let after = format!("after calibration {}", index + 1);
        if !improved {
            thermal.push(plane(&cal, snaps, settings, &best, &after)?);
            break StoryOutcome::NotImproved;
        }
        observer(&StoryEvent::DiagnosisStarted { after_step: index });
        let t = Instant::now();
        let full = match diagnose_hall(&current, snaps, &best, &registry, &diag_settings) {
            Ok(full) => full,
            // After the last calibration the diagnosis only informs; its failure is
            // reported, not fatal, so the calibrations and the report are not lost.
            Err(e) if added.len() >= settings.max_effects && index > 0 => {
                let message = e.to_string();
                observer(&StoryEvent::DiagnosisFailed {
                    after_step: index,
                    error: &message,
                });
                final_diagnosis_error = Some(message);
                thermal.push(plane(&cal, snaps, settings, &best, &after)?);
                break StoryOutcome::Improved;
            }
            Err(e) => return Err(e),
        };
        let diag = summarise(index, &full, t.elapsed().as_secs_f64());
        // Which racks warm each sensor in the calibrated model's flow (the first
        // snapshot, as `kalibre diagnose` says): where a missing effect would act.
        let heat = match snaps.first() {
            Some(first) => cal.model.rack_heat(&first.state, &best)?.1,
            None => Vec::new(),
        };
        if let Some(dir) = out_dir {
            write_json(
                dir,
                &format!("diagnosis-{}.json", index + 1),
                &full.document(&current, &cal.report.residuals, Some(&heat)),
            )?;
        }
        observer(&StoryEvent::DiagnosisDone {
            step: &diag,
            full: &full,
            calibration: &cal.report,
            heat: &heat,
        });
        let top = diag.top_significant().cloned();
        diagnoses.push(diag);
        let (top, entry) = match top.and_then(|t| t.entry.clone().map(|e| (t, e))) {
            Some(top) if added.len() < settings.max_effects => top,
            _ => {
                thermal.push(plane(&cal, snaps, settings, &best, &after)?);
                break if added.is_empty() {
                    StoryOutcome::NothingSignificant
                } else {
                    StoryOutcome::Improved
                };
            }
        };
        // Where the diagnosis predicted its MAE: the effect at its fitted value and the
        // calibrated parameters moved beside it.
        let fit = full
            .diagnosis
            .hypotheses
            .iter()
            .find(|h| h.name == top.name);
        current = match fit {
            Some(h) => {
                with_effect_refitted(&current, &cal.report, &cal.model, &registry, h, &entry)?
            }
            None => with_effect(&current, &cal, &registry, &entry)?,
        };
        if let Some(dir) = out_dir {
            current.save(&dir.join("hall-with-effect.json"))?;
        }
        observer(&StoryEvent::EffectAdded {
            entry: &entry,
            hall: &current,
        });
        added.push(entry);
        name = format!("add {}, recalibrate", top.name);
    };
    let report = StoryReport {
        schema: STORY_SCHEMA.into(),
        hall: hall.name.clone(),
        steps,
        diagnoses,
        added,
        outcome,
        reference_mae_c: settings.reference_mae_c,
        final_diagnosis_error,
        wall_s: started.elapsed().as_secs_f64(),
        thermal,
    };
    if let Some(dir) = out_dir {
        write_json(dir, "story.json", &report)?;
        let html = crate::report::story_html(&current, snaps, &report);
        let path = dir.join("report.html");
        kalibre_core::write_atomic(&path, html).map_err(|e| Error::io(&path, e))?;
    }
    Ok(report)
}

/// The thermal plane of a calibration's model at `params`.
fn plane(
    cal: &HallCalibration,
    snaps: &[HallSnapshot],
    settings: &StorySettings,
    params: &[f64],
    label: &str,
) -> Result<ThermalPlane> {
    let snap = &snaps[settings.thermal_snapshot];
    let solution = cal.model.solve(&snap.state, params)?;
    ThermalPlane::from_solution(
        cal.model.simulator(),
        &solution,
        settings.thermal_z_m,
        format!("{label}, snapshot {}", snap.state.label),
    )
}

/// The calibrated model's server intakes at `params` against `truth` (per snapshot).
fn step_intakes(
    cal: &HallCalibration,
    snaps: &[HallSnapshot],
    params: &[f64],
    truth: &[BTreeMap<String, f64>],
) -> Result<StepIntakes> {
    if truth.len() != snaps.len() {
        return Err(Error::Mismatch(format!(
            "true intakes for {} snapshots, but {} snapshots",
            truth.len(),
            snaps.len()
        )));
    }
    let mut rows = Vec::new();
    for snap in snaps {
        rows.extend(cal.model.server_air(&snap.state, params)?);
    }
    let labels: Vec<&str> = snaps.iter().map(|s| s.state.label.as_str()).collect();
    let lookup = |label: &str, server: &str| {
        let k = labels.iter().position(|l| *l == label)?;
        truth[k].get(server).copied()
    };
    let e = intake_error(&rows, &lookup)?;
    let (w, t) = e.warmest_true;
    let (x, tx) = e.worst;
    Ok(StepIntakes {
        mae_c: e.mae_c,
        warmest_server: w.server,
        warmest_snapshot: w.snapshot,
        warmest_true_c: t,
        warmest_model_c: w.intake_c,
        worst_error_c: x.intake_c - tx,
        worst_server: x.server,
        worst_snapshot: x.snapshot,
    })
}

fn summarise(after_step: usize, d: &HallDiagnosis, wall_s: f64) -> DiagnosisStep {
    DiagnosisStep {
        after_step,
        mae_c: d.diagnosis.mae,
        hypotheses: d
            .diagnosis
            .hypotheses
            .iter()
            .enumerate()
            .take(KEPT_HYPOTHESES)
            .map(|(i, h)| Suggestion {
                name: h.name.clone(),
                explained_fraction: h.explained_fraction,
                predicted_mae_c: h.predicted_mae,
                significant: h.significant,
                inert: h.inert,
                identifiable: h.identifiable,
                in_range: h.in_range,
                delta_bic: Some(h.delta_bic),
                entry: d.entry(i).cloned(),
            })
            .collect(),
        wall_s,
    }
}

/// The hall with `entry` added, warm-started at `cal`'s calibrated values (not refitted
/// beside the effect: [`with_effect_refitted`] is).
pub fn with_effect(
    hall: &Hall,
    cal: &HallCalibration,
    registry: &EffectRegistry,
    entry: &EffectSpec,
) -> Result<Hall> {
    with_effect_from_report(hall, &cal.report, &cal.model, registry, entry)
}

fn write_json<T: Serialize>(dir: &Path, name: &str, value: &T) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let path = dir.join(name);
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::Mismatch(format!("{}: cannot serialise: {e}", path.display())))?;
    kalibre_core::write_atomic(&path, text + "\n").map_err(|e| Error::io(&path, e))
}
