//! The rules of `formats.md` section 1 that the JSON structure alone does not enforce:
//! ids, unit ranges, boxes inside the room, overlaps, sensors in the air, alpha bounds.
//!
//! The first problem in document order (section by section) is reported, with the JSON
//! pointer of the offending value.

use std::collections::{HashMap, HashSet};

use super::geometry::Aabb;
use super::types::{Hall, SupplyKind, HALL_SCHEMA};
use crate::snapshots::number;
use crate::{Error, Result};

// One rule for every name, shared with a model of your own's (kalibre-core).
pub use kalibre_core::{unprintable_name, MAX_NAME_CHARS};

/// A point as `[x, y, z]`, each coordinate readable however large.
fn point(p: &[f64; 3]) -> String {
    format!("[{}, {}, {}]", number(p[0]), number(p[1]), number(p[2]))
}

/// The largest alpha bound taken (cfm/W): a server's air would then warm by 0.02 K, and
/// larger values are a unit error (alpha is about 0.1 for real servers).
pub const MAX_ALPHA_CFM_PER_W: f64 = 100.0;

/// The smallest alpha bound taken (cfm/W): a server's air would warm by 1.8 million K.
/// Below it the surrogate's features overflow (a fit at 1e-200 went NaN); a value in
/// another unit (m3/s per W, about 5e-5) is still taken, and warned of.
pub const MIN_ALPHA_CFM_PER_W: f64 = 1e-6;

/// The largest CRAC flow taken (m3/s): ten times the largest units built.
pub const MAX_CRAC_FLOW_M3_S: f64 = 300.0;

/// The most units a rack may have: the tallest racks built have about 60 (a unit is
/// 44.45 mm), and a unit much thinner than the grid leaves a server no cell to draw from.
pub const MAX_RACK_UNITS: u32 = 100;

/// Tolerance of every geometric test (m): boxes that touch do not overlap.
pub const GEOMETRY_TOL_M: f64 = 1e-3;

const AXES: [&str; 3] = ["x", "y", "z"];

impl Hall {
    /// Checks every rule of `formats.md` section 1 that the types do not already enforce;
    /// `file` names the source in errors. [`Hall::from_json_str`] calls it.
    pub fn validate(&self, file: &str) -> Result<()> {
        let c = Checker { file };
        if self.schema != HALL_SCHEMA {
            return Err(c.err(
                "/schema",
                format!("expected \"{HALL_SCHEMA}\", found \"{}\"", self.schema),
            ));
        }
        let room = self.room.size_m;
        for (a, &s) in room.iter().enumerate() {
            c.positive(s, &format!("/room/size_m/{a}"), "room size")?;
        }
        self.check_server_types(&c)?;
        self.check_cracs(&c, room)?;
        for (i, t) in self.tiles.iter().enumerate() {
            let p = format!("/tiles/{i}");
            c.check_box(&p, &t.position_m, &t.size_m, &room[..2])?;
            let f = t.open_fraction;
            c.finite(f, &format!("{p}/open_fraction"))?;
            if !(f > 0.0 && f <= 1.0) {
                return Err(c.err(
                    format!("{p}/open_fraction"),
                    format!("expected a fraction in (0, 1], found {}", number(f)),
                ));
            }
        }
        for (i, r) in self.returns.iter().enumerate() {
            c.check_box(
                &format!("/returns/{i}"),
                &r.position_m,
                &r.size_m,
                &room[..2],
            )?;
        }
        self.check_racks(&c, room)?;
        self.check_tiles_clear(&c, room)?;
        self.check_containment(&c, room)?;
        self.check_sensors(&c)?;
        for (i, e) in self.effects.iter().enumerate() {
            if e.kind.is_empty() {
                return Err(c.err(
                    format!("/effects/{i}/kind"),
                    "expected a non-empty effect kind",
                ));
            }
        }
        Ok(())
    }

    fn check_server_types(&self, c: &Checker) -> Result<()> {
        c.unique_ids(
            self.server_types
                .iter()
                .enumerate()
                .map(|(i, t)| (t.id.as_str(), format!("/server_types/{i}/id"))),
        )?;
        for (i, t) in self.server_types.iter().enumerate() {
            let p = format!("/server_types/{i}/alpha_cfm_per_w");
            let a = &t.alpha_cfm_per_w;
            c.finite(a.initial, &format!("{p}/initial"))?;
            c.finite(a.min, &format!("{p}/min"))?;
            c.finite(a.max, &format!("{p}/max"))?;
            if a.min <= 0.0 {
                return Err(c.err(
                    format!("{p}/min"),
                    format!(
                        "expected 0 < min <= initial <= max, found min {}",
                        number(a.min)
                    ),
                ));
            }
            if a.min < MIN_ALPHA_CFM_PER_W {
                return Err(c.err(
                    format!("{p}/min"),
                    format!(
                        "expected min >= {} cfm/W (a server air rise of 1.8 million K), found {}",
                        number(MIN_ALPHA_CFM_PER_W),
                        number(a.min)
                    ),
                ));
            }
            if a.min > a.max {
                return Err(c.err(
                    p,
                    format!(
                        "expected 0 < min <= initial <= max, found min {} > max {} (inverted bounds)",
                        number(a.min),
                        number(a.max)
                    ),
                ));
            }
            if a.max > MAX_ALPHA_CFM_PER_W {
                return Err(c.err(
                    format!("{p}/max"),
                    format!(
                        "expected max <= {MAX_ALPHA_CFM_PER_W} cfm/W (a server air rise of 0.02 K), found {}",
                        number(a.max)
                    ),
                ));
            }
            if a.initial < a.min || a.initial > a.max {
                return Err(c.err(
                    format!("{p}/initial"),
                    format!(
                        "expected 0 < min <= initial <= max, found initial {} outside [{}, {}]",
                        number(a.initial),
                        number(a.min),
                        number(a.max)
                    ),
                ));
            }
        }
        Ok(())
    }

    fn check_cracs(&self, c: &Checker, room: [f64; 3]) -> Result<()> {
        if self.cracs.is_empty() {
            // Servers would heat the room with nothing to take the heat away.
            return Err(c.err("/cracs", "a hall needs at least one CRAC"));
        }
        c.unique_ids(
            self.cracs
                .iter()
                .enumerate()
                .map(|(i, k)| (k.id.as_str(), format!("/cracs/{i}/id"))),
        )?;
        for (i, k) in self.cracs.iter().enumerate() {
            let p = format!("/cracs/{i}");
            c.check_box(&p, &k.position_m, &k.size_m, &room)?;
            c.positive(
                k.rated_flow_m3_s,
                &format!("{p}/rated_flow_m3_s"),
                "rated flow",
            )?;
            if k.rated_flow_m3_s > MAX_CRAC_FLOW_M3_S {
                return Err(c.err(
                    format!("{p}/rated_flow_m3_s"),
                    format!(
                        "expected a rated flow of at most {MAX_CRAC_FLOW_M3_S} m3/s, found {}",
                        number(k.rated_flow_m3_s)
                    ),
                ));
            }
            if k.supply == SupplyKind::Floor && self.tiles.is_empty() {
                return Err(c.err(
                    format!("{p}/supply"),
                    format!(
                        "CRAC `{}` has supply `floor`, which needs tiles, but the hall has no tiles",
                        k.id
                    ),
                ));
            }
        }
        // The converse: tiles fed by no CRAC deliver nothing, and a `front` typed for
        // `floor` would silently make another hall.
        if !self.tiles.is_empty() && self.cracs.iter().all(|k| k.supply != SupplyKind::Floor) {
            return Err(c.err(
                "/tiles",
                format!(
                    "the hall has {} tile(s), but no CRAC has supply `floor` to feed them; \
                     set the supply of the CRACs under the raised floor to `floor`, or remove \
                     the tiles",
                    self.tiles.len()
                ),
            ));
        }
        Ok(())
    }

    fn check_racks(&self, c: &Checker, room: [f64; 3]) -> Result<()> {
        c.unique_ids(
            self.racks
                .iter()
                .enumerate()
                .map(|(i, r)| (r.id.as_str(), format!("/racks/{i}/id"))),
        )?;
        c.unique_ids(self.racks.iter().enumerate().flat_map(|(i, r)| {
            r.servers
                .iter()
                .enumerate()
                .map(move |(j, s)| (s.id.as_str(), format!("/racks/{i}/servers/{j}/id")))
        }))?;
        let types: HashSet<&str> = self.server_types.iter().map(|t| t.id.as_str()).collect();
        for (i, r) in self.racks.iter().enumerate() {
            let p = format!("/racks/{i}");
            c.check_box(&p, &r.position_m, &r.size_m, &room)?;
            if r.units < 1 {
                return Err(c.err(format!("{p}/units"), "expected units >= 1, found 0"));
            }
            if r.units > MAX_RACK_UNITS {
                return Err(c.err(
                    format!("{p}/units"),
                    format!(
                        "expected at most {MAX_RACK_UNITS} units (racks have about 42-60), found {}",
                        r.units
                    ),
                ));
            }
            for (j, s) in r.servers.iter().enumerate() {
                let sp = format!("{p}/servers/{j}");
                if !types.contains(s.server_type.as_str()) {
                    let mut known: Vec<&str> = types.iter().copied().collect();
                    known.sort_unstable();
                    let expected = match known.is_empty() {
                        true => "`server_types` defines none".to_string(),
                        false => format!("expected one of: {}", known.join(", ")),
                    };
                    return Err(c.err(
                        format!("{sp}/type"),
                        format!("unknown server type `{}`; {expected}", s.server_type),
                    ));
                }
                if s.u < 1 || s.u > r.units {
                    return Err(c.err(
                        format!("{sp}/u"),
                        format!(
                            "server `{}` starts at unit {}, outside its rack's units; expected 1..={}",
                            s.id, s.u, r.units
                        ),
                    ));
                }
                if s.height_u < 1 {
                    return Err(c.err(format!("{sp}/height_u"), "expected height_u >= 1, found 0"));
                }
                let top = u64::from(s.u) + u64::from(s.height_u) - 1;
                if top > u64::from(r.units) {
                    return Err(c.err(
                        format!("{sp}/height_u"),
                        format!(
                            "server `{}` spans units {}..={top}, outside its rack's units; expected u + height_u - 1 <= {}",
                            s.id, s.u, r.units
                        ),
                    ));
                }
            }
            check_unit_overlaps(c, &p, r)?;
        }
        let boxes: Vec<Aabb> = self
            .racks
            .iter()
            .map(|r| Aabb::from_position_size(r.position_m, r.size_m))
            .collect();
        if let Some((first, later)) = first_overlap(&boxes) {
            return Err(c.err(
                format!("/racks/{later}"),
                format!(
                    "rack `{}` overlaps rack `{}`; expected racks not to overlap (touching is fine, tolerance 1 mm)",
                    self.racks[later].id, self.racks[first].id
                ),
            ));
        }
        for (i, (r, b)) in self.racks.iter().zip(&boxes).enumerate() {
            for k in &self.cracs {
                if b.overlaps(
                    &Aabb::from_position_size(k.position_m, k.size_m),
                    GEOMETRY_TOL_M,
                ) {
                    return Err(c.err(
                        format!("/racks/{i}"),
                        format!(
                            "rack `{}` overlaps CRAC `{}`; expected racks not to overlap a CRAC",
                            r.id, k.id
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Every rack and CRAC as (`"rack"` or `"CRAC"`, id, box): the solids that sensors
    /// and tiles must keep out of.
    pub(crate) fn solid_boxes(&self) -> impl Iterator<Item = (&'static str, &str, Aabb)> + '_ {
        let racks = self.racks.iter().map(|r| {
            let b = Aabb::from_position_size(r.position_m, r.size_m);
            ("rack", r.id.as_str(), b)
        });
        let cracs = self.cracs.iter().map(|k| {
            let b = Aabb::from_position_size(k.position_m, k.size_m);
            ("CRAC", k.id.as_str(), b)
        });
        racks.chain(cracs)
    }

    /// No tile under a rack or CRAC (the simulator drops a tile's cells that a grid snaps
    /// under a neighbouring rack, so the hall itself must not put it there), and no two
    /// tiles or return grilles on the same area.
    fn check_tiles_clear(&self, c: &Checker, room: [f64; 3]) -> Result<()> {
        for (what, id, solid) in self.solid_boxes() {
            for (i, t) in self.tiles.iter().enumerate() {
                if t.column(room[2]).overlaps(&solid, GEOMETRY_TOL_M) {
                    return Err(c.err(
                        format!("/tiles/{i}"),
                        format!(
                            "tile at {:?} lies under {what} `{id}`; expected tiles clear of racks and CRACs (touching is fine, tolerance 1 mm)",
                            t.position_m
                        ),
                    ));
                }
            }
        }
        // Two tiles (or two return grilles) on the same floor (ceiling) area would count
        // its air twice.
        let tiles = self.tiles.iter().map(|t| (t.position_m, t.size_m));
        check_no_overlap(c, "tiles", "tile", tiles)?;
        let returns = self.returns.iter().map(|r| (r.position_m, r.size_m));
        check_no_overlap(c, "returns", "return grille", returns)
    }

    fn check_containment(&self, c: &Checker, room: [f64; 3]) -> Result<()> {
        for (i, b) in self.containment.iter().enumerate() {
            let p = format!("/containment/{i}");
            for a in 0..3 {
                c.finite(b.min_m[a], &format!("{p}/min_m/{a}"))?;
                c.finite(b.max_m[a], &format!("{p}/max_m/{a}"))?;
            }
            for a in 0..3 {
                if b.max_m[a] <= b.min_m[a] {
                    return Err(c.err(
                        format!("{p}/max_m/{a}"),
                        format!(
                            "expected max_m > min_m along {} (positive size), found {} <= {}",
                            AXES[a],
                            number(b.max_m[a]),
                            number(b.min_m[a])
                        ),
                    ));
                }
                if b.min_m[a] < -GEOMETRY_TOL_M {
                    return Err(c.err(
                        format!("{p}/min_m/{a}"),
                        format!(
                            "expected >= 0 (inside the room), found {}",
                            number(b.min_m[a])
                        ),
                    ));
                }
                if b.max_m[a] > room[a] + GEOMETRY_TOL_M {
                    return Err(c.err(
                        format!("{p}/max_m/{a}"),
                        format!(
                            "expected <= {} (inside the room along {}), found {}",
                            number(room[a]),
                            AXES[a],
                            number(b.max_m[a])
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn check_sensors(&self, c: &Checker) -> Result<()> {
        c.unique_ids(
            self.sensors
                .iter()
                .enumerate()
                .map(|(i, s)| (s.id.as_str(), format!("/sensors/{i}/id"))),
        )?;
        let room = self.room_box();
        for (i, s) in self.sensors.iter().enumerate() {
            let p = format!("/sensors/{i}/position_m");
            for (a, &v) in s.position_m.iter().enumerate() {
                c.finite(v, &format!("{p}/{a}"))?;
            }
            if !room.contains_point(s.position_m, GEOMETRY_TOL_M) {
                return Err(c.err(
                    p,
                    format!(
                        "sensor `{}` at {} is outside the room; expected a point within [0, {}] x [0, {}] x [0, {}] m",
                        s.id,
                        point(&s.position_m),
                        number(room.max[0]),
                        number(room.max[1]),
                        number(room.max[2])
                    ),
                ));
            }
            for (what, id, b) in self.solid_boxes() {
                if b.contains_point_strict(s.position_m, GEOMETRY_TOL_M) {
                    return Err(c.err(
                        p,
                        format!(
                            "sensor `{}` at {} is inside {what} `{id}`; expected a point in the air, not inside a solid",
                            s.id,
                            point(&s.position_m)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// No two of these floor or ceiling rectangles (minimum corner, size) overlap; the later
/// one is named.
fn check_no_overlap(
    c: &Checker,
    list: &str,
    what: &str,
    rects: impl Iterator<Item = ([f64; 2], [f64; 2])>,
) -> Result<()> {
    let boxes: Vec<Aabb> = rects
        .map(|(p, s)| Aabb {
            min: [p[0], p[1], 0.0],
            max: [p[0] + s[0], p[1] + s[1], 1.0],
        })
        .collect();
    for (j, b) in boxes.iter().enumerate() {
        if let Some(i) = boxes[..j]
            .iter()
            .position(|a| a.overlaps(b, GEOMETRY_TOL_M))
        {
            return Err(c.err(
                format!("/{list}/{j}"),
                format!(
                    "{what} at {:?} overlaps {what} {i} at {:?}; expected {what}s not to overlap (touching is fine, tolerance 1 mm)",
                    [b.min[0], b.min[1]],
                    [boxes[i].min[0], boxes[i].min[1]]
                ),
            ));
        }
    }
    Ok(())
}

/// Servers of one rack must not share a unit. Sorting by first unit keeps this linear in
/// the number of servers after the sort.
fn check_unit_overlaps(c: &Checker, rack_pointer: &str, r: &super::types::Rack) -> Result<()> {
    let mut spans: Vec<(u64, u64, usize)> = r
        .servers
        .iter()
        .enumerate()
        .map(|(j, s)| {
            let u = u64::from(s.u);
            (u, u + u64::from(s.height_u).max(1) - 1, j)
        })
        .collect();
    spans.sort_unstable();
    let mut reach: Option<(u64, usize)> = None; // highest top so far and its server
    for &(u, top, j) in &spans {
        if let Some((prev_top, k)) = reach {
            if u <= prev_top {
                let (first, later) = (j.min(k), j.max(k));
                let (a, b) = (&r.servers[first], &r.servers[later]);
                return Err(c.err(
                    format!("{rack_pointer}/servers/{later}/u"),
                    format!(
                        "server `{}` (units {}..={}) overlaps server `{}` (units {}..={}); expected no two servers of a rack to share a unit",
                        b.id,
                        b.u,
                        u64::from(b.u) + u64::from(b.height_u) - 1,
                        a.id,
                        a.u,
                        u64::from(a.u) + u64::from(a.height_u) - 1
                    ),
                ));
            }
        }
        if reach.is_none_or(|(prev_top, _)| top > prev_top) {
            reach = Some((top, j));
        }
    }
    Ok(())
}

/// The overlapping pair `(first, later)` with the earliest `later` (then earliest `first`)
/// in list order. A sweep along x avoids comparing every pair of a large hall.
fn first_overlap(boxes: &[Aabb]) -> Option<(usize, usize)> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| boxes[a].min[0].total_cmp(&boxes[b].min[0]));
    let mut best: Option<(usize, usize)> = None;
    for (n, &i) in order.iter().enumerate() {
        for &j in &order[n + 1..] {
            if boxes[j].min[0] >= boxes[i].max[0] - GEOMETRY_TOL_M {
                break;
            }
            if boxes[i].overlaps(&boxes[j], GEOMETRY_TOL_M) {
                let pair = (i.min(j), i.max(j));
                if best.is_none_or(|(f, l)| (pair.1, pair.0) < (l, f)) {
                    best = Some(pair);
                }
            }
        }
    }
    best
}

struct Checker<'a> {
    file: &'a str,
}

impl Checker<'_> {
    fn err(&self, field: impl Into<String>, message: impl Into<String>) -> Error {
        Error::format(self.file, field, message)
    }

    fn finite(&self, v: f64, pointer: &str) -> Result<()> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(self.err(
                pointer,
                format!("expected a finite number, found {}", number(v)),
            ))
        }
    }

    fn positive(&self, v: f64, pointer: &str, what: &str) -> Result<()> {
        self.finite(v, pointer)?;
        if v > 0.0 {
            Ok(())
        } else {
            Err(self.err(
                pointer,
                format!("expected a positive {what}, found {}", number(v)),
            ))
        }
    }

    /// A room-aligned box given by its minimum corner and size (2-D footprints or 3-D
    /// boxes): finite, positive size, inside the room within the tolerance.
    fn check_box(&self, pointer: &str, pos: &[f64], size: &[f64], room: &[f64]) -> Result<()> {
        for (a, (&p, &s)) in pos.iter().zip(size).enumerate() {
            self.finite(p, &format!("{pointer}/position_m/{a}"))?;
            self.positive(s, &format!("{pointer}/size_m/{a}"), "size")?;
        }
        for (a, ((&p, &s), &r)) in pos.iter().zip(size).zip(room).enumerate() {
            if p < -GEOMETRY_TOL_M {
                return Err(self.err(
                    format!("{pointer}/position_m/{a}"),
                    format!(
                        "box starts at {} = {} m, outside the room; expected >= 0",
                        AXES[a],
                        number(p)
                    ),
                ));
            }
            if p + s > r + GEOMETRY_TOL_M {
                return Err(self.err(
                    format!("{pointer}/position_m/{a}"),
                    format!(
                        "box reaches {} = {} m, outside the room; expected position + size <= {} m",
                        AXES[a],
                        number(p + s),
                        number(r)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Non-empty ids, unique within the list.
    fn unique_ids<'b>(&self, ids: impl Iterator<Item = (&'b str, String)>) -> Result<()> {
        let mut seen: HashMap<&str, String> = HashMap::new();
        for (id, pointer) in ids {
            if id.is_empty() {
                return Err(self.err(pointer, "expected a non-empty id"));
            }
            if let Some(why) = unprintable_name(id) {
                return Err(self.err(pointer, format!("id {why}")));
            }
            if let Some(first) = seen.get(id) {
                return Err(self.err(
                    pointer,
                    format!("duplicate id `{id}` (first at {first}); expected unique ids"),
                ));
            }
            seen.insert(id, pointer);
        }
        Ok(())
    }
}
