//! Writing `hall.json`.

use std::path::Path;

use super::types::Hall;
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
        // As in `to_json_pretty`: a hall always serialises.
        serde_json::to_string(&hall).expect("a hall always serialises to JSON")
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
