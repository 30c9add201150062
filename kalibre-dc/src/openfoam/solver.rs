//! [`OpenFoamEffectSolver`]: OpenFOAM as the diagnosis's solver, so that candidate
//! effects are linearised with the real CFD engine rather than the built-in simulator.
//!
//! Each distinct list of effects gets its own [`OpenFoamModel`] (a bypass opening is part
//! of the mesh; the case cache keeps one meshed case per list). Every finished solve is
//! kept in `cache_root/diagnosis-runs/` under a hash of the model's fingerprint and the
//! run's inputs, so an interrupted diagnosis run again repeats no solve.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use super::model::SUPPORTED_EFFECTS;
use super::{OpenFoamError, OpenFoamModel, OpenFoamSettings};
use crate::diagnosis::EffectSolver;
use crate::effects::{Effect, EffectRegistry};
use crate::hall::Hall;
use crate::snapshots::OperatingState;
use crate::{Error, ParamLayout, Result};

/// OpenFOAM solving a hall with any list of supported effects (see the module docs).
#[derive(Debug)]
pub struct OpenFoamEffectSolver {
    hall: Hall,
    settings: OpenFoamSettings,
    models: Mutex<HashMap<String, Arc<OpenFoamModel>>>,
    results: PathBuf,
}

fn of(e: OpenFoamError) -> Error {
    Error::Simulation(format!("OpenFOAM: {e}"))
}

/// 64-bit FNV-1a over the bits of the run's inputs: stable across builds.
fn run_key(fingerprint: &str, state: &OperatingState, values: &[f64]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    eat(fingerprint.as_bytes());
    eat(state.label.as_bytes());
    for v in state
        .setpoint_c
        .iter()
        .chain(&state.fan_speed)
        .chain(&state.power_w)
        .chain(values)
    {
        eat(&v.to_bits().to_le_bytes());
    }
    format!("{h:016x}")
}

impl OpenFoamEffectSolver {
    /// The solver of `hall`; meshed cases, runs and kept results go under
    /// `settings.cache_root`.
    pub fn new(hall: &Hall, settings: OpenFoamSettings) -> Result<Self> {
        let settings = settings.check().map_err(of)?;
        let results = settings.cache_root.join("diagnosis-runs");
        std::fs::create_dir_all(&results).map_err(|e| Error::io(&results, e))?;
        Ok(OpenFoamEffectSolver {
            hall: hall.clone(),
            settings,
            models: Mutex::new(HashMap::new()),
            results,
        })
    }

    /// The model for this list of effects, meshed on first use.
    fn model(&self, effects: &[(&dyn Effect, &[f64])]) -> Result<Arc<OpenFoamModel>> {
        let specs: Vec<_> = effects.iter().map(|(e, _)| e.to_spec()).collect();
        let key = serde_json::to_string(&specs).map_err(|e| Error::Simulation(e.to_string()))?;
        // Held while meshing, so that two runs never build the same case at once.
        let mut models = self
            .models
            .lock()
            .map_err(|_| Error::Simulation("OpenFOAM model cache poisoned".into()))?;
        if let Some(m) = models.get(&key) {
            return Ok(Arc::clone(m));
        }
        let registry = EffectRegistry::builtin();
        let built: Vec<Box<dyn Effect>> = specs
            .iter()
            .map(|s| registry.build(s, &self.hall))
            .collect::<Result<_>>()?;
        let layout = ParamLayout::new(&self.hall, &built)?;
        let model = Arc::new(
            OpenFoamModel::with_layout(&self.hall, self.settings.clone(), built, layout)
                .map_err(of)?,
        );
        models.insert(key, Arc::clone(&model));
        Ok(model)
    }

    /// Where the result of a run with `key` is kept.
    fn result_path(&self, key: &str) -> PathBuf {
        self.results.join(format!("{key}.json"))
    }
}

impl EffectSolver for OpenFoamEffectSolver {
    fn name(&self) -> String {
        "OpenFOAM".into()
    }

    fn supports(&self, kind: &str) -> bool {
        SUPPORTED_EFFECTS.contains(&kind)
    }

    fn solve(
        &self,
        state: &OperatingState,
        alpha_per_server: &[f64],
        effects: &[(&dyn Effect, &[f64])],
    ) -> Result<Vec<f64>> {
        let model = self.model(effects)?;
        let values: Vec<f64> = alpha_per_server
            .iter()
            .chain(effects.iter().flat_map(|(_, v)| v.iter()))
            .copied()
            .collect();
        use kalibre_core::Model;
        // Results kept by earlier versions are under the model's legacy fingerprints.
        let paths: Vec<PathBuf> = (model.run_fingerprints().iter())
            .map(|f| self.result_path(&run_key(f, state, &values)))
            .collect();
        let path = &paths[0];
        let n = self.hall.sensors.len();
        for kept in &paths {
            if let Ok(text) = std::fs::read_to_string(kept) {
                // A kept result of another length (a changed hall) is solved again.
                if let Ok(v) = serde_json::from_str::<Vec<f64>>(&text) {
                    if v.len() == n && v.iter().all(|x| x.is_finite()) {
                        return Ok(v);
                    }
                }
            }
        }
        let values: Vec<&[f64]> = effects.iter().map(|(_, v)| *v).collect();
        let (out, _) = model
            .evaluate_at(state, alpha_per_server, &values)
            .map_err(|e| Error::Simulation(format!("OpenFOAM run of `{}`: {e}", state.label)))?;
        // Written whole, then renamed, so a kill never leaves half a result.
        let text =
            serde_json::to_string(&out.values).map_err(|e| Error::Simulation(e.to_string()))?;
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        std::fs::write(&tmp, text).map_err(|e| Error::io(&tmp, e))?;
        std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))?;
        Ok(out.values)
    }

    fn refined(&self, _factor: f64) -> Result<Option<Box<dyn EffectSolver>>> {
        // A grid twice as fine has eight times the cells: not offered.
        Ok(None)
    }
}
