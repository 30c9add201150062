//! Modifications: what effects ask of one simulator run.
//!
//! An [`crate::effects::Effect`] turns its parameter values into entries of [`SimMods`];
//! the simulator resolves them onto its grid for that run only. Entries are in hall terms
//! (indices into the hall's lists, boxes in metres), so effects never see the grid.

use crate::hall::Aabb;

/// A side of a containment box whose panels may be opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WallSide {
    /// The panel at the box's minimum x (an aisle end, for rows along x).
    MinusX,
    /// The panel at the box's maximum x.
    PlusX,
    /// The panel at the box's minimum y.
    MinusY,
    /// The panel at the box's maximum y.
    PlusY,
    /// The ceiling panel (only when the box stops below the room ceiling).
    Top,
}

impl WallSide {
    /// All five sides.
    pub const ALL: [WallSide; 5] = [
        WallSide::MinusX,
        WallSide::PlusX,
        WallSide::MinusY,
        WallSide::PlusY,
        WallSide::Top,
    ];

    /// Name used in `hall.json` (`-x`, `+x`, `-y`, `+y`, `top`).
    pub fn as_str(self) -> &'static str {
        match self {
            WallSide::MinusX => "-x",
            WallSide::PlusX => "+x",
            WallSide::MinusY => "-y",
            WallSide::PlusY => "+y",
            WallSide::Top => "top",
        }
    }

    /// Parses a name of [`Self::as_str`].
    pub fn parse(s: &str) -> Option<WallSide> {
        WallSide::ALL.into_iter().find(|w| w.as_str() == s)
    }
}

/// Part of a rack's exhaust flows back to its intake through the rack (missing blanking
/// panels), carrying the exhaust-side air temperature.
#[derive(Debug, Clone, PartialEq)]
pub struct RackRecirculation {
    /// Index of the rack in `hall.racks`.
    pub rack: usize,
    /// Recirculated flow as a fraction of the rack's total server flow.
    pub fraction: f64,
    /// Height band `[z0, z1]` (m) of the gap; the whole rack height when `None`.
    pub z_m: Option<[f64; 2]>,
}

/// An extra supply opening (e.g. a cable cut-out) delivering a share of every CRAC's flow
/// at that CRAC's supply temperature; the CRAC's regular outlets deliver the rest.
#[derive(Debug, Clone, PartialEq)]
pub struct SupplyOpening {
    /// The opening: cells whose centres lie in the box (a box thinner than a cell takes
    /// the cell layer containing it, e.g. `z = 0..0` is the floor layer).
    pub region: Aabb,
    /// Share of the supply flow, in `[0, 1)`.
    pub share: f64,
}

/// Containment panels opened with a fraction of the open-face conductance: the flow
/// through them follows the pressure difference.
#[derive(Debug, Clone, PartialEq)]
pub struct WallOpening {
    /// Index of the containment in `hall.containment`.
    pub containment: usize,
    /// The sides opened.
    pub sides: Vec<WallSide>,
    /// Open fraction of the panel area, in `[0, 1]`.
    pub open_fraction: f64,
}

/// A forced air path: takes `flow_m3_s` from the cells of `from` (evenly) and releases it,
/// at the mixed temperature it took, in the cells of `to`.
#[derive(Debug, Clone, PartialEq)]
pub struct AirLink {
    /// Where the air is taken.
    pub from: Aabb,
    /// Where it is released.
    pub to: Aabb,
    /// Volume flow (m3/s), `>= 0`.
    pub flow_m3_s: f64,
}

/// Everything the effects of one run change, in hall terms.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimMods {
    /// Supply temperature offset (C) per CRAC, hall order; empty means all zero.
    pub supply_offset_c: Vec<f64>,
    /// In-rack recirculation paths.
    pub rack_recirculation: Vec<RackRecirculation>,
    /// Extra supply openings.
    pub supply_openings: Vec<SupplyOpening>,
    /// Opened containment panels.
    pub wall_openings: Vec<WallOpening>,
    /// Forced air paths.
    pub air_links: Vec<AirLink>,
}

impl SimMods {
    /// The share of the supply the extra openings take (the tiles and CRAC fronts
    /// deliver the rest).
    pub fn supply_opening_share(&self) -> f64 {
        self.supply_openings.iter().map(|o| o.share).sum()
    }

    /// No modification, for a hall with `cracs` CRACs.
    pub fn new(cracs: usize) -> Self {
        SimMods {
            supply_offset_c: vec![0.0; cracs],
            ..Default::default()
        }
    }
}
