//! Writing `hall.json`.

use std::path::Path;

use super::types::{AlphaMode, Hall};
use crate::effects::{placement, Effect};
use crate::{Error, Result};

impl Hall {
    /// The hall as pretty-printed `hall.json` text (two-space indent, fields in format order).
    pub fn to_json_pretty(&self) -> String {
        // Serialising cannot fail: every map key is a string and serde_json writes to memory.
        serde_json::to_string_pretty(self).expect("a hall always serialises to JSON")
    }

    /// The hall as compact JSON without its name and its free-form `extra` data, which
    /// change no reading: what a model's fingerprint hashes, so that renaming or
    /// annotating a hall keeps its journaled runs.
    ///
    /// ```
    /// # let text = include_str!("../../../data/openfoam/of-dev-clean/hall.json");
    /// use kalibre_dc::hall::Hall;
    /// let hall: Hall = serde_json::from_str(text).unwrap();
    /// let mut noted = hall.clone();
    /// noted.name = "hall 7, as surveyed".into();
    /// noted.sensors[0].extra = Some(serde_json::json!({ "note": "moved in May" }));
    /// assert_eq!(noted.physics_json(), hall.physics_json());
    /// noted.cracs[0].rated_flow_m3_s *= 1.1;
    /// assert_ne!(noted.physics_json(), hall.physics_json());
    /// ```
    pub fn physics_json(&self) -> String {
        let mut hall = self.clone();
        hall.name.clear();
        hall.extra = None;
        hall.room.extra = None;
        hall.server_types.iter_mut().for_each(|t| t.extra = None);
        hall.cracs.iter_mut().for_each(|c| c.extra = None);
        hall.tiles.iter_mut().for_each(|t| t.extra = None);
        hall.returns.iter_mut().for_each(|r| r.extra = None);
        for rack in &mut hall.racks {
            rack.extra = None;
            rack.servers.iter_mut().for_each(|s| s.extra = None);
        }
        hall.containment.iter_mut().for_each(|c| c.extra = None);
        hall.sensors.iter_mut().for_each(|s| s.extra = None);
        hall.calibrate.extra = None;
        for t in &mut hall.server_types {
            t.alpha_cfm_per_w.extra = None;
        }
        hall.effects.iter_mut().for_each(|e| {
            e.fields.remove("extra");
        });
        // As in `to_json_pretty`: a hall always serialises.
        serde_json::to_string(&hall).expect("a hall always serialises to JSON")
    }

    /// What a model's fingerprint hashes of the hall: [`Self::physics_json`] without the
    /// bounds and initial values of the calibrated parameters, with the hall's alpha
    /// calibrated as `alpha` and `effects` as its effects.
    ///
    /// Bounds and initial values say where a calibration searches and where it starts,
    /// not what a run at given parameter values computes; and a journaled run is reused
    /// only at exactly its parameter values. So they are not the model's: a journal's
    /// runs stay usable when a bound or an initial value is edited. Left out are each
    /// server type's `alpha_cfm_per_w` `min` and `max`, and its `initial` unless `alpha`
    /// is [`AlphaMode::Fixed`] (every run then takes it: it is physics). `effects` stand
    /// as their placements ([`placement`]: each entry without its parameters' values and
    /// bounds, every one of which a run is given), in place of the hall's `effects`
    /// entries as written; the effect's other fields (where and how it acts) stay.
    ///
    /// ```
    /// # let text = include_str!("../../../data/openfoam/of-dev-clean/hall.json");
    /// use kalibre_dc::hall::{AlphaMode, Hall};
    /// let hall: Hall = serde_json::from_str(text).unwrap();
    /// let mut searched = hall.clone();
    /// searched.server_types[0].alpha_cfm_per_w.max = 1.0;
    /// searched.server_types[0].alpha_cfm_per_w.initial = 0.5;
    /// assert_eq!(
    ///     searched.model_json(AlphaMode::PerType, &[]),
    ///     hall.model_json(AlphaMode::PerType, &[])
    /// );
    /// // With alpha fixed, every run takes the initial value.
    /// assert_ne!(
    ///     searched.model_json(AlphaMode::Fixed, &[]),
    ///     hall.model_json(AlphaMode::Fixed, &[])
    /// );
    /// let mut cooler = hall.clone();
    /// cooler.cracs[0].rated_flow_m3_s *= 1.1;
    /// assert_ne!(
    ///     cooler.model_json(AlphaMode::PerType, &[]),
    ///     hall.model_json(AlphaMode::PerType, &[])
    /// );
    /// ```
    pub fn model_json(&self, alpha: AlphaMode, effects: &[Box<dyn Effect>]) -> String {
        let mut hall = self.clone();
        hall.effects = effects
            .iter()
            .map(|e| placement(&e.to_spec(), e.as_ref()))
            .collect();
        // As in `to_json_pretty`: a hall always serialises, to a JSON object.
        let mut json: serde_json::Value =
            serde_json::from_str(&hall.physics_json()).expect("a hall's JSON is a JSON value");
        for t in json["server_types"].as_array_mut().into_iter().flatten() {
            if let Some(a) = t["alpha_cfm_per_w"].as_object_mut() {
                a.remove("min");
                a.remove("max");
                if alpha != AlphaMode::Fixed {
                    a.remove("initial");
                }
            }
        }
        json["calibrate"]["alpha"] = serde_json::to_value(alpha).expect("a mode serialises");
        json.to_string()
    }

    /// Checks the hall ([`Hall::validate`]) and writes it to `path` as `hall.json`, so that a
    /// file this writes is always one the reader accepts.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.validate(&path.display().to_string())?;
        let mut text = self.to_json_pretty();
        text.push('\n');
        kalibre_core::write_atomic(path, text).map_err(|e| Error::io(path, e))
    }
}
