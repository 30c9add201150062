//! Where the effects act, checked against the grid before any run.
//!
//! A run resolves its [`SimMods`] onto the grid, and a region that covers no open cell
//! (a recirculation band thinner than a cell at a cell boundary, an opening inside a
//! rack) fails that run. It fails every run that gives the effect a value and succeeds,
//! acting nowhere, at zero: a calibration would then learn from the zero-valued runs
//! only. [`Simulator::check_placements`] finds such a region once, up front.

use super::mods::SimMods;
use super::Simulator;
use crate::hall::Aabb;
use crate::snapshots::number;
use crate::Error;
use crate::Result;

impl Simulator {
    /// Checks that every region `mods` names covers at least one open cell, whatever the
    /// flows and shares: each supply opening, both faces of each rack recirculation band,
    /// both ends of each air link, and each opened containment. The error
    /// ([`Error::Geometry`]) names the first region that does not and the cell size.
    ///
    /// ```
    /// use kalibre_dc::sim::{RackRecirculation, SimConfig, SimMods, Simulator};
    /// use kalibre_dc::synth::{generate, Preset, SynthOptions};
    ///
    /// let hall = generate(&SynthOptions::new(Preset::Demo, 1)).unwrap().hall;
    /// let sim = Simulator::new(&hall, SimConfig::default().with_cell_m(0.2)).unwrap();
    /// let mut mods = SimMods::new(hall.cracs.len());
    /// mods.rack_recirculation.push(RackRecirculation { rack: 0, fraction: 0.1, z_m: None });
    /// assert!(sim.check_placements(&mods).is_ok());
    /// // A band one micrometre high, on the boundary of two 0.2 m cells, holds no cell.
    /// mods.rack_recirculation[0].z_m = Some([1.0, 1.000001]);
    /// assert!(sim.check_placements(&mods).is_err());
    /// ```
    pub fn check_placements(&self, mods: &SimMods) -> Result<()> {
        let topo = self.topo();
        let hall = self.hall();
        let cells = self.grid().cell_m_text();
        let nowhere = |what: String| {
            Error::Geometry(format!(
                "{what} covers no open cell on cells of {cells} m: make it at least a cell \
                 across, or use finer cells (`--grid-m`)"
            ))
        };
        for (j, o) in mods.supply_openings.iter().enumerate() {
            if topo.box_stencil(&o.region).is_none() {
                return Err(nowhere(format!(
                    "supply opening {j} ({})",
                    box_text(&o.region)
                )));
            }
        }
        for rr in &mods.rack_recirculation {
            let r = hall.racks.get(rr.rack).ok_or_else(|| {
                Error::Geometry(format!("rack recirculation: no rack index {}", rr.rack))
            })?;
            let band = match rr.z_m {
                Some([z0, z1]) => format!(" in z {}-{} m", number(z0), number(z1)),
                None => String::new(),
            };
            for side in [r.inlet.opposite(), r.inlet] {
                if topo.rack_face(hall, rr.rack, side, rr.z_m).is_none() {
                    let face = if side == r.inlet { "intake" } else { "exhaust" };
                    return Err(nowhere(format!(
                        "rack `{}`'s recirculation{band}, at its {face} face,",
                        r.id
                    )));
                }
            }
        }
        for (j, l) in mods.air_links.iter().enumerate() {
            for (end, region) in [("from", &l.from), ("to", &l.to)] {
                if topo.box_stencil(region).is_none() {
                    return Err(nowhere(format!(
                        "air link {j}'s `{end}` box ({})",
                        box_text(region)
                    )));
                }
            }
        }
        for o in &mods.wall_openings {
            if topo.walls.get(o.containment).is_none() {
                return Err(Error::Geometry(format!(
                    "wall opening: no containment index {}",
                    o.containment
                )));
            }
        }
        Ok(())
    }
}

/// `x0-x1 x y0-y1 x z0-z1 m`.
fn box_text(b: &Aabb) -> String {
    let axis = |a: usize| format!("{}-{}", number(b.min[a]), number(b.max[a]));
    format!("{} x {} x {} m", axis(0), axis(1), axis(2))
}
