//! The OpenFOAM model's fingerprint, and the one versions before it gave the same model
//! (read as its own in journals: [`kalibre_core::Model::legacy_fingerprints`]).

use super::super::geometry::CaseExtras;
use super::super::{OpenFoamError, OpenFoamSettings};
use super::{hash_hex, json, GENERATOR};
use crate::effects::Effect;
use crate::hall::{AlphaMode, Hall};

/// What the model's fingerprints hash, beside the hall and its effects.
pub(super) struct Inputs<'a> {
    /// The checked settings (only those that change results serialise).
    pub(super) settings: &'a OpenFoamSettings,
    /// How alpha is calibrated (the layout's mode).
    pub(super) mode: AlphaMode,
    /// Whether the case has containment panels (only then does their leak count).
    pub(super) panels: bool,
    /// What the effects add to the mesh.
    pub(super) extras: &'a CaseExtras,
}

/// `(fingerprint, legacy fingerprint)` of the model of `hall` with `effects`.
///
/// The fingerprint covers the generator version, the hall as a run computes with it
/// ([`Hall::model_json`]: without the calibrated parameters' bounds and initial values),
/// the settings, the alpha mode, the panels' leak for a contained hall and what the
/// effects add to the mesh (their openings and gaps, which their placements give and an
/// effect whose upper bounds are 0 lacks). The legacy one is exactly what versions before
/// it computed: `hall.json` with bounds and initial values and the effects' entries.
pub(super) fn fingerprints(
    hall: &Hall,
    effects: &[Box<dyn Effect>],
    inputs: &Inputs<'_>,
) -> Result<(String, String), OpenFoamError> {
    let settings_json = json(inputs.settings)?;
    let mode_key = format!("{:?}", inputs.mode);
    let leak_key = format!(
        "containment_leak_fraction={}",
        inputs.settings.containment_leak_fraction
    );
    let extras_key = format!("{:?}", inputs.extras);
    let model_json = hall.model_json(inputs.mode, effects);
    let mut parts: Vec<&[u8]> = vec![
        GENERATOR.as_bytes(),
        model_json.as_bytes(),
        settings_json.as_bytes(),
        mode_key.as_bytes(),
    ];
    if inputs.panels {
        parts.push(leak_key.as_bytes());
    }
    if *inputs.extras != CaseExtras::default() {
        parts.push(extras_key.as_bytes());
    }
    let fingerprint = format!("{GENERATOR}:{}", hash_hex(&parts));

    let specs: Vec<_> = effects.iter().map(|e| e.to_spec()).collect();
    let hall_json = hall.physics_json();
    let effects_json = json(&specs)?;
    let mut parts: Vec<&[u8]> = vec![
        GENERATOR.as_bytes(),
        hall_json.as_bytes(),
        settings_json.as_bytes(),
        effects_json.as_bytes(),
        mode_key.as_bytes(),
    ];
    if inputs.panels {
        parts.push(leak_key.as_bytes());
    }
    let legacy = format!("{GENERATOR}:{}", hash_hex(&parts));
    Ok((fingerprint, legacy))
}

#[cfg(test)]
mod tests {
    use super::super::super::geometry::CaseGeometry;
    use super::super::case_extras;
    use super::*;
    use crate::effects::EffectRegistry;

    /// of-dev-clean, with two effects (one of bounds of its own) when `with_effects`.
    fn hall(with_effects: bool) -> Hall {
        let text = include_str!("../../../../data/openfoam/of-dev-clean/hall.json");
        let mut json: serde_json::Value = serde_json::from_str(text).unwrap();
        if with_effects {
            json["effects"] = serde_json::json!([
                { "kind": "crac_supply_offset", "crac": "crac-1", "offset_c": 0.5,
                  "offset_c_bounds": [-2.0, 2.0] },
                { "kind": "rack_recirculation", "rack": "A1" }
            ]);
        }
        serde_json::from_value(json).unwrap()
    }

    /// What `OpenFoamModel::new` builds before its keys, with default settings.
    fn parts_of(
        hall: &Hall,
    ) -> (
        OpenFoamSettings,
        CaseExtras,
        CaseGeometry,
        Vec<Box<dyn Effect>>,
    ) {
        let settings = OpenFoamSettings::default().check().unwrap();
        let effects = EffectRegistry::builtin().build_all(hall).unwrap();
        let extras = case_extras(hall, &effects).unwrap();
        let geometry = CaseGeometry::with_extras(hall, settings.grid_m, &extras).unwrap();
        (settings, extras, geometry, effects)
    }

    fn fingerprints_of(hall: &Hall) -> (String, String) {
        let (settings, extras, geometry, effects) = parts_of(hall);
        let inputs = Inputs {
            settings: &settings,
            mode: hall.calibrate.alpha,
            panels: !geometry.panels.is_empty(),
            extras: &extras,
        };
        fingerprints(hall, &effects, &inputs).unwrap()
    }

    fn case_keys_of(hall: &Hall) -> (String, String) {
        let (settings, extras, geometry, _) = parts_of(hall);
        let settings_json = serde_json::to_string(&settings).unwrap();
        super::super::case_keys(hall, &geometry, &extras, &settings_json)
    }

    /// `base` with other bounds and initial values (of alphas and effects).
    fn searched(base: &Hall) -> Hall {
        let mut searched = base.clone();
        searched.server_types[0].alpha_cfm_per_w.max = 1.0;
        searched.server_types[1].alpha_cfm_per_w.initial = 0.4;
        searched.effects[0]
            .fields
            .insert("offset_c_bounds".into(), serde_json::json!([-1.0, 1.0]));
        searched.effects[1]
            .fields
            .insert("fraction".into(), serde_json::json!(0.3));
        searched
    }

    /// `base` with its recirculation gap through another rack.
    fn moved(base: &Hall) -> Hall {
        let mut moved = base.clone();
        moved.effects[1]
            .fields
            .insert("rack".into(), serde_json::json!("B2"));
        moved
    }

    /// The legacy fingerprints are the values `OpenFoamModel::new` gave these halls with
    /// default settings before bounds and initial values were left out.
    #[test]
    fn the_legacy_fingerprint_is_the_one_earlier_versions_gave() {
        let (_, plain) = fingerprints_of(&hall(false));
        assert_eq!(plain, "kalibre-dc-openfoam/3:1b0fbf5f369cf5ea");
        let (_, with_effects) = fingerprints_of(&hall(true));
        assert_eq!(with_effects, "kalibre-dc-openfoam/3:d1e498253969f313");
    }

    #[test]
    fn bounds_and_initial_values_are_not_in_the_fingerprint() {
        let base = hall(true);
        let (fingerprint, legacy) = fingerprints_of(&base);
        let (same, other_legacy) = fingerprints_of(&searched(&base));
        assert_eq!(same, fingerprint);
        assert_ne!(other_legacy, legacy);
        // Where the effect acts, and the hall's physics, are the model's.
        assert_ne!(fingerprints_of(&moved(&base)).0, fingerprint);
        let mut cooler = base;
        cooler.cracs[0].rated_flow_m3_s *= 1.1;
        assert_ne!(fingerprints_of(&cooler).0, fingerprint);
    }

    /// A case meshed by an earlier version is found under the name it gave; an edited
    /// bound or initial value meshes nothing again, while moved geometry or a moved
    /// gap does.
    #[test]
    fn the_case_is_keyed_by_its_mesh_and_found_under_its_earlier_name() {
        let base = hall(true);
        let (key, legacy) = case_keys_of(&base);
        assert_eq!(case_keys_of(&hall(false)).1, "1a808ce324641dae");
        assert_eq!(legacy, "e28b5c4085499157");
        let (same, other_legacy) = case_keys_of(&searched(&base));
        assert_eq!(same, key);
        assert_ne!(other_legacy, legacy);
        assert_ne!(case_keys_of(&moved(&base)).0, key);
        let mut shifted = base;
        shifted.sensors[0].position_m[2] += 0.1;
        assert_ne!(case_keys_of(&shifted).0, key);
    }
}
