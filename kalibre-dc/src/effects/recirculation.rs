//! `rack_recirculation`: part of a rack's exhaust flows back to its intake through the
//! rack (missing blanking panels), at the exhaust-side air temperature.
//!
//! | field | required | meaning |
//! |---|---|---|
//! | `rack` | yes | rack id |
//! | `z_m` | no | `[z0, z1]` height band (m) of the gap, within the rack; whole height when absent |
//! | `fraction` | no | initial recirculated flow as a fraction of the rack's server flow, default 0.1 |
//! | `fraction_bounds` | no | bounds, within and default `[0, 1]` |

use kalibre_core::{number, Param};
use serde_json::Value;

use super::fields::{param_fields, spec, unknown_id, Fields};
use super::{check_values, Effect, EffectFactory};
use crate::hall::{EffectSpec, Hall};
use crate::sim::{RackRecirculation, SimMods};
use crate::Result;

const KIND: &str = "rack_recirculation";
const BOUNDS: [f64; 2] = [0.0, 1.0];

/// In-rack recirculation of one rack.
#[derive(Debug, Clone)]
pub struct RackRecirculationEffect {
    rack: usize,
    rack_id: String,
    z_m: Option<[f64; 2]>,
    param: Param,
}

impl Effect for RackRecirculationEffect {
    fn kind(&self) -> &str {
        KIND
    }

    fn parameters(&self) -> Vec<Param> {
        vec![self.param.clone()]
    }

    fn to_spec(&self) -> EffectSpec {
        let mut f: Vec<(String, Value)> = vec![("rack".into(), Value::from(self.rack_id.clone()))];
        if let Some(z) = self.z_m {
            f.push(("z_m".into(), Value::from(z.to_vec())));
        }
        f.extend(param_fields(&self.param, BOUNDS[0], BOUNDS[1]));
        spec(
            KIND,
            f.iter().map(|(k, v)| (k.as_str(), v.clone())).collect(),
        )
    }

    fn modify(&self, values: &[f64], _hall: &Hall, mods: &mut SimMods) -> Result<()> {
        check_values(KIND, values, 1)?;
        if values[0] > 0.0 {
            mods.rack_recirculation.push(RackRecirculation {
                rack: self.rack,
                fraction: values[0],
                z_m: self.z_m,
            });
        }
        Ok(())
    }
}

/// Builds [`RackRecirculationEffect`].
#[derive(Debug, Clone, Copy)]
pub struct RackRecirculationFactory;

impl EffectFactory for RackRecirculationFactory {
    fn kind(&self) -> &str {
        KIND
    }

    fn build(&self, s: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
        let mut f = Fields::new(s).expecting(&["rack", "z_m"], &["fraction"])?;
        let id = f.str("rack")?;
        let rack = hall.racks.iter().position(|r| r.id == id).ok_or_else(|| {
            f.error(
                "rack",
                unknown_id("rack", id, hall.racks.iter().map(|r| r.id.as_str())),
            )
        })?;
        let r = &hall.racks[rack];
        let z_m = f.opt_array::<2>("z_m")?;
        let (lo, hi) = (r.position_m[2], r.position_m[2] + r.size_m[2]);
        if let Some([z0, z1]) = z_m {
            if !(z0 < z1 && z0 >= lo - 1e-9 && z1 <= hi + 1e-9) {
                return Err(f.error(
                    "z_m",
                    format!(
                        "[{}, {}] must be increasing and within the rack's height [{}, {}]",
                        number(z0),
                        number(z1),
                        number(lo),
                        number(hi)
                    ),
                ));
            }
        }
        // The whole height given is the whole height: one placement however written.
        let z_m = z_m.filter(|&[z0, z1]| z0 > lo + 1e-9 || z1 < hi - 1e-9);
        let param = f.param("fraction", BOUNDS[0], BOUNDS[1], 0.1)?;
        f.finish()?;
        Ok(Box::new(RackRecirculationEffect {
            rack,
            rack_id: id.to_string(),
            z_m,
            param,
        }))
    }

    fn meaning(&self) -> &str {
        "exhaust returning through the rack to its own intakes: a missing blanking panel or an empty slot"
    }

    fn candidates(&self, hall: &Hall) -> Vec<EffectSpec> {
        hall.racks
            .iter()
            .map(|r| spec(KIND, vec![("rack", Value::from(r.id.clone()))]))
            .collect()
    }
}
