//! The hall description (`hall.json`, `kalibre.hall/1`) as Rust types.
//!
//! Field names follow `formats.md` exactly; unknown fields are rejected except under
//! `extra`. Loading ([`super::Hall::load`]) also enforces the geometric rules.

use serde::{Deserialize, Serialize};

/// The schema tag of `hall.json`.
pub const HALL_SCHEMA: &str = "kalibre.hall/1";

/// A data hall: geometry, equipment, sensors, and what calibration may change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hall {
    /// Always `kalibre.hall/1`.
    pub schema: String,
    /// Hall name.
    pub name: String,
    /// The room box.
    pub room: Room,
    /// Server types, each with its alpha bounds.
    pub server_types: Vec<ServerType>,
    /// Cooling units.
    pub cracs: Vec<Crac>,
    /// Perforated floor tiles (raised-floor supply).
    #[serde(default)]
    pub tiles: Vec<Tile>,
    /// Ceiling return grilles.
    #[serde(default)]
    pub returns: Vec<ReturnGrille>,
    /// Racks with their servers.
    pub racks: Vec<Rack>,
    /// Aisle containment boxes.
    #[serde(default)]
    pub containment: Vec<Containment>,
    /// Temperature sensors.
    pub sensors: Vec<Sensor>,
    /// What calibration may change.
    #[serde(default)]
    pub calibrate: CalibrateSpec,
    /// Model extensions (physical effects), each with its own parameters.
    #[serde(default)]
    pub effects: Vec<EffectSpec>,
    /// Free-form data for other tools.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// The room: a box from the origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Room {
    /// Size along x, y, z (m).
    pub size_m: [f64; 3],
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// A server type with its air flow rate bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServerType {
    /// Unique id.
    pub id: String,
    /// Air flow rate per watt (cfm/W): initial guess and bounds.
    pub alpha_cfm_per_w: AlphaBounds,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// `0 < min <= initial <= max`, in cfm/W.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlphaBounds {
    /// Initial value.
    pub initial: f64,
    /// Lower bound.
    pub min: f64,
    /// Upper bound.
    pub max: f64,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// How a CRAC delivers its supply air.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SupplyKind {
    /// Through the hall's tiles from a raised-floor plenum.
    Floor,
    /// The CRAC's face blows into the room (on the side facing the room's interior).
    Front,
}

/// A computer-room air conditioner: a solid box.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Crac {
    /// Unique id.
    pub id: String,
    /// Minimum corner (m).
    pub position_m: [f64; 3],
    /// Size (m).
    pub size_m: [f64; 3],
    /// Flow at fan speed 1 (m3/s).
    pub rated_flow_m3_s: f64,
    /// Supply path.
    pub supply: SupplyKind,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// A perforated floor tile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tile {
    /// Minimum corner x, y (m), on the floor.
    pub position_m: [f64; 2],
    /// Size x, y (m).
    pub size_m: [f64; 2],
    /// Open area fraction in (0, 1]; shares supply flow with area.
    pub open_fraction: f64,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

impl Tile {
    /// Open area (m2): the tiles share the floor supply in proportion to it.
    pub fn open_area_m2(&self) -> f64 {
        self.size_m[0] * self.size_m[1] * self.open_fraction
    }
}

/// A ceiling return grille.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReturnGrille {
    /// Minimum corner x, y (m), at the ceiling.
    pub position_m: [f64; 2],
    /// Size x, y (m).
    pub size_m: [f64; 2],
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// A side of a rack, as the direction of its outward normal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Side {
    /// +x.
    #[serde(rename = "+x")]
    PlusX,
    /// -x.
    #[serde(rename = "-x")]
    MinusX,
    /// +y.
    #[serde(rename = "+y")]
    PlusY,
    /// -y.
    #[serde(rename = "-y")]
    MinusY,
}

impl Side {
    /// The opposite side.
    pub fn opposite(self) -> Side {
        match self {
            Side::PlusX => Side::MinusX,
            Side::MinusX => Side::PlusX,
            Side::PlusY => Side::MinusY,
            Side::MinusY => Side::PlusY,
        }
    }

    /// Name used in `hall.json` (`+x`, `-x`, `+y`, `-y`).
    pub fn as_str(self) -> &'static str {
        match self {
            Side::PlusX => "+x",
            Side::MinusX => "-x",
            Side::PlusY => "+y",
            Side::MinusY => "-y",
        }
    }

    /// Axis index (0 = x, 1 = y) and sign (+1.0 or -1.0) of the outward normal.
    pub fn axis_sign(self) -> (usize, f64) {
        match self {
            Side::PlusX => (0, 1.0),
            Side::MinusX => (0, -1.0),
            Side::PlusY => (1, 1.0),
            Side::MinusY => (1, -1.0),
        }
    }
}

/// A rack: a solid box whose servers draw air on the `inlet` side and exhaust on the opposite.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rack {
    /// Unique id.
    pub id: String,
    /// Minimum corner (m).
    pub position_m: [f64; 3],
    /// Size (m).
    pub size_m: [f64; 3],
    /// The side that draws air.
    pub inlet: Side,
    /// Number of rack units dividing its height evenly.
    #[serde(deserialize_with = "whole_u32")]
    pub units: u32,
    /// Servers, each occupying `u .. u + height_u - 1`.
    pub servers: Vec<Server>,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// A server (or a group of servers with one power reading).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Server {
    /// Unique id (across the hall).
    pub id: String,
    /// Server type id.
    #[serde(rename = "type")]
    pub server_type: String,
    /// Lowest unit, from 1.
    #[serde(deserialize_with = "whole_u32")]
    pub u: u32,
    /// Units occupied.
    #[serde(deserialize_with = "whole_u32")]
    pub height_u: u32,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// Kind of aisle containment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContainmentKind {
    /// Encloses a hot aisle.
    HotAisle,
    /// Encloses a cold aisle.
    ColdAisle,
}

/// An aisle containment box: its faces not covered by racks are walls (panels and doors),
/// its top is a ceiling panel unless it reaches the room ceiling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Containment {
    /// Hot or cold aisle.
    pub kind: ContainmentKind,
    /// Minimum corner (m).
    pub min_m: [f64; 3],
    /// Maximum corner (m).
    pub max_m: [f64; 3],
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// The aisle a sensor is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Aisle {
    /// Cold aisle (server intakes).
    Cold,
    /// Hot aisle (server exhausts).
    Hot,
}

impl Aisle {
    /// `cold` or `hot`.
    pub fn as_str(self) -> &'static str {
        match self {
            Aisle::Cold => "cold",
            Aisle::Hot => "hot",
        }
    }
}

/// A temperature sensor at a point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sensor {
    /// Unique id.
    pub id: String,
    /// Position (m).
    pub position_m: [f64; 3],
    /// Aisle.
    pub aisle: Aisle,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// How server air flow rates are calibrated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum AlphaMode {
    /// One alpha per server type (default).
    #[default]
    PerType,
    /// One alpha per server (the paper's formulation).
    PerServer,
    /// Alpha is not calibrated.
    Fixed,
}

/// The `calibrate` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct CalibrateSpec {
    /// How alpha is calibrated.
    #[serde(default)]
    pub alpha: AlphaMode,
    /// Free-form data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra: Option<serde_json::Value>,
}

/// One `effects` entry: a `kind` and that kind's fields, interpreted by the effect registry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectSpec {
    /// Effect kind, e.g. `bypass`.
    pub kind: String,
    /// The kind's own fields.
    #[serde(flatten)]
    pub fields: serde_json::Map<String, serde_json::Value>,
}

/// `v` as a count when it is a whole number in `u32`'s range (`42.0`, `-0.0`), else
/// `None`: how `hall.json` reads a count written as a float.
pub(crate) fn whole_count(v: f64) -> Option<u32> {
    (v.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(&v)).then_some(v as u32)
}

/// A count in `hall.json`: an integer, or a number with no fractional part (`42.0`,
/// `4.2e1`). JSON has one number type, and exporters that write every number as a float
/// (Python, pandas columns) mean the same count; `42.5` or `-1` is refused.
fn whole_u32<'de, D: serde::Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    use serde::de::{Error, Unexpected, Visitor};
    struct Whole;
    impl Visitor<'_> for Whole {
        type Value = u32;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(f, "a whole number in [0, {}]", u32::MAX)
        }
        fn visit_u64<E: Error>(self, v: u64) -> Result<u32, E> {
            u32::try_from(v).map_err(|_| E::invalid_value(Unexpected::Unsigned(v), &self))
        }
        fn visit_i64<E: Error>(self, v: i64) -> Result<u32, E> {
            u32::try_from(v).map_err(|_| E::invalid_value(Unexpected::Signed(v), &self))
        }
        fn visit_f64<E: Error>(self, v: f64) -> Result<u32, E> {
            whole_count(v).ok_or_else(|| E::invalid_value(Unexpected::Float(v), &self))
        }
    }
    d.deserialize_any(Whole)
}
