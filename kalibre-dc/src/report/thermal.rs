//! A thermal plane: a horizontal slice of the simulator's temperature field (e.g. at
//! inlet height), drawn as an SVG heat map with the racks outlined and a legend.

use std::fmt::Write;

use serde::{Deserialize, Serialize};

use super::svg::{esc, fmt_tick, ticks};
use crate::hall::Hall;
use crate::sim::{Simulator, Solution};
use crate::{Error, Result};

/// Inlet height of the thermal planes in reports (m): the middle of a 42U rack.
pub const INLET_HEIGHT_M: f64 = 1.2;

/// Temperatures of one horizontal layer of grid cells (C; NaN in solid cells).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThermalPlane {
    /// What the plane shows (e.g. "before calibration, snapshot t0").
    pub title: String,
    /// Cells along x and y.
    pub n: [usize; 2],
    /// Cell size along x and y (m).
    pub d_m: [f64; 2],
    /// Height of the cell centres (m).
    pub z_m: f64,
    /// Temperature per cell (C), x fastest; NaN where the cell is solid.
    pub temperature_c: Vec<f64>,
}

impl ThermalPlane {
    /// The layer of cells containing height `z_m` of a solved field.
    pub fn from_solution(
        sim: &Simulator,
        solution: &Solution,
        z_m: f64,
        title: impl Into<String>,
    ) -> Result<Self> {
        let grid = sim.grid();
        let height = grid.d[2] * grid.n[2] as f64;
        if !(z_m.is_finite() && (0.0..=height).contains(&z_m)) {
            return Err(Error::Mismatch(format!(
                "thermal plane: z = {z_m} m lies outside the room (0 to {height} m)"
            )));
        }
        if solution.temperature_c.len() != grid.len() {
            return Err(Error::Mismatch(format!(
                "thermal plane: the solution has {} cells, the grid {}",
                solution.temperature_c.len(),
                grid.len()
            )));
        }
        // The layer containing z; a z on a face (1.2 m on a 0.2 m grid) takes the layer
        // above, whatever the rounding of z / dz.
        let k = grid.cell_of(2, z_m + 1e-9 * grid.d[2]);
        let solid = sim.solid();
        let mut temperature_c = Vec::with_capacity(grid.n[0] * grid.n[1]);
        for j in 0..grid.n[1] {
            for i in 0..grid.n[0] {
                let c = grid.idx(i, j, k);
                temperature_c.push(if solid[c] {
                    f64::NAN
                } else {
                    solution.temperature_c[c]
                });
            }
        }
        Ok(ThermalPlane {
            title: title.into(),
            n: [grid.n[0], grid.n[1]],
            d_m: [grid.d[0], grid.d[1]],
            z_m: grid.centre(2, k),
            temperature_c,
        })
    }

    /// Lowest and highest finite temperature (None when every cell is solid).
    pub fn range_c(&self) -> Option<(f64, f64)> {
        let finite = self.temperature_c.iter().filter(|v| v.is_finite());
        let lo = finite.clone().cloned().fold(f64::INFINITY, f64::min);
        let hi = finite.cloned().fold(f64::NEG_INFINITY, f64::max);
        (lo <= hi).then_some((lo, hi))
    }
}

/// A sequential colour scale over `[lo_c, hi_c]` (blue, pale yellow, red).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourScale {
    /// Temperature of the coldest colour (C).
    pub lo_c: f64,
    /// Temperature of the hottest colour (C).
    pub hi_c: f64,
}

/// Colour stops of the scale (ColorBrewer RdYlBu, reversed): readable in grey-scale
/// print and for the common colour-vision deficiencies.
const STOPS: [(f64, f64, f64); 5] = [
    (49.0, 54.0, 149.0),
    (116.0, 173.0, 209.0),
    (255.0, 255.0, 191.0),
    (244.0, 109.0, 67.0),
    (165.0, 0.0, 38.0),
];

impl ColourScale {
    /// The scale spanning every finite value of the planes, widened outwards to whole
    /// half-degrees so that the legend's ends are round; one shared scale lets planes
    /// be compared by colour. None when no plane has a finite value.
    pub fn spanning(planes: &[&ThermalPlane]) -> Option<Self> {
        let (lo, hi) = planes.iter().filter_map(|p| p.range_c()).fold(
            None,
            |acc: Option<(f64, f64)>, (a, b)| {
                Some(acc.map_or((a, b), |(x, y)| (x.min(a), y.max(b))))
            },
        )?;
        let lo_c = (lo * 2.0).floor() / 2.0;
        let mut hi_c = (hi * 2.0).ceil() / 2.0;
        if hi_c <= lo_c {
            hi_c = lo_c + 0.5;
        }
        Some(ColourScale { lo_c, hi_c })
    }

    /// Position of `t` on the scale, clamped to `[0, 1]`.
    pub fn fraction(&self, t: f64) -> f64 {
        ((t - self.lo_c) / (self.hi_c - self.lo_c)).clamp(0.0, 1.0)
    }

    /// The colour of temperature `t` (`rgb(...)`); values outside the scale take the
    /// end colours, NaN is grey.
    pub fn colour(&self, t: f64) -> String {
        if !t.is_finite() {
            return "rgb(190,190,190)".into();
        }
        let f = self.fraction(t) * (STOPS.len() - 1) as f64;
        let i = (f.floor() as usize).min(STOPS.len() - 2);
        let w = f - i as f64;
        let (a, b) = (STOPS[i], STOPS[i + 1]);
        format!(
            "rgb({:.0},{:.0},{:.0})",
            a.0 + w * (b.0 - a.0),
            a.1 + w * (b.1 - a.1),
            a.2 + w * (b.2 - a.2)
        )
    }
}

/// A sensor marker on a plane: position (m) and the value to colour it by (C).
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Label (sensor id).
    pub label: String,
    /// Plan position (m).
    pub position_m: [f64; 2],
    /// The measured temperature (C).
    pub value_c: f64,
}

/// Colours are quantised to this many levels so that runs of equal colour along a row
/// merge into one rectangle (a tenth of the file size, no visible difference).
const LEVELS: f64 = 64.0;

/// The SVG of a plane: cells coloured by `scale`, solid cells grey, racks outlined,
/// `markers` (measured sensors) drawn as circles in the same colours, and a legend.
pub fn thermal_svg(
    hall: &Hall,
    plane: &ThermalPlane,
    scale: &ColourScale,
    markers: &[Marker],
) -> String {
    let [lx, ly] = [
        plane.d_m[0] * plane.n[0] as f64,
        plane.d_m[1] * plane.n[1] as f64,
    ];
    let width = 520.0;
    let k = (width - 20.0) / lx.max(1e-9);
    let height = ly * k + 74.0;
    let x = |v: f64| 10.0 + v * k;
    let y = |v: f64| 10.0 + (ly - v) * k;
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height:.0}" width="100%" style="max-width:{width}px" font-family="sans-serif" shape-rendering="crispEdges">"#
    );
    let _ = write!(
        s,
        "<title>{} (z = {:.2} m)</title>",
        esc(&plane.title),
        plane.z_m
    );
    let level = |t: f64| -> Option<i64> {
        t.is_finite()
            .then(|| (scale.fraction(t) * LEVELS).round() as i64)
    };
    for j in 0..plane.n[1] {
        let row = &plane.temperature_c[j * plane.n[0]..(j + 1) * plane.n[0]];
        let mut i = 0;
        while i < row.len() {
            let l = level(row[i]);
            let mut end = i + 1;
            while end < row.len() && level(row[end]) == l {
                end += 1;
            }
            let colour = match l {
                Some(l) => scale.colour(scale.lo_c + (scale.hi_c - scale.lo_c) * l as f64 / LEVELS),
                None => "rgb(190,190,190)".into(),
            };
            let _ = write!(
                s,
                r#"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" fill="{colour}"/>"#,
                x(i as f64 * plane.d_m[0]),
                y((j + 1) as f64 * plane.d_m[1]),
                (end - i) as f64 * plane.d_m[0] * k,
                plane.d_m[1] * k
            );
            i = end;
        }
    }
    let _ = write!(
        s,
        r##"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#333"/>"##,
        x(0.0),
        y(ly),
        lx * k,
        ly * k
    );
    for r in &hall.racks {
        let _ = write!(
            s,
            r##"<rect class="rack" x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#111" stroke-width="1.2"><title>rack {}</title></rect>"##,
            x(r.position_m[0]),
            y(r.position_m[1] + r.size_m[1]),
            r.size_m[0] * k,
            r.size_m[1] * k,
            esc(&r.id)
        );
    }
    for c in &hall.cracs {
        let _ = write!(
            s,
            r##"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#1e3a8a" stroke-width="1.5"><title>CRAC {}</title></rect>"##,
            x(c.position_m[0]),
            y(c.position_m[1] + c.size_m[1]),
            c.size_m[0] * k,
            c.size_m[1] * k,
            esc(&c.id)
        );
    }
    for m in markers {
        let _ = write!(
            s,
            r##"<circle cx="{:.1}" cy="{:.1}" r="4.5" fill="{}" stroke="#000"><title>{}: measured {:.2} C</title></circle>"##,
            x(m.position_m[0]),
            y(m.position_m[1]),
            scale.colour(m.value_c),
            esc(&m.label),
            m.value_c
        );
    }
    // Legend: the colour bar with ticks in C.
    let (bx, by, bw) = (20.0, ly * k + 22.0, 260.0);
    for i in 0..52 {
        let f = (i as f64 + 0.5) / 52.0;
        let _ = write!(
            s,
            r#"<rect x="{:.1}" y="{by:.1}" width="{:.2}" height="10" fill="{}"/>"#,
            bx + bw * i as f64 / 52.0,
            bw / 52.0 + 0.3,
            scale.colour(scale.lo_c + f * (scale.hi_c - scale.lo_c))
        );
    }
    // The scale's ends, and round ticks between them not crowding the ends.
    let span = scale.hi_c - scale.lo_c;
    let mut marks = vec![scale.lo_c, scale.hi_c];
    marks.extend(
        ticks(scale.lo_c, scale.hi_c, 4)
            .into_iter()
            .filter(|t| (t - scale.lo_c).min(scale.hi_c - t) > 0.12 * span),
    );
    for t in marks {
        let px = bx + bw * scale.fraction(t);
        let _ = write!(
            s,
            r##"<line x1="{px:.1}" y1="{:.1}" x2="{px:.1}" y2="{:.1}" stroke="#333"/><text class="tick" x="{px:.1}" y="{:.1}" font-size="11" text-anchor="middle">{}</text>"##,
            by + 10.0,
            by + 13.0,
            by + 24.0,
            fmt_tick(t)
        );
    }
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" font-size="11">C at z = {:.2} m</text><text x="{bx:.1}" y="{:.1}" font-size="11">grey: racks and CRACs; circles: sensors, filled with the measured temperature</text>"#,
        bx + bw + 12.0,
        by + 9.0,
        plane.z_m,
        by + 40.0
    );
    s.push_str("</svg>");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(values: Vec<f64>, n: [usize; 2]) -> ThermalPlane {
        ThermalPlane {
            title: "t".into(),
            n,
            d_m: [1.0, 1.0],
            z_m: 1.2,
            temperature_c: values,
        }
    }

    #[test]
    fn shared_scale_spans_both_planes_and_ignores_solid_cells() {
        let a = plane(vec![18.3, f64::NAN, 24.1, 20.0], [2, 2]);
        let b = plane(vec![f64::NAN, 31.2, 19.0, 17.9], [2, 2]);
        let s = ColourScale::spanning(&[&a, &b]).unwrap();
        assert_eq!((s.lo_c, s.hi_c), (17.5, 31.5));
        // The ends take the end colours; beyond them, clamped.
        assert_eq!(s.colour(17.5), "rgb(49,54,149)");
        assert_eq!(s.colour(31.5), "rgb(165,0,38)");
        assert_eq!(s.colour(-40.0), s.colour(17.5));
        assert_eq!(s.colour(99.0), s.colour(31.5));
        assert_eq!(s.colour((17.5 + 31.5) / 2.0), "rgb(255,255,191)");
        assert_eq!(s.colour(f64::NAN), "rgb(190,190,190)");
        // Cold quarter bluish, warm quarter reddish, and no jumps between neighbouring values.
        let rgb = |t: f64| -> Vec<f64> {
            let c = s.colour(t);
            c[4..c.len() - 1]
                .split(',')
                .map(|x| x.parse().unwrap())
                .collect()
        };
        for i in 0..=140 {
            let t = 17.5 + 0.1 * i as f64;
            let (c, next) = (rgb(t), rgb(t + 0.1));
            if t < 21.0 {
                assert!(c[2] > c[0], "{t} C is not bluish: {c:?}");
            } else if t > 28.0 {
                assert!(c[0] > c[2], "{t} C is not reddish: {c:?}");
            }
            let jump = c
                .iter()
                .zip(&next)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(jump <= 16.0, "colour jumps by {jump} at {t} C");
        }
        // All solid: no scale; a uniform field still gets a non-empty one.
        assert!(ColourScale::spanning(&[&plane(vec![f64::NAN; 4], [2, 2])]).is_none());
        let flat = ColourScale::spanning(&[&plane(vec![20.0; 4], [2, 2])]).unwrap();
        assert!(flat.hi_c > flat.lo_c);
    }

    #[test]
    fn plane_of_the_simulator_outlines_every_rack_and_shows_the_scale() {
        let opts = crate::synth::SynthOptions::new(crate::synth::Preset::Demo, 3);
        let hall = crate::synth::generate_hall(&opts).unwrap();
        let sim = Simulator::new(&hall, crate::sim::SimConfig::default().with_cell_m(0.4)).unwrap();
        let n = sim.grid().len();
        // A made-up field: temperature rising along x, so the scale is known.
        let mut sol_t = vec![0.0; n];
        for (c, t) in sol_t.iter_mut().enumerate() {
            *t = 18.0 + sim.grid().cell_centre(c)[0];
        }
        let p = ThermalPlane {
            title: "x ramp".into(),
            n: [sim.grid().n[0], sim.grid().n[1]],
            d_m: [sim.grid().d[0], sim.grid().d[1]],
            z_m: 1.2,
            temperature_c: (0..sim.grid().n[0] * sim.grid().n[1])
                .map(|c| sol_t[c])
                .collect(),
        };
        let scale = ColourScale::spanning(&[&p]).unwrap();
        assert_eq!(scale.lo_c, 18.0);
        assert_eq!(scale.hi_c, 30.0);
        let svg = thermal_svg(&hall, &p, &scale, &[]);
        assert_eq!(svg.matches(r#"class="rack""#).count(), hall.racks.len());
        for r in &hall.racks {
            assert!(svg.contains(&format!("<title>rack {}</title>", r.id)));
        }
        // Legend ends at the scale limits.
        assert!(
            svg.contains(">18</text>") && svg.contains(">30</text>"),
            "{svg}"
        );
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
    }

    #[test]
    fn slice_of_a_solved_field_marks_racks_solid_and_rejects_heights_outside_the_room() {
        let opts = crate::synth::SynthOptions::new(crate::synth::Preset::Demo, 3)
            .with_snapshots(1)
            .with_model_cell_m(0.4)
            .with_measurement_cell_m(0.4)
            .with_reference_runs(false);
        let s = crate::synth::generate(&opts).unwrap();
        let sim =
            Simulator::new(&s.hall, crate::sim::SimConfig::default().with_cell_m(0.4)).unwrap();
        let layout = crate::ParamLayout::new(&s.hall, &[]).unwrap();
        let alpha = layout.alpha_per_server(&layout.space().initial());
        let sol = sim.solve(&s.snapshots[0].state, &alpha, &[]).unwrap();
        let p = ThermalPlane::from_solution(&sim, &sol, INLET_HEIGHT_M, "t0").unwrap();
        let grid = sim.grid();
        assert_eq!(p.temperature_c.len(), grid.n[0] * grid.n[1]);
        assert!((p.z_m - INLET_HEIGHT_M).abs() <= grid.d[2] / 2.0 + 1e-12);
        // Every cell centre inside a rack is solid (NaN); the air is between the supply
        // and the hottest exhaust.
        let k = grid.cell_of(2, INLET_HEIGHT_M);
        for r in &s.hall.racks {
            let c = [
                r.position_m[0] + r.size_m[0] / 2.0,
                r.position_m[1] + r.size_m[1] / 2.0,
            ];
            let (i, j) = (grid.cell_of(0, c[0]), grid.cell_of(1, c[1]));
            assert!(sim.solid()[grid.idx(i, j, k)], "rack {} not solid", r.id);
            assert!(p.temperature_c[i + grid.n[0] * j].is_nan(), "rack {}", r.id);
        }
        let (lo, hi) = p.range_c().unwrap();
        let hottest = sol
            .server_exhaust_c
            .iter()
            .cloned()
            .fold(f64::MIN, f64::max);
        assert!(
            lo >= sol.supply_c - 0.05 && hi <= hottest + 0.05,
            "{lo} {hi}"
        );
        let fluid = p.temperature_c.iter().filter(|t| t.is_finite()).count();
        assert!(fluid > p.temperature_c.len() / 2);
        assert!(ThermalPlane::from_solution(&sim, &sol, 9.0, "above").is_err());
        assert!(ThermalPlane::from_solution(&sim, &sol, f64::NAN, "nan").is_err());
    }
}
