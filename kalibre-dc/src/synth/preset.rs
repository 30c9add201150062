//! The presets (`demo`, `hall-a`, `hall-b`) and the layout figures each stands for.

use std::fmt;
use std::str::FromStr;

use crate::{Error, Result};

/// A synthetic hall preset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Preset {
    /// About 300 servers in two rows, 4 CRACs, 24 sensors, a 12 x 8.4 x 3 m room.
    #[default]
    Demo,
    /// 2,240 servers in 10 rows with hot-aisle containment, 10 CRACs, 60 sensors, 9-11
    /// server types (the size of the paper's hall A).
    HallA,
    /// 2,560 servers in 8 rows with hot-aisle containment, 8 CRACs, 64 sensors, 8-12
    /// server types.
    HallB,
}

impl Preset {
    /// The CLI name: `demo`, `hall-a` or `hall-b`.
    pub fn as_str(self) -> &'static str {
        match self {
            Preset::Demo => "demo",
            Preset::HallA => "hall-a",
            Preset::HallB => "hall-b",
        }
    }

    /// The layout figures of the preset.
    pub(crate) fn layout(self) -> LayoutSpec {
        match self {
            Preset::Demo => LayoutSpec {
                row_pairs: 1,
                racks_per_row: 12,
                servers: 300,
                cracs: 4,
                cold_sensors_per_row: 8,
                hot_sensors_per_row: 4,
                types: (4, 5),
                outer_cold_m: 2.4,
                inner_cold_m: 1.8,
                end_clearance_m: 1.4,
            },
            Preset::HallA => LayoutSpec {
                row_pairs: 5,
                racks_per_row: 16,
                servers: 2240,
                cracs: 10,
                cold_sensors_per_row: 4,
                hot_sensors_per_row: 2,
                types: (9, 11),
                outer_cold_m: 1.8,
                inner_cold_m: 1.8,
                end_clearance_m: 1.8,
            },
            Preset::HallB => LayoutSpec {
                row_pairs: 4,
                racks_per_row: 20,
                servers: 2560,
                cracs: 8,
                cold_sensors_per_row: 5,
                hot_sensors_per_row: 3,
                types: (8, 12),
                outer_cold_m: 1.8,
                inner_cold_m: 2.4,
                end_clearance_m: 1.8,
            },
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Preset {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "demo" => Ok(Preset::Demo),
            "hall-a" => Ok(Preset::HallA),
            "hall-b" => Ok(Preset::HallB),
            other => Err(Error::Mismatch(format!(
                "unknown preset `{other}` (expected demo, hall-a or hall-b)"
            ))),
        }
    }
}

/// Layout figures: rows come in pairs around a hot aisle; CRACs stand at both ends of the
/// rows; all sizes are multiples of 0.2 m so that grids of 0.2 m and 0.1 m align.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LayoutSpec {
    /// Pairs of rows (each pair back to back around one hot aisle).
    pub row_pairs: usize,
    /// Racks per row.
    pub racks_per_row: usize,
    /// Server entries in the hall.
    pub servers: usize,
    /// CRACs, split between the two end walls.
    pub cracs: usize,
    /// Cold-aisle sensors per row.
    pub cold_sensors_per_row: usize,
    /// Hot-aisle sensors per row.
    pub hot_sensors_per_row: usize,
    /// Inclusive range of the number of server types.
    pub types: (usize, usize),
    /// Width of the cold aisles along the side walls (m).
    pub outer_cold_m: f64,
    /// Width of the cold aisles between pairs (m).
    pub inner_cold_m: f64,
    /// Free floor between a CRAC and the row ends (m).
    pub end_clearance_m: f64,
}
