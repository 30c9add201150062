//! A small SVG line chart for the experiment figures (the report module's chart helpers
//! are private to `kalibre-dc`, and plotters is not a dependency of the root package).

use std::fmt::Write;

/// One line of a chart, with an optional vertical spread per point.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Stroke colour.
    pub colour: &'static str,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Half-height of an error bar per point (empty: none).
    pub spread: Vec<f64>,
    /// Dashed stroke.
    pub dashed: bool,
}

/// A line chart with linear x and a linear or log10 y axis.
#[derive(Debug, Clone)]
pub struct LineChart {
    /// Title above the plot.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// Plot y on a log10 axis (non-positive values are dropped).
    pub log_y: bool,
    /// The lines.
    pub series: Vec<Series>,
}

const W: f64 = 460.0;
const H: f64 = 320.0;
const L: f64 = 64.0;
const R: f64 = 12.0;
const T: f64 = 30.0;
const B: f64 = 44.0;

fn nice_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let raw = (hi - lo) / n.max(1) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return vec![lo];
    }
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let start = (lo / step).ceil() * step;
    (0..)
        .map(|i| start + i as f64 * step)
        .take_while(|t| *t <= hi + 1e-9 * step)
        .collect()
}

impl LineChart {
    fn ty(&self, y: f64) -> Option<f64> {
        if self.log_y {
            (y > 0.0).then(|| y.log10())
        } else {
            y.is_finite().then_some(y)
        }
    }

    /// The chart as an `<svg>` element of 460 x 320 px placed at `(ox, oy)`.
    pub fn svg_at(&self, ox: f64, oy: f64) -> String {
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for s in &self.series {
            for (i, &(x, y)) in s.points.iter().enumerate() {
                let e = s.spread.get(i).copied().unwrap_or(0.0);
                if let (Some(a), Some(b)) = (self.ty(y - e).or(self.ty(y)), self.ty(y + e)) {
                    xs.push(x);
                    ys.push(a);
                    ys.push(b);
                }
            }
        }
        let span = |v: &[f64]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if !(lo.is_finite() && hi.is_finite()) {
                (0.0, 1.0)
            } else if hi - lo < 1e-12 {
                (lo - 1.0, hi + 1.0)
            } else {
                (lo, hi)
            }
        };
        let (x0, x1) = span(&xs);
        let (mut y0, mut y1) = span(&ys);
        if !self.log_y && y0 > 0.0 {
            y0 = 0.0; // Linear MAE axes start at zero so bars compare honestly.
        }
        // Headroom above the data for the legend.
        y1 += (0.05 + 0.07 * self.series.len() as f64) * (y1 - y0);
        let px = |x: f64, y: f64| {
            (
                L + (x - x0) / (x1 - x0) * (W - L - R),
                T + (1.0 - (y - y0) / (y1 - y0)) * (H - T - B),
            )
        };
        let mut s = format!(
            r##"<svg x="{ox}" y="{oy}" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="11"><rect x="{L}" y="{T}" width="{:.1}" height="{:.1}" fill="#fafafa" stroke="#999"/><text x="{:.1}" y="18" text-anchor="middle" font-size="13">{}</text>"##,
            W - L - R,
            H - T - B,
            W / 2.0,
            esc(&self.title)
        );
        for t in nice_ticks(x0, x1, 6) {
            let (a, b) = px(t, y0);
            let _ = write!(
                s,
                r##"<line x1="{a:.1}" y1="{b:.1}" x2="{a:.1}" y2="{:.1}" stroke="#666"/><text x="{a:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                b + 4.0,
                b + 16.0,
                fmt_tick(t)
            );
        }
        let y_ticks = if self.log_y {
            log_ticks(y0, y1)
        } else {
            nice_ticks(y0, y1, 5)
        };
        for t in y_ticks {
            let (a, b) = px(x0, t);
            let label = if self.log_y {
                fmt_tick(10f64.powf(t))
            } else {
                fmt_tick(t)
            };
            let _ = write!(
                s,
                r##"<line x1="{:.1}" y1="{b:.1}" x2="{a:.1}" y2="{b:.1}" stroke="#666"/><text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"##,
                a - 4.0,
                a - 6.0,
                b + 4.0
            );
        }
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text transform="translate(14,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            L + (W - L - R) / 2.0,
            H - 8.0,
            esc(&self.x_label),
            T + (H - T - B) / 2.0,
            esc(&self.y_label)
        );
        for (k, ser) in self.series.iter().enumerate() {
            let mut pts = Vec::new();
            for (i, &(x, y)) in ser.points.iter().enumerate() {
                let Some(ty) = self.ty(y) else { continue };
                let (a, b) = px(x, ty);
                pts.push(format!("{a:.1},{b:.1}"));
                let _ = write!(
                    s,
                    r#"<circle cx="{a:.1}" cy="{b:.1}" r="2.5" fill="{}"/>"#,
                    ser.colour
                );
                let e = ser.spread.get(i).copied().unwrap_or(0.0);
                if e > 0.0 {
                    if let (Some(lo), Some(hi)) = (self.ty(y - e).or(Some(y0)), self.ty(y + e)) {
                        let (_, b0) = px(x, lo);
                        let (_, b1) = px(x, hi);
                        let _ = write!(
                            s,
                            r#"<line x1="{a:.1}" y1="{b0:.1}" x2="{a:.1}" y2="{b1:.1}" stroke="{}"/>"#,
                            ser.colour
                        );
                    }
                }
            }
            let dash = if ser.dashed {
                r#" stroke-dasharray="5,4""#
            } else {
                ""
            };
            let _ = write!(
                s,
                r#"<polyline fill="none" stroke="{}" stroke-width="2"{dash} points="{}"/>"#,
                ser.colour,
                pts.join(" ")
            );
            let ly = T + 12.0 + 14.0 * k as f64;
            let _ = write!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="14" height="3" fill="{}"/><text x="{:.1}" y="{ly:.1}">{}</text>"#,
                L + 8.0,
                ly - 4.0,
                ser.colour,
                L + 26.0,
                esc(&ser.name)
            );
        }
        s.push_str("</svg>");
        s
    }
}

/// Panels side by side in one SVG document.
pub fn panels(charts: &[LineChart]) -> String {
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{H}" viewBox="0 0 {} {H}">"#,
        W * charts.len() as f64,
        W * charts.len() as f64
    );
    for (i, c) in charts.iter().enumerate() {
        s.push_str(&c.svg_at(W * i as f64, 0.0));
    }
    s.push_str("</svg>\n");
    s
}

/// Ticks of a log10 axis (values are exponents): 1, 2 and 5 times powers of ten, or
/// powers of ten alone when the axis spans more than two decades.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mults: &[f64] = if hi - lo > 2.0 {
        &[1.0]
    } else {
        &[1.0, 2.0, 5.0]
    };
    let mut v = Vec::new();
    for e in lo.floor() as i32..=hi.ceil() as i32 {
        for m in mults {
            let t = (m * 10f64.powi(e)).log10();
            if t >= lo - 1e-9 && t <= hi + 1e-9 {
                v.push(t);
            }
        }
    }
    v
}

fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else if (v - v.round()).abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v:.3}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string()
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
