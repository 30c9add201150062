//! Legacy VTK output (structured points, cell data) that ParaView opens.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::{Simulator, Solution};
use crate::{Error, Result};

/// The file [`write_vtk`] writes a snapshot's fields to: its label with every character
/// but ASCII letters, digits, `-` and `_` replaced by `_` (no path can escape the
/// directory), then `.vtk`. Two labels can map to one name (`a/b`, `a_b`).
///
/// ```
/// assert_eq!(kalibre_dc::sim::vtk_file_name("../t 0"), "___t_0.vtk");
/// ```
pub fn vtk_file_name(label: &str) -> String {
    let name: String = label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if name.is_empty() {
        "solution.vtk".to_string()
    } else {
        format!("{name}.vtk")
    }
}

/// Writes `<dir>/<label>.vtk` ([`vtk_file_name`]) with cell data `temperature_c` (solid
/// cells as NaN), `pressure`, `solid` and the vector `velocity_m_s`; returns the path.
pub fn write_vtk(dir: impl AsRef<Path>, sim: &Simulator, sol: &Solution) -> Result<PathBuf> {
    let dir = dir.as_ref();
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let path = dir.join(vtk_file_name(&sol.label));
    let g = sim.grid();
    let mut s = String::with_capacity(g.len() * 64);
    s.push_str("# vtk DataFile Version 3.0\n");
    s.push_str(&format!(
        "kalibre hall {} state {}\nASCII\nDATASET STRUCTURED_POINTS\n",
        sim.hall().name,
        sol.label
    ));
    s.push_str(&format!(
        "DIMENSIONS {} {} {}\n",
        g.n[0] + 1,
        g.n[1] + 1,
        g.n[2] + 1
    ));
    s.push_str("ORIGIN 0 0 0\n");
    s.push_str(&format!("SPACING {} {} {}\n", g.d[0], g.d[1], g.d[2]));
    s.push_str(&format!("CELL_DATA {}\n", g.len()));
    s.push_str("SCALARS temperature_c double 1\nLOOKUP_TABLE default\n");
    for t in &sol.temperature_c {
        s.push_str(&if t.is_finite() {
            format!("{t:.4}\n")
        } else {
            "nan\n".to_string()
        });
    }
    s.push_str("SCALARS pressure double 1\nLOOKUP_TABLE default\n");
    for p in &sol.pressure {
        s.push_str(&format!("{p:.6e}\n"));
    }
    s.push_str("SCALARS solid int 1\nLOOKUP_TABLE default\n");
    for f in sim.solid() {
        s.push_str(if *f { "1\n" } else { "0\n" });
    }
    s.push_str("VECTORS velocity_m_s double\n");
    for v in sol.velocity_m_s(g) {
        s.push_str(&format!("{:.5e} {:.5e} {:.5e}\n", v[0], v[1], v[2]));
    }
    let mut f = std::fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
    f.write_all(s.as_bytes()).map_err(|e| Error::io(&path, e))?;
    Ok(path)
}
