//! `bypass`: part of the supply enters the room where no server draws it (a cable
//! cut-out in a hot aisle, a misplaced tile), at supply temperature; the regular tiles
//! (and any CRAC fronts) deliver the rest. The opening is the plenum's, so a hall with no
//! `floor` CRAC refuses it, and the diagnosis has no such candidate there.
//!
//! | field | required | meaning |
//! |---|---|---|
//! | `position_m`, `size_m` | one placement | floor opening: `[x, y]` minimum corner and `[dx, dy]` size (m), inside the room and not under a rack or CRAC |
//! | `behind_rack` | one placement | rack id: the floor strip (rack width, `depth_m` deep, or to the wall, rack, CRAC or tile behind it if that is nearer) behind its exhaust; a rack that exhausts against one is refused |
//! | `depth_m` | no | depth of the `behind_rack` strip (m), default 0.4 |
//! | `fraction` | no | initial share of the CRAC flow, default 0.05 |
//! | `fraction_bounds` | no | bounds, within and default `[0, 0.5]` |
//!
//! The hall's openings together, each at its upper bound, must leave the tiles some of
//! the supply ([`super::first_oversubscribed`]): two bypasses at the default bounds are
//! refused.

use kalibre_core::Param;
use serde_json::Value;

use super::fields::{param_fields, spec, unknown_id, Fields};
use super::{check_values, Effect, EffectFactory};
use crate::hall::{Aabb, EffectSpec, Hall, SupplyKind, GEOMETRY_TOL_M};
use crate::sim::{SimMods, SupplyOpening};
use crate::{Error, Result};

const KIND: &str = "bypass";
const BOUNDS: [f64; 2] = [0.0, 0.5];
/// The share of the supply a diagnosis candidate leaves the tiles at its upper bound,
/// with the hall's own openings at theirs.
pub const CANDIDATE_TILE_SHARE: f64 = 0.05;
/// No candidates when less than this share is left for them.
const MIN_CANDIDATE_UPPER: f64 = 0.01;

/// Where the bypass air enters.
#[derive(Debug, Clone, PartialEq)]
enum Placement {
    Floor {
        position_m: [f64; 2],
        size_m: [f64; 2],
    },
    BehindRack {
        rack: String,
        depth_m: f64,
    },
}

/// A bypass opening.
#[derive(Debug, Clone)]
pub struct Bypass {
    placement: Placement,
    region: Aabb,
    param: Param,
}

impl Effect for Bypass {
    fn kind(&self) -> &str {
        KIND
    }

    fn parameters(&self) -> Vec<Param> {
        vec![self.param.clone()]
    }

    fn to_spec(&self) -> EffectSpec {
        let mut f: Vec<(String, Value)> = match &self.placement {
            Placement::Floor { position_m, size_m } => vec![
                ("position_m".into(), Value::from(position_m.to_vec())),
                ("size_m".into(), Value::from(size_m.to_vec())),
            ],
            Placement::BehindRack { rack, depth_m } => vec![
                ("behind_rack".into(), Value::from(rack.clone())),
                ("depth_m".into(), Value::from(*depth_m)),
            ],
        };
        f.extend(param_fields(&self.param, BOUNDS[0], BOUNDS[1]));
        spec(
            KIND,
            f.iter().map(|(k, v)| (k.as_str(), v.clone())).collect(),
        )
    }

    fn modify(&self, values: &[f64], _hall: &Hall, mods: &mut SimMods) -> Result<()> {
        check_values(KIND, values, 1)?;
        if values[0] > 0.0 {
            mods.supply_openings.push(SupplyOpening {
                region: self.region,
                share: values[0],
            });
        }
        Ok(())
    }
}

/// Builds [`Bypass`].
#[derive(Debug, Clone, Copy)]
pub struct BypassFactory;

impl EffectFactory for BypassFactory {
    fn kind(&self) -> &str {
        KIND
    }

    fn build(&self, s: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
        let mut f = Fields::new(s).expecting(
            &["position_m", "size_m", "behind_rack", "depth_m"],
            &["fraction"],
        )?;
        let pos = f.opt_array::<2>("position_m")?;
        let size = f.opt_array::<2>("size_m")?;
        let behind = f.opt_str("behind_rack")?;
        // The opening lets plenum air up through the floor; a hall whose CRACs all blow
        // through their fronts has no plenum, so no supply could come up there.
        if hall.cracs.iter().all(|c| c.supply != SupplyKind::Floor) {
            return Err(Error::Effect {
                kind: KIND.into(),
                message: "a bypass is an opening of the raised floor's plenum, and no CRAC \
                          of this hall supplies one (every `supply` is `front`)"
                    .into(),
            });
        }
        let depth = f.opt_f64("depth_m")?;
        let room = hall.room.size_m;
        let (placement, region) =
            match (pos, size, behind) {
                (Some(p), Some(sz), None) => {
                    if depth.is_some() {
                        return Err(f.error("depth_m", "only with `behind_rack`"));
                    }
                    if !(sz[0] > 0.0 && sz[1] > 0.0) {
                        return Err(f.error("size_m", "must be positive"));
                    }
                    if p[0] < -1e-9
                        || p[1] < -1e-9
                        || p[0] + sz[0] > room[0] + 1e-9
                        || p[1] + sz[1] > room[1] + 1e-9
                    {
                        return Err(f.error("position_m", "the opening must lie inside the room"));
                    }
                    let region = Aabb {
                        min: [p[0], p[1], 0.0],
                        max: [p[0] + sz[0], p[1] + sz[1], 0.0],
                    };
                    // Air cannot rise through a rack or a CRAC standing on the opening,
                    // and an opening partly under one would silently lose that part:
                    // the same rule as for tiles (touching is fine).
                    let column = Aabb {
                        min: region.min,
                        max: [region.max[0], region.max[1], room[2]],
                    };
                    if let Some((what, id, b)) = hall
                        .solid_boxes()
                        .find(|(_, _, b)| column.overlaps(b, GEOMETRY_TOL_M))
                    {
                        let under = match b.contains_box(&region, GEOMETRY_TOL_M) {
                            true => "lies under",
                            false => "runs partly under",
                        };
                        return Err(f.error(
                            "position_m",
                            format!(
                                "the opening {under} {what} `{id}`; expected open floor \
                                 (touching is fine, tolerance 1 mm)"
                            ),
                        ));
                    }
                    // On a tile, the floor there would deliver the tile's share and the
                    // opening's: the same double count that overlapping tiles are refused
                    // for.
                    if let Some(i) = (hall.tiles.iter())
                        .position(|t| column.overlaps(&t.column(room[2]), GEOMETRY_TOL_M))
                    {
                        return Err(f.error(
                            "position_m",
                            format!(
                                "the opening overlaps tile {i} (/tiles/{i}), whose supply the \
                                 floor there would then deliver twice; expected open floor \
                                 beside the tiles (touching is fine, tolerance 1 mm)"
                            ),
                        ));
                    }
                    (
                        Placement::Floor {
                            position_m: p,
                            size_m: sz,
                        },
                        region,
                    )
                }
                (None, None, Some(id)) => {
                    let r = hall.racks.iter().find(|r| r.id == id).ok_or_else(|| {
                        f.error(
                            "behind_rack",
                            unknown_id("rack", id, hall.racks.iter().map(|r| r.id.as_str())),
                        )
                    })?;
                    let d = depth.unwrap_or(0.4);
                    if !(d > 0.0 && d <= 5.0) {
                        return Err(f.error("depth_m", format!("{d} is outside (0, 5]")));
                    }
                    let b = Aabb::from_position_size(r.position_m, r.size_m);
                    let (axis, sign) = r.inlet.opposite().axis_sign();
                    let mut region = Aabb {
                        min: [b.min[0], b.min[1], 0.0],
                        max: [b.max[0], b.max[1], 0.0],
                    };
                    if sign > 0.0 {
                        region.min[axis] = b.max[axis];
                        region.max[axis] = (b.max[axis] + d).min(room[axis]);
                    } else {
                        region.max[axis] = b.min[axis];
                        region.min[axis] = (b.min[axis] - d).max(0.0);
                    }
                    // The strip ends at the first rack or CRAC behind the exhaust, as it
                    // ends at the wall: air cannot enter under a solid, and a strip
                    // partly under one would lose that part of the flow. It ends at a
                    // tile too: the floor there delivers the tile's share already, and
                    // an opening over it would count that air twice.
                    let mut against = "a wall".to_string();
                    let column = |r: &Aabb| Aabb {
                        min: r.min,
                        max: [r.max[0], r.max[1], room[2]],
                    };
                    let solids = hall
                        .solid_boxes()
                        .filter(|(_, other, _)| *other != id)
                        .map(|(what, other, o)| (format!("{what} `{other}`"), o));
                    let tiles = (hall.tiles.iter().enumerate())
                        .map(|(i, t)| (format!("tile {i} (/tiles/{i})"), t.column(room[2])));
                    for (what, o) in solids.chain(tiles) {
                        if !column(&region).overlaps(&o, GEOMETRY_TOL_M) {
                            continue;
                        }
                        if sign > 0.0 {
                            region.max[axis] = region.max[axis].min(o.min[axis]);
                        } else {
                            region.min[axis] = region.min[axis].max(o.max[axis]);
                        }
                        against = what;
                    }
                    if region.max[axis] - region.min[axis] <= 1e-9 {
                        return Err(f.error(
                            "behind_rack",
                            format!("rack `{id}` exhausts against {against}"),
                        ));
                    }
                    (
                        Placement::BehindRack {
                            rack: id.to_string(),
                            depth_m: d,
                        },
                        region,
                    )
                }
                (None, None, None) => return Err(f.error(
                    "position_m",
                    "missing: give `position_m` and `size_m` (a floor opening) or `behind_rack`",
                )),
                (Some(_), None, None) => {
                    return Err(f.error(
                        "size_m",
                        "missing: a floor opening needs `position_m` and `size_m`",
                    ))
                }
                (None, Some(_), None) => {
                    return Err(f.error(
                        "position_m",
                        "missing: a floor opening needs `position_m` and `size_m`",
                    ))
                }
                (_, _, Some(_)) => {
                    return Err(f.error(
                        "behind_rack",
                        "give either `behind_rack` or `position_m` and `size_m`, not both",
                    ))
                }
            };
        let param = f.param("fraction", BOUNDS[0], BOUNDS[1], 0.05)?;
        f.finish()?;
        Ok(Box::new(Bypass {
            placement,
            region,
            param,
        }))
    }

    fn meaning(&self) -> &str {
        "supply entering where no server draws it: a cable cut-out or a misplaced tile"
    }

    /// A strip behind each rack. When the hall's own openings could take much of the
    /// supply at their upper bounds, the candidates' upper bound is lowered so that the
    /// tiles keep [`CANDIDATE_TILE_SHARE`] of it: a hall written with a candidate added
    /// (`kalibre diagnose --write-hall`) then calibrates over its whole box.
    fn candidates(&self, hall: &Hall) -> Vec<EffectSpec> {
        let taken: f64 = hall
            .effects
            .iter()
            .filter_map(|s| super::from_spec(s, hall).ok())
            .map(|e| super::supply_share_at_upper_bounds(e.as_ref(), hall))
            .sum();
        let upper = BOUNDS[1].min(1.0 - CANDIDATE_TILE_SHARE - taken);
        if upper < MIN_CANDIDATE_UPPER {
            // The hall's openings may take (almost) all of it already.
            return Vec::new();
        }
        hall.racks
            .iter()
            .map(|r| {
                let mut fields = vec![("behind_rack", Value::from(r.id.clone()))];
                if upper < BOUNDS[1] {
                    let upper = (upper * 1e4).floor() / 1e4;
                    fields.push(("fraction_bounds", Value::from(vec![BOUNDS[0], upper])));
                }
                spec(KIND, fields)
            })
            // A rack exhausting against a wall, rack or CRAC has no strip to open.
            .filter(|c| self.build(c, hall).is_ok())
            .collect()
    }
}
