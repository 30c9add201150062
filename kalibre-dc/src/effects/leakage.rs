//! `containment_leakage`: openings in aisle containment (gaps, open doors, missing
//! panels); the flow through them follows the pressure difference across the panel.
//!
//! | field | required | meaning |
//! |---|---|---|
//! | `containment` | no | index into `containment`; every containment when absent |
//! | `sides` | no | panels opened: any of `-x`, `+x`, `-y`, `+y`, `top`; all when absent (`-x`/`+x` are the aisle-end doors for rows along x); a side on the room's boundary, which has no panel (a ceiling-high containment's `top`), is refused |
//! | `open_fraction` | no | initial open fraction of those panels, default 0.05 |
//! | `open_fraction_bounds` | no | bounds, within and default `[0, 1]` |

use kalibre_core::Param;
use serde_json::Value;

use super::fields::{param_fields, spec, Fields};
use super::{check_values, Effect, EffectFactory};
use crate::hall::{EffectSpec, Hall};
use crate::sim::{SimMods, WallOpening, WallSide};
use crate::Result;

const KIND: &str = "containment_leakage";
const BOUNDS: [f64; 2] = [0.0, 1.0];

/// Leaky containment panels.
#[derive(Debug, Clone)]
pub struct ContainmentLeakage {
    containment: Option<usize>,
    sides: Option<Vec<WallSide>>,
    param: Param,
}

impl Effect for ContainmentLeakage {
    fn kind(&self) -> &str {
        KIND
    }

    fn parameters(&self) -> Vec<Param> {
        vec![self.param.clone()]
    }

    fn to_spec(&self) -> EffectSpec {
        let mut f: Vec<(String, Value)> = Vec::new();
        if let Some(c) = self.containment {
            f.push(("containment".into(), Value::from(c)));
        }
        if let Some(s) = &self.sides {
            f.push((
                "sides".into(),
                Value::from(s.iter().map(|w| w.as_str()).collect::<Vec<_>>()),
            ));
        }
        f.extend(param_fields(&self.param, BOUNDS[0], BOUNDS[1]));
        spec(
            KIND,
            f.iter().map(|(k, v)| (k.as_str(), v.clone())).collect(),
        )
    }

    fn modify(&self, values: &[f64], hall: &Hall, mods: &mut SimMods) -> Result<()> {
        check_values(KIND, values, 1)?;
        let sides = self.sides.clone().unwrap_or_else(|| WallSide::ALL.to_vec());
        let which: Vec<usize> = match self.containment {
            Some(c) => vec![c],
            None => (0..hall.containment.len()).collect(),
        };
        for c in which {
            mods.wall_openings.push(WallOpening {
                containment: c,
                sides: sides.clone(),
                open_fraction: values[0].clamp(0.0, 1.0),
            });
        }
        Ok(())
    }
}

/// Builds [`ContainmentLeakage`].
#[derive(Debug, Clone, Copy)]
pub struct ContainmentLeakageFactory;

impl EffectFactory for ContainmentLeakageFactory {
    fn kind(&self) -> &str {
        KIND
    }

    fn build(&self, s: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
        let mut f = Fields::new(s).expecting(&["containment", "sides"], &["open_fraction"])?;
        if hall.containment.is_empty() {
            return Err(f.error("kind", "the hall has no containment"));
        }
        let containment = f.opt_usize("containment")?;
        if let Some(c) = containment {
            if c >= hall.containment.len() {
                return Err(f.error(
                    "containment",
                    format!(
                        "index {c} is out of range: the hall's containments are 0..{}",
                        hall.containment.len() - 1
                    ),
                ));
            }
        }
        let sides = match f.opt_str_list("sides")? {
            None => None,
            Some(list) => {
                if list.is_empty() {
                    return Err(f.error("sides", "empty list"));
                }
                let mut out = Vec::new();
                for s in list {
                    let side = WallSide::parse(s).ok_or_else(|| {
                        f.error("sides", format!("`{s}` is not one of -x, +x, -y, +y, top"))
                    })?;
                    if out.contains(&side) {
                        return Err(f.error("sides", format!("`{s}` is listed twice")));
                    }
                    out.push(side);
                }
                // One order, and every side as none given: the same opening is one
                // placement however it is written (two entries of it are refused).
                out.sort_by_key(|w| WallSide::ALL.iter().position(|a| a == w));
                (out.len() < WallSide::ALL.len()).then_some(out)
            }
        };
        // A side on the room's boundary has no panel to open: such an entry would hide
        // nothing (synth wrote its truth all the same).
        if let Some(list) = &sides {
            let targets: Vec<usize> = match containment {
                Some(c) => vec![c],
                None => (0..hall.containment.len()).collect(),
            };
            for side in list {
                if let Some(why) = targets
                    .iter()
                    .map(|&c| no_panel(hall, c, *side))
                    .collect::<Option<Vec<_>>>()
                    .and_then(|whys| whys.into_iter().next())
                {
                    return Err(
                        f.error("sides", format!("`{}` opens nothing: {why}", side.as_str()))
                    );
                }
            }
        }
        // The only containment is what "every containment" means.
        let containment = containment.filter(|_| hall.containment.len() > 1);
        let param = f.param("open_fraction", BOUNDS[0], BOUNDS[1], 0.05)?;
        f.finish()?;
        Ok(Box::new(ContainmentLeakage {
            containment,
            sides,
            param,
        }))
    }

    fn meaning(&self) -> &str {
        "air crossing the aisle containment: a gap, an open door or a missing panel"
    }

    fn candidates(&self, hall: &Hall) -> Vec<EffectSpec> {
        // Leaky panels everywhere (the common case: a containment kit of one make), each
        // containment as a whole, then each side of each containment (a door left open).
        let mut out = Vec::new();
        if hall.containment.is_empty() {
            return out;
        }
        out.push(spec(KIND, vec![]));
        if hall.containment.len() > 1 {
            for c in 0..hall.containment.len() {
                out.push(spec(KIND, vec![("containment", Value::from(c))]));
            }
        }
        for c in 0..hall.containment.len() {
            for s in WallSide::ALL
                .into_iter()
                .filter(|&s| no_panel(hall, c, s).is_none())
            {
                out.push(spec(
                    KIND,
                    vec![
                        ("containment", Value::from(c)),
                        ("sides", Value::from(vec![s.as_str()])),
                    ],
                ));
            }
        }
        out
    }
}

/// Why containment `c` has no panel on `side`: that side lies on the room's boundary (a
/// ceiling-high containment has no top; one against a wall, no panel there).
fn no_panel(hall: &Hall, c: usize, side: WallSide) -> Option<String> {
    let b = &hall.containment[c];
    let room = hall.room.size_m;
    let tol = crate::hall::GEOMETRY_TOL_M;
    let (at_boundary, what) = match side {
        WallSide::MinusX => (b.min_m[0] <= tol, "stands against the room wall at x = 0"),
        WallSide::PlusX => (
            b.max_m[0] >= room[0] - tol,
            "stands against the room's +x wall",
        ),
        WallSide::MinusY => (b.min_m[1] <= tol, "stands against the room wall at y = 0"),
        WallSide::PlusY => (
            b.max_m[1] >= room[1] - tol,
            "stands against the room's +y wall",
        ),
        WallSide::Top => (
            b.max_m[2] >= room[2] - tol,
            "reaches the ceiling, so it has no top panel",
        ),
    };
    at_boundary.then(|| format!("containment {c} {what}"))
}
