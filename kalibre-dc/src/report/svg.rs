//! Minimal SVG building blocks for offline HTML reports (no scripts, no external files).

use std::fmt::Write;

/// Escapes text for HTML and SVG.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A diverging colour for `v` in `[-1, 1]`: blue (negative), white, red (positive).
pub fn diverging(v: f64) -> String {
    let v = if v.is_finite() {
        v.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let (r, g, b) = if v >= 0.0 {
        (255.0, 255.0 * (1.0 - v), 255.0 * (1.0 - v))
    } else {
        (255.0 * (1.0 + v), 255.0 * (1.0 + v), 255.0)
    };
    format!("rgb({:.0},{:.0},{:.0})", r, g, b)
}

/// Rounds an axis span to "nice" tick values.
pub fn ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / n.max(1) as f64;
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

/// A line or scatter chart with linear axes.
pub struct Chart {
    /// Width and height in pixels.
    pub size: (f64, f64),
    /// x range.
    pub x: (f64, f64),
    /// y range.
    pub y: (f64, f64),
    /// Axis labels.
    pub labels: (String, String),
    body: String,
    x_ticks: Option<Vec<(f64, String)>>,
}

const MARGIN: (f64, f64, f64, f64) = (56.0, 16.0, 20.0, 44.0); // left, right, top, bottom

impl Chart {
    /// A chart over the given ranges (widened when empty).
    pub fn new(size: (f64, f64), x: (f64, f64), y: (f64, f64), xl: &str, yl: &str) -> Self {
        let widen = |(a, b): (f64, f64)| {
            if (b - a).abs() < 1e-12 || !(a.is_finite() && b.is_finite()) {
                let c = if a.is_finite() { a } else { 0.0 };
                (c - 1.0, c + 1.0)
            } else {
                (a, b)
            }
        };
        Chart {
            size,
            x: widen(x),
            y: widen(y),
            labels: (xl.into(), yl.into()),
            body: String::new(),
            x_ticks: None,
        }
    }

    /// Pixel position of a data point.
    pub fn px(&self, x: f64, y: f64) -> (f64, f64) {
        let (w, h) = self.size;
        let (l, r, t, b) = MARGIN;
        let fx = (x - self.x.0) / (self.x.1 - self.x.0);
        let fy = (y - self.y.0) / (self.y.1 - self.y.0);
        (l + fx * (w - l - r), t + (1.0 - fy) * (h - t - b))
    }

    /// Labelled ticks on the x axis in place of the automatic ones.
    pub fn with_x_ticks(mut self, ticks: Vec<(f64, String)>) -> Self {
        self.x_ticks = Some(ticks);
        self
    }

    /// A polyline through the points.
    pub fn line(&mut self, points: &[(f64, f64)], colour: &str, dashed: bool) {
        let pts: Vec<String> = points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|&(x, y)| {
                let (a, b) = self.px(x, y);
                format!("{a:.1},{b:.1}")
            })
            .collect();
        let dash = if dashed {
            r#" stroke-dasharray="5,4""#
        } else {
            ""
        };
        let _ = write!(
            self.body,
            r#"<polyline fill="none" stroke="{colour}" stroke-width="2"{dash} points="{}"/>"#,
            pts.join(" ")
        );
    }

    /// A dot with a hover title.
    pub fn dot(&mut self, x: f64, y: f64, r: f64, colour: &str, title: &str) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let (a, b) = self.px(x, y);
        let _ = write!(
            self.body,
            r#"<circle cx="{a:.1}" cy="{b:.1}" r="{r}" fill="{colour}" fill-opacity="0.8"><title>{}</title></circle>"#,
            esc(title)
        );
    }

    /// A small label just above and right of a data point.
    pub fn text(&mut self, x: f64, y: f64, text: &str) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let (a, b) = self.px(x, y);
        let _ = write!(
            self.body,
            r#"<text x="{:.1}" y="{:.1}" font-size="11">{}</text>"#,
            a + 8.0,
            b - 6.0,
            esc(text)
        );
    }

    /// A legend entry at row `i`.
    pub fn legend(&mut self, i: usize, colour: &str, text: &str) {
        let (l, _, t, _) = MARGIN;
        let y = t + 8.0 + 16.0 * i as f64;
        let _ = write!(
            self.body,
            r#"<rect x="{:.1}" y="{:.1}" width="12" height="4" fill="{colour}"/><text x="{:.1}" y="{:.1}" font-size="12">{}</text>"#,
            l + 10.0,
            y - 4.0,
            l + 28.0,
            y,
            esc(text)
        );
    }

    /// The finished SVG element.
    pub fn finish(self) -> String {
        let (w, h) = self.size;
        let (l, r, t, b) = MARGIN;
        let mut s = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="100%" style="max-width:{w}px" font-family="sans-serif">"#
        );
        let _ = write!(
            s,
            r##"<rect x="{l}" y="{t}" width="{:.1}" height="{:.1}" fill="#fafafa" stroke="#999"/>"##,
            w - l - r,
            h - t - b
        );
        let x_ticks = self.x_ticks.clone().unwrap_or_else(|| {
            ticks(self.x.0, self.x.1, 6)
                .into_iter()
                .map(|t| (t, fmt_tick(t)))
                .collect()
        });
        for (tx, label) in x_ticks {
            let (px, _) = self.px(tx, self.y.0);
            let _ = write!(
                s,
                r##"<line x1="{px:.1}" y1="{:.1}" x2="{px:.1}" y2="{:.1}" stroke="#ddd"/><text x="{px:.1}" y="{:.1}" font-size="11" text-anchor="middle">{}</text>"##,
                t,
                h - b,
                h - b + 14.0,
                esc(&label)
            );
        }
        for ty in ticks(self.y.0, self.y.1, 5) {
            let (_, py) = self.px(self.x.0, ty);
            let _ = write!(
                s,
                r##"<line x1="{l}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end">{}</text>"##,
                w - r,
                l - 4.0,
                py + 4.0,
                fmt_tick(ty)
            );
        }
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="12" text-anchor="middle">{}</text><text x="14" y="{:.1}" font-size="12" text-anchor="middle" transform="rotate(-90 14 {:.1})">{}</text>"#,
            l + (w - l - r) / 2.0,
            h - 6.0,
            esc(&self.labels.0),
            t + (h - t - b) / 2.0,
            t + (h - t - b) / 2.0,
            esc(&self.labels.1)
        );
        s.push_str(&self.body);
        s.push_str("</svg>");
        s
    }
}

/// A tick label: integers without decimals, others with at most two.
pub fn fmt_tick(v: f64) -> String {
    if v.abs() >= 100.0 || v == v.round() {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}
