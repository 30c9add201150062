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

    /// Checks the hall ([`Hall::validate`]) and writes it to `path` as `hall.json`, so that a
    /// file this writes is always one the reader accepts.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.validate(&path.display().to_string())?;
        let mut text = self.to_json_pretty();
        text.push('\n');
        kalibre_core::write_atomic(path, text).map_err(|e| Error::io(path, e))
    }
}
