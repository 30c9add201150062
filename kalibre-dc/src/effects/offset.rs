//! `crac_supply_offset`: a CRAC supplies air at its setpoint plus an offset (a drifted
//! sensor or a tired coil).
//!
//! | field | required | meaning |
//! |---|---|---|
//! | `crac` | no | CRAC id; every CRAC when absent |
//! | `offset_c` | no | initial offset (C), default 0 |
//! | `offset_c_bounds` | no | bounds (C), within and default `[-5, 5]` |

use kalibre_core::Param;
use serde_json::Value;

use super::fields::{param_fields, spec, unknown_id, Fields};
use super::{check_values, Effect, EffectFactory};
use crate::hall::{EffectSpec, Hall};
use crate::sim::SimMods;
use crate::Result;

const KIND: &str = "crac_supply_offset";
const BOUNDS: [f64; 2] = [-5.0, 5.0];

/// Supply temperature = setpoint + `offset_c` for one CRAC or all.
#[derive(Debug, Clone)]
pub struct CracSupplyOffset {
    crac: Option<(usize, String)>,
    param: Param,
}

impl Effect for CracSupplyOffset {
    fn kind(&self) -> &str {
        KIND
    }

    fn parameters(&self) -> Vec<Param> {
        vec![self.param.clone()]
    }

    fn to_spec(&self) -> EffectSpec {
        let mut f: Vec<(String, Value)> = Vec::new();
        if let Some((_, id)) = &self.crac {
            f.push(("crac".into(), Value::from(id.clone())));
        }
        f.extend(param_fields(&self.param, BOUNDS[0], BOUNDS[1]));
        spec(
            KIND,
            f.iter().map(|(k, v)| (k.as_str(), v.clone())).collect(),
        )
    }

    fn modify(&self, values: &[f64], hall: &Hall, mods: &mut SimMods) -> Result<()> {
        check_values(KIND, values, 1)?;
        if mods.supply_offset_c.len() != hall.cracs.len() {
            mods.supply_offset_c.resize(hall.cracs.len(), 0.0);
        }
        match &self.crac {
            Some((k, _)) => mods.supply_offset_c[*k] += values[0],
            None => mods
                .supply_offset_c
                .iter_mut()
                .for_each(|o| *o += values[0]),
        }
        Ok(())
    }
}

/// Where a whole-hall offset and per-CRAC offsets over every CRAC meet:
/// `(whole-hall entry, the entry that completes the CRACs, the per-CRAC entries)`. The
/// whole-hall offset is then the sum of the others' directions, so the calibration
/// could not tell them apart (only each CRAC's total acts). `None` with fewer entries.
pub(super) fn offsets_set_twice(
    effects: &[Box<dyn Effect>],
    hall: &Hall,
) -> Option<(usize, usize, Vec<usize>)> {
    let crac_of = |e: &dyn Effect| -> Option<Option<String>> {
        (e.kind() == KIND).then(|| {
            e.to_spec()
                .fields
                .get("crac")
                .and_then(Value::as_str)
                .map(str::to_string)
        })
    };
    let mut whole = None;
    let mut per_crac: Vec<(usize, String)> = Vec::new();
    for (i, e) in effects.iter().enumerate() {
        match crac_of(e.as_ref()) {
            Some(None) => whole = whole.or(Some(i)),
            Some(Some(id)) if !per_crac.iter().any(|(_, c)| *c == id) => per_crac.push((i, id)),
            _ => continue,
        }
        if let Some(w) = whole {
            if hall.cracs.len() > 1 && per_crac.len() == hall.cracs.len() {
                let entries = per_crac.iter().map(|(j, _)| *j).collect();
                return Some((w, i, entries));
            }
        }
    }
    None
}

/// Builds [`CracSupplyOffset`].
#[derive(Debug, Clone, Copy)]
pub struct CracSupplyOffsetFactory;

impl EffectFactory for CracSupplyOffsetFactory {
    fn kind(&self) -> &str {
        KIND
    }

    fn build(&self, s: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
        let mut f = Fields::new(s).expecting(&["crac"], &["offset_c"])?;
        let crac = match f.opt_str("crac")? {
            None => None,
            Some(id) => match hall.cracs.iter().position(|c| c.id == id) {
                Some(k) => Some((k, id.to_string())),
                None => {
                    return Err(f.error(
                        "crac",
                        unknown_id("CRAC", id, hall.cracs.iter().map(|c| c.id.as_str())),
                    ))
                }
            },
        };
        // The only CRAC is what "every CRAC" means: one placement however written.
        let crac = crac.filter(|_| hall.cracs.len() > 1);
        let param = f.param("offset_c", BOUNDS[0], BOUNDS[1], 0.0)?;
        f.finish()?;
        Ok(Box::new(CracSupplyOffset { crac, param }))
    }

    fn meaning(&self) -> &str {
        "a CRAC supplying warmer or colder than its setpoint: a drifted sensor or a tired coil"
    }

    fn candidates(&self, hall: &Hall) -> Vec<EffectSpec> {
        let mut out = vec![spec(KIND, vec![])];
        if hall.cracs.len() > 1 {
            out.extend(
                hall.cracs
                    .iter()
                    .map(|c| spec(KIND, vec![("crac", Value::from(c.id.clone()))])),
            );
        }
        out
    }
}
