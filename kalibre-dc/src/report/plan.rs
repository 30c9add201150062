//! A plan view (top-down) of a hall with each sensor coloured by a value (its residual).

use std::fmt::Write;

use super::svg::{diverging, esc};
use crate::hall::{Aisle, Hall};

/// SVG plan of the hall: racks, CRACs, tiles, containment, and the sensors coloured by
/// `value_per_sensor` on a diverging scale of `±scale` (NaN: grey, no reading).
pub fn plan_svg(hall: &Hall, value_per_sensor: &[f64], scale: f64, unit: &str) -> String {
    let [lx, ly, _] = hall.room.size_m;
    let width = 760.0;
    let k = (width - 20.0) / lx.max(1e-9);
    let height = ly * k + 60.0;
    let x = |v: f64| 10.0 + v * k;
    let y = |v: f64| 10.0 + (ly - v) * k; // y up in the hall, down on screen
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height:.0}" width="100%" style="max-width:{width}px" font-family="sans-serif">"#
    );
    let _ = write!(
        s,
        r##"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="#fcfcfc" stroke="#333"/>"##,
        x(0.0),
        y(ly),
        lx * k,
        ly * k
    );
    let rect = |s: &mut String, p: [f64; 2], d: [f64; 2], style: &str, title: &str| {
        let _ = write!(
            s,
            r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" {style}><title>{}</title></rect>"#,
            x(p[0]),
            y(p[1] + d[1]),
            d[0] * k,
            d[1] * k,
            esc(title)
        );
    };
    for t in &hall.tiles {
        rect(
            &mut s,
            t.position_m,
            t.size_m,
            r##"fill="#dbeafe" stroke="#93c5fd""##,
            "tile",
        );
    }
    for c in &hall.containment {
        let d = [c.max_m[0] - c.min_m[0], c.max_m[1] - c.min_m[1]];
        rect(
            &mut s,
            [c.min_m[0], c.min_m[1]],
            d,
            r##"fill="#fee2e2" fill-opacity="0.5" stroke="#ef4444" stroke-dasharray="4,3""##,
            "containment",
        );
    }
    for r in &hall.racks {
        rect(
            &mut s,
            [r.position_m[0], r.position_m[1]],
            [r.size_m[0], r.size_m[1]],
            r##"fill="#9ca3af" stroke="#4b5563""##,
            &format!("rack {} ({} servers)", r.id, r.servers.len()),
        );
    }
    for c in &hall.cracs {
        rect(
            &mut s,
            [c.position_m[0], c.position_m[1]],
            [c.size_m[0], c.size_m[1]],
            r##"fill="#3b82f6" stroke="#1e3a8a""##,
            &format!("CRAC {}", c.id),
        );
    }
    for (sensor, v) in hall.sensors.iter().zip(value_per_sensor) {
        let colour = if v.is_finite() {
            diverging(v / scale.max(1e-9))
        } else {
            "#bbb".to_string()
        };
        let shape = match sensor.aisle {
            Aisle::Cold => "circle",
            Aisle::Hot => "rect",
        };
        let (cx, cy) = (x(sensor.position_m[0]), y(sensor.position_m[1]));
        let title = format!(
            "{} ({} aisle, z {:.1} m): {}",
            sensor.id,
            sensor.aisle.as_str(),
            sensor.position_m[2],
            if v.is_finite() {
                format!("{v:+.2} {unit}")
            } else {
                "no reading".into()
            }
        );
        if shape == "circle" {
            let _ = write!(
                s,
                r##"<circle cx="{cx:.1}" cy="{cy:.1}" r="6" fill="{colour}" stroke="#111"><title>{}</title></circle>"##,
                esc(&title)
            );
        } else {
            let _ = write!(
                s,
                r##"<rect x="{:.1}" y="{:.1}" width="11" height="11" fill="{colour}" stroke="#111"><title>{}</title></rect>"##,
                cx - 5.5,
                cy - 5.5,
                esc(&title)
            );
        }
    }
    // Colour scale.
    let y0 = ly * k + 24.0;
    for i in 0..=20 {
        let v = -1.0 + i as f64 / 10.0;
        let _ = write!(
            s,
            r#"<rect x="{:.1}" y="{y0:.1}" width="12" height="10" fill="{}"/>"#,
            20.0 + 12.0 * i as f64,
            diverging(v)
        );
    }
    let _ = write!(
        s,
        r#"<text x="20" y="{:.1}" font-size="11">-{scale:.2} {unit}</text><text x="272" y="{:.1}" font-size="11" text-anchor="end">+{scale:.2} {unit}</text><text x="290" y="{:.1}" font-size="11">model minus measurement (circle: cold aisle, square: hot aisle)</text>"#,
        y0 + 22.0,
        y0 + 22.0,
        y0 + 9.0
    );
    s.push_str("</svg>");
    s
}
