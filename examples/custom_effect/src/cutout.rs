//! `cutout_bypass`: cold supply air escaping through one named cable cut-out tile, e.g. an
//! unsealed cable opening in a hot aisle's raised floor. The cut-out takes a share of every
//! CRAC's floor supply at that CRAC's supply temperature; the regular tiles deliver the rest.
//!
//! | field | required | meaning |
//! |---|---|---|
//! | `tile` | yes | the cut-out's name on the floor plan, e.g. `HA1-07` |
//! | `position_m` | yes | `[x, y]` centre of the tile (m) |
//! | `size_m` | no | `[dx, dy]` tile size (m), default `[0.6, 0.6]` |
//! | `flow_fraction` | no | initial share of the supply flow through the cut-out, default 0.05 |
//! | `flow_fraction_bounds` | no | bounds, within and default `[0, 0.3]` |

use kalibre::core::Param;
use kalibre::dc::effects::{Effect, EffectFactory, Fields};
use kalibre::dc::hall::{Aabb, ContainmentKind, EffectSpec, Hall};
use kalibre::dc::sim::{SimMods, SupplyOpening};
use kalibre::dc::{Error, Result};
use serde_json::{Map, Value};

/// The kind name used in `hall.json`.
pub const KIND: &str = "cutout_bypass";
/// Default and widest bounds of `flow_fraction`.
pub const FLOW_FRACTION_BOUNDS: [f64; 2] = [0.0, 0.3];
/// Standard raised-floor tile size (m).
pub const TILE_M: f64 = 0.6;

/// One cable cut-out tile with its bypass flow.
#[derive(Debug, Clone)]
pub struct CutoutBypass {
    tile: String,
    centre_m: [f64; 2],
    size_m: [f64; 2],
    flow_fraction: Param,
}

impl CutoutBypass {
    /// The floor region of the cut-out (a zero-height box: the floor cell layer).
    pub fn region(&self) -> Aabb {
        let [x, y] = self.centre_m;
        let [dx, dy] = self.size_m;
        Aabb {
            min: [x - 0.5 * dx, y - 0.5 * dy, 0.0],
            max: [x + 0.5 * dx, y + 0.5 * dy, 0.0],
        }
    }

    /// The tile's name.
    pub fn tile(&self) -> &str {
        &self.tile
    }
}

/// An `effects` entry of this kind (the fields a user pastes into `hall.json`).
pub fn cutout_spec(tile: &str, centre_m: [f64; 2], flow_fraction: Option<f64>) -> EffectSpec {
    let mut fields = Map::new();
    fields.insert("tile".into(), Value::from(tile));
    fields.insert("position_m".into(), Value::from(centre_m.to_vec()));
    if let Some(f) = flow_fraction {
        fields.insert("flow_fraction".into(), Value::from(f));
    }
    EffectSpec {
        kind: KIND.into(),
        fields,
    }
}

impl Effect for CutoutBypass {
    fn kind(&self) -> &str {
        KIND
    }

    fn parameters(&self) -> Vec<Param> {
        vec![self.flow_fraction.clone()]
    }

    fn to_spec(&self) -> EffectSpec {
        let mut s = cutout_spec(&self.tile, self.centre_m, Some(self.flow_fraction.initial));
        if self.size_m != [TILE_M, TILE_M] {
            s.fields
                .insert("size_m".into(), Value::from(self.size_m.to_vec()));
        }
        let p = &self.flow_fraction;
        if [p.lower, p.upper] != FLOW_FRACTION_BOUNDS {
            s.fields.insert(
                "flow_fraction_bounds".into(),
                Value::from(vec![p.lower, p.upper]),
            );
        }
        s
    }

    fn modify(&self, values: &[f64], _hall: &Hall, mods: &mut SimMods) -> Result<()> {
        let share = match values {
            [v] if v.is_finite() && (0.0..1.0).contains(v) => *v,
            _ => {
                return Err(Error::Effect {
                    kind: KIND.into(),
                    message: format!("expected one flow fraction in [0, 1), got {values:?}"),
                })
            }
        };
        if share > 0.0 {
            mods.supply_openings.push(SupplyOpening {
                region: self.region(),
                share,
            });
        }
        Ok(())
    }
}

/// Builds [`CutoutBypass`] from its `effects` entry.
#[derive(Debug, Clone, Copy)]
pub struct CutoutBypassFactory;

impl EffectFactory for CutoutBypassFactory {
    fn kind(&self) -> &str {
        KIND
    }

    fn build(&self, spec: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
        let mut f = Fields::new(spec);
        let tile = f.str("tile")?;
        if tile.trim().is_empty() {
            return Err(f.error("tile", "expected a non-empty name"));
        }
        let centre_m = f
            .opt_array::<2>("position_m")?
            .ok_or_else(|| f.error("position_m", "missing (required)"))?;
        let size_m = f.opt_array::<2>("size_m")?.unwrap_or([TILE_M, TILE_M]);
        if !(size_m[0] > 0.0 && size_m[1] > 0.0 && size_m[0] <= 2.0 && size_m[1] <= 2.0) {
            return Err(f.error("size_m", "expected sizes in (0, 2] m"));
        }
        let room = hall.room.size_m;
        let inside = (0..2).all(|a| {
            centre_m[a] - 0.5 * size_m[a] >= -1e-9
                && centre_m[a] + 0.5 * size_m[a] <= room[a] + 1e-9
        });
        if !inside {
            return Err(f.error(
                "position_m",
                format!(
                    "the tile at {centre_m:?} (size {size_m:?}) must lie inside the room [0, {}] x [0, {}] m",
                    room[0], room[1]
                ),
            ));
        }
        let flow_fraction = f.param(
            "flow_fraction",
            FLOW_FRACTION_BOUNDS[0],
            FLOW_FRACTION_BOUNDS[1],
            0.05,
        )?;
        f.finish()?;
        Ok(Box::new(CutoutBypass {
            tile: tile.to_string(),
            centre_m,
            size_m,
            flow_fraction,
        }))
    }

    /// One candidate tile every 0.6 m along the centre line of each hot-aisle containment:
    /// where a forgotten cable cut-out would cool the exhaust.
    fn candidates(&self, hall: &Hall) -> Vec<EffectSpec> {
        let mut out = Vec::new();
        for (c, box_) in hall.containment.iter().enumerate() {
            if box_.kind != ContainmentKind::HotAisle {
                continue;
            }
            let len = [box_.max_m[0] - box_.min_m[0], box_.max_m[1] - box_.min_m[1]];
            // The aisle runs along its longer side.
            let (along, across) = if len[0] >= len[1] { (0, 1) } else { (1, 0) };
            let n = (len[along] / TILE_M + 1e-9).floor() as usize;
            let mid = 0.5 * (box_.min_m[across] + box_.max_m[across]);
            for j in 0..n {
                let mut centre = [0.0; 2];
                centre[along] = box_.min_m[along] + (j as f64 + 0.5) * TILE_M;
                centre[across] = mid;
                let centre = centre.map(|v| (v * 1e3).round() / 1e3);
                out.push(cutout_spec(
                    &format!("HA{}-{:02}", c + 1, j + 1),
                    centre,
                    None,
                ));
            }
        }
        out
    }
}
