//! Offline HTML reports with SVG figures: what a calibration found, where the model
//! still fails, and how the error fell.

mod intakes;
mod plan;
mod story;
mod svg;
mod thermal;

pub use intakes::intakes_html;
pub use plan::plan_svg;
pub use story::{outcome_text, story_error_svg, story_html};
pub use thermal::{thermal_svg, ColourScale, Marker, ThermalPlane, INLET_HEIGHT_M};

use std::fmt::Write;

use kalibre_core::calibrate::Report;

use crate::hall::Hall;
use crate::sim::{coldest_under_read, sensor_warming, InletCheck, RackHeat};
use crate::snapshots::HallSnapshot;
use crate::surrogate::PenaltyReport;
use svg::{esc, Chart};

const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;color:#111}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}\
th{background:#f3f4f6}td:first-child,th:first-child{text-align:left}\
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(420px,1fr));gap:1em}\
.note{background:#fff7ed;border-left:4px solid #f97316;padding:.4em .8em}";

/// A rack is named among those warming a sensor when it gives at least this share of the
/// sensor's warming (in the report, and in `kalibre diagnose`).
pub const WARMING_RACK_MIN_SHARE: f64 = 0.1;

/// Where each effect of `hall` acts, for the kinds the hall has more than once: by the
/// prefix of its parameters' names (`rack_recirculation` for the first of a kind,
/// `rack_recirculation#2` for the second, as [`crate::ParamLayout`] names them), its
/// placement in words (`rack B4`: the entry's fields less its parameters' values and
/// bounds).
pub fn effect_locations(hall: &Hall) -> Vec<(String, String)> {
    let registry = crate::effects::EffectRegistry::builtin();
    let mut out = Vec::new();
    for (i, spec) in hall.effects.iter().enumerate() {
        let same = |s: &&crate::hall::EffectSpec| s.kind == spec.kind;
        if hall.effects.iter().filter(same).count() < 2 {
            continue;
        }
        let n = hall.effects[..i].iter().filter(same).count();
        let prefix = match n {
            0 => spec.kind.clone(),
            n => format!("{}#{}", spec.kind, n + 1),
        };
        // A kind of another build: every field but the bounds.
        let place = match registry.build(spec, hall) {
            Ok(e) => crate::effects::placement(spec, e.as_ref()),
            Err(_) => spec.clone(),
        };
        let words: Vec<String> = place
            .fields
            .iter()
            .filter(|(k, _)| !k.ends_with("_bounds"))
            .map(|(k, v)| match v {
                serde_json::Value::String(s) => format!("{k} {s}"),
                v => format!("{k} {v}"),
            })
            .collect();
        if !words.is_empty() {
            out.push((prefix, words.join(", ")));
        }
    }
    out
}

/// A parameter's name with its effect's placement beside it when the hall has that kind
/// more than once (`rack_recirculation#2/fraction (rack B4)`; `locations` from
/// [`effect_locations`]); the name alone otherwise.
pub fn param_label(name: &str, locations: &[(String, String)]) -> String {
    let prefix = name.split('/').next().unwrap_or(name);
    match locations.iter().find(|(p, _)| p == prefix) {
        Some((_, place)) => format!("{name} ({place})"),
        None => name.to_string(),
    }
}

/// Mean residual (model minus measurement) per sensor over the snapshots of the report.
pub fn mean_residual_per_sensor(hall: &Hall, report: &Report) -> Vec<f64> {
    let mut sum = vec![0.0; hall.sensors.len()];
    let mut n = vec![0usize; hall.sensors.len()];
    for r in &report.residuals {
        if let Some(k) = hall.sensors.iter().position(|s| s.id == r.sensor) {
            sum[k] += r.predicted_c - r.measured_c;
            n[k] += 1;
        }
    }
    sum.iter()
        .zip(&n)
        .map(|(s, &c)| if c > 0 { s / c as f64 } else { f64::NAN })
        .collect()
}

/// The error per iteration: the model's MAE at each iteration and the best so far.
pub fn history_svg(report: &Report) -> String {
    let pts: Vec<(f64, f64)> = report
        .history
        .iter()
        .filter_map(|h| h.mae_c.map(|m| (h.iteration as f64, m)))
        .collect();
    let best: Vec<(f64, f64)> = report
        .history
        .iter()
        .filter_map(|h| h.best_mae_c.map(|m| (h.iteration as f64, m)))
        .collect();
    let mut ymax = pts.iter().chain(&best).map(|p| p.1).fold(0.0, f64::max);
    if let Some(m) = report.initial.mae_c {
        ymax = ymax.max(m);
    }
    let xmax = pts.iter().map(|p| p.0).fold(1.0, f64::max);
    let mut c = Chart::new(
        (520.0, 300.0),
        (0.0, xmax),
        (0.0, ymax * 1.05),
        "iteration",
        "MAE (C)",
    );
    if let Some(m) = report.initial.mae_c {
        c.line(&[(0.0, m), (xmax, m)], "#9ca3af", true);
        c.legend(2, "#9ca3af", "uncalibrated model");
    }
    c.line(&pts, "#f97316", false);
    c.line(&best, "#2563eb", false);
    for &(x, y) in &pts {
        c.dot(x, y, 3.0, "#f97316", &format!("iteration {x}: {y:.3} C"));
    }
    c.legend(0, "#f97316", "model at the searched parameters");
    c.legend(1, "#2563eb", "best so far");
    c.finish()
}

/// Measured against predicted temperature, every sensor and snapshot of the best model.
pub fn parity_svg(hall: &Hall, report: &Report) -> String {
    let vals: Vec<f64> = report
        .residuals
        .iter()
        .flat_map(|r| [r.measured_c, r.predicted_c])
        .filter(|v| v.is_finite())
        .collect();
    let lo = vals.iter().cloned().fold(f64::INFINITY, f64::min).floor();
    let hi = vals
        .iter()
        .cloned()
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil();
    let mut c = Chart::new(
        (420.0, 380.0),
        (lo, hi),
        (lo, hi),
        "measured (C)",
        "model (C)",
    );
    c.line(&[(lo, lo), (hi, hi)], "#9ca3af", true);
    for r in &report.residuals {
        let hot = hall
            .sensors
            .iter()
            .find(|s| s.id == r.sensor)
            .is_some_and(|s| s.aisle == crate::hall::Aisle::Hot);
        let colour = if hot { "#dc2626" } else { "#2563eb" };
        c.dot(
            r.measured_c,
            r.predicted_c,
            3.5,
            colour,
            &format!(
                "{} @ {}: measured {:.2}, model {:.2}{}",
                r.sensor,
                r.snapshot,
                r.measured_c,
                r.predicted_c,
                r.weight
                    .map_or(String::new(), |w| format!(", grid weight {w:.2}"))
            ),
        );
    }
    c.legend(0, "#2563eb", "cold aisle");
    c.legend(1, "#dc2626", "hot aisle");
    c.finish()
}

/// The HTML report of one calibration; with `intakes` (each snapshot's server intakes at
/// the best parameters, labelled) it also shows them and the setpoint headroom.
pub fn calibration_html(
    hall: &Hall,
    snaps: &[HallSnapshot],
    report: &Report,
    prior: &PenaltyReport,
    intakes: Option<&[(String, InletCheck)]>,
    warming: Option<&[RackHeat]>,
) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>kalibre: {}</title><style>{STYLE}</style></head><body>",
        esc(&hall.name)
    );
    let _ = write!(
        h,
        "<h1>Calibration of hall <code>{}</code></h1>",
        esc(&hall.name)
    );
    let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    let _ = write!(
        h,
        "<table><tr><th>measure</th><th>value</th></tr>\
         <tr><td>MAE at the hall's initial parameters (C)</td><td>{}</td></tr>\
         <tr><td>best MAE (C)</td><td>{:.3} (found in {})</td></tr>\
         <tr><td>best RMSE / max abs (C)</td><td>{:.3} / {:.3}</td></tr>\
         <tr><td>model runs</td><td>{} ({} new, {} from the journal, {} failed)</td></tr>\
         <tr><td>snapshots x sensors</td><td>{} x {}</td></tr>\
         <tr><td>stopped</td><td>{}</td></tr>\
         <tr><td>likelihood</td><td>{}</td></tr></table>",
        fmt(report.initial.mae_c),
        report.best.mae_c,
        esc(&report.best_found_in()),
        report.best.rmse_c,
        report.best.max_abs_c,
        report.runs.total,
        report.runs.new,
        report.runs.cached,
        report.runs.failed,
        snaps.len(),
        hall.sensors.len(),
        report.stop_reason,
        match grid_weighting_text(report) {
            Some(w) => format!("{}; {w}", likelihood_text(report)),
            None => likelihood_text(report),
        }
    );
    if prior.binds {
        let _ = write!(
            h,
            "<p class=\"note\">The temperature-rise prior binds at the best parameters: {} server(s) below and {} above [{}, {}] C. \
             The data pull against the prior (a prior-data conflict): check the range before trusting these alphas.</p>",
            prior.servers_below, prior.servers_above, prior.range_c[0], prior.range_c[1]
        );
    }
    for text in [
        passed_over_text(report),
        weighted_best_text(report, |m| format!("{m:.3} C")),
    ]
    .into_iter()
    .flatten()
    {
        let _ = write!(h, "<p class=\"note\">Note: {}.</p>", esc(&text));
    }
    let residual = mean_residual_per_sensor(hall, report);
    let scale = residual
        .iter()
        .filter(|v| v.is_finite())
        .fold(0.5f64, |m, v| m.max(v.abs()));
    let _ = write!(
        h,
        "<h2>Where the model fails</h2><p>Mean residual per sensor over all snapshots (best parameters).</p>{}",
        plan_svg(hall, &residual, scale, "C")
    );
    let _ = write!(
        h,
        "<div class=\"grid\"><div><h2>Error per iteration</h2>{}</div><div><h2>Measured against model</h2>{}</div></div>",
        history_svg(report),
        parity_svg(hall, report)
    );
    h.push_str(
        "<h2>Parameters</h2><table><tr><th>parameter</th><th>initial</th><th>calibrated</th>\
         <th>one standard deviation (linearised)</th><th>move from the model's numerics</th></tr>",
    );
    let locations = effect_locations(hall);
    for (name, v) in &report.best.params.0 {
        let init = report.initial.params.get(name);
        let spread = match report.uncertainty.iter().find(|u| u.name == *name) {
            // Only equal bounds leave a parameter out of an estimated uncertainty.
            None if !report.uncertainty.is_empty() => "fixed (equal bounds)".to_string(),
            None => "-".to_string(),
            Some(u) => match (u.std, u.rel_std) {
                (None, _) => "not determined by the measurements".to_string(),
                (Some(_), Some(r)) if !u.settled() => format!(
                    "&plusmn;{}% (not settled: the measurements point {}% away)",
                    percent(100.0 * r, false),
                    percent(100.0 * u.rel_shift().unwrap_or(f64::NAN), true)
                ),
                (Some(_), Some(r)) if !u.identified => {
                    format!("&plusmn;{:.0}% (poorly identified)", 100.0 * r)
                }
                (Some(_), Some(r)) => format!("&plusmn;{:.1}%", 100.0 * r),
                (Some(sd), None) => format!("&plusmn;{sd:.3}"),
            },
        };
        let numerics = report
            .uncertainty
            .iter()
            .find(|u| u.name == *name)
            .and_then(|u| match (u.rel_numerical(), u.numerical) {
                (Some(r), _) => Some(format!("{:.1}%", 100.0 * r)),
                (None, Some(n)) => Some(format!("{n:.3}")),
                _ => None,
            })
            .unwrap_or_else(|| "-".into());
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{v:.5}</td><td>{spread}</td><td>{numerics}</td></tr>",
            esc(&param_label(name, &locations)),
            init.map_or("-".into(), |i| format!("{i:.5}"))
        );
    }
    h.push_str("</table>");
    if !report.numerical_checks.is_empty() {
        let checks: Vec<String> = report
            .numerical_checks
            .iter()
            .map(|c| esc(&c.describe()))
            .collect();
        let _ = write!(
            h,
            "<p>The model's numerics, checked once at the best run ({}). A parameter whose \
             spread and numerics' move together exceed {:.0}% is not called identified: the \
             grid alone moves it that far.</p>",
            checks.join("; "),
            100.0 * kalibre_core::calibrate::IDENTIFIED_REL_STD
        );
    }
    if let Some(src) = report.uncertainty_slopes {
        let _ = write!(
            h,
            "<p>Spreads linearised with {} at the best run.</p>",
            src.describe()
        );
    }
    if let Some(note) = report.repeated_residual_note() {
        let _ = write!(h, "<p><b>Model error:</b> {}.</p>", esc(&note));
    }
    if let Some(checks) = intakes {
        let under = coldest_under_read(hall, &report.residuals);
        h.push_str(&intakes_html(checks, under.as_ref()));
    }
    h.push_str("<h2>Residuals per sensor</h2>");
    if let (Some(_), Some(first)) = (warming, snaps.first()) {
        let _ = write!(
            h,
            "<p>The last column gives the racks whose exhausts warm each sensor in the \
             calibrated model's air flow (snapshot {}, racks giving at least {:.0} % of the \
             sensor's warming over the supply): the racks whose alphas the sensor informs. A \
             sensor the model reads too cold that no exhaust reaches takes its warmth by a path \
             the model lacks.</p>",
            esc(&first.state.label),
            100.0 * WARMING_RACK_MIN_SHARE
        );
    }
    h.push_str("<table><tr><th>sensor</th><th>aisle</th>");
    for s in snaps {
        let _ = write!(h, "<th>{} (C)</th>", esc(&s.state.label));
    }
    if warming.is_some() {
        h.push_str("<th>warmed by, in the model</th>");
    }
    h.push_str("</tr>");
    for sensor in &hall.sensors {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td>",
            esc(&sensor.id),
            sensor.aisle.as_str()
        );
        for s in snaps {
            let r = report
                .residuals
                .iter()
                .find(|r| r.sensor == sensor.id && r.snapshot == s.state.label);
            let _ = match r {
                Some(r) => write!(
                    h,
                    "<td title=\"measured {:.2}, model {:.2}\">{:+.2}</td>",
                    r.measured_c,
                    r.predicted_c,
                    r.predicted_c - r.measured_c
                ),
                None => write!(h, "<td>-</td>"),
            };
        }
        if let Some(rows) = warming {
            let cell = match sensor_warming(rows, &sensor.id, WARMING_RACK_MIN_SHARE) {
                None => "no exhaust".to_string(),
                Some(w) => {
                    let racks: Vec<String> = w
                        .racks
                        .iter()
                        .map(|r| format!("{} {:.0} %", esc(&r.rack), 100.0 * r.share))
                        .collect();
                    format!("{:.2} K: {}", w.warming_k, racks.join(", "))
                }
            };
            let _ = write!(h, "<td>{cell}</td>");
        }
        h.push_str("</tr>");
    }
    h.push_str("</table><p>Generated by kalibre.</p></body></html>");
    h
}

/// The lower-MAE run the rise prior kept from being the best, in words (none when
/// there is none).
pub fn passed_over_text(report: &Report) -> Option<String> {
    let p = report.best.passed_over.as_ref()?;
    Some(format!(
        "a run with a lower MAE ({:.3} C, iteration {}) was not taken as the best: \
         the temperature-rise prior costs {:.2} K there, against {:.2} K here",
        p.score,
        p.iteration,
        p.prior,
        report.best.prior.unwrap_or(0.0)
    ))
}

/// Why the best run's MAE is above a run's the calibration made, when the polish judged
/// runs by a weighted misfit (grid weighting, the Student-t likelihood) and the prior did
/// not account for it (see [`passed_over_text`]); none otherwise. Without it a best MAE
/// above the initial one reads as a calibration that made things worse. `mae` writes an
/// MAE in the calibration's units.
pub fn weighted_best_text(report: &Report, mae: impl Fn(f64) -> String) -> Option<String> {
    let grid = report.residuals.iter().any(|r| r.weight.is_some());
    let robust = report.settings.robust_nu.is_some();
    if !(grid || robust) || report.best.passed_over.is_some() {
        return None;
    }
    let initial = report.initial.mae_c.map(|m| (0, m));
    let runs = report
        .history
        .iter()
        .filter_map(|h| h.mae_c.map(|m| (h.iteration, m)));
    let (iteration, lowest) = initial
        .into_iter()
        .chain(runs)
        .filter(|(_, m)| m.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    // Below the printed precision the two read the same.
    (lowest < report.best.mae_c - 5e-4).then(|| {
        let at = if iteration == 0 {
            "the initial parameters".to_string()
        } else {
            format!("iteration {iteration}")
        };
        let how = match (grid, robust) {
            (true, true) => "the grid weighting and the Student-t likelihood",
            (true, false) => "the grid weighting",
            _ => "the Student-t likelihood",
        };
        format!(
            "a run with a lower MAE ({}, {at}) fits worse by the polish's measure: the \
             best run is the optimum under {how}, where some readings count less (see \
             \"grid weighting\" and \"likelihood\"), so its MAE, with every reading \
             counted alike, can be higher",
            mae(lowest)
        )
    })
}

/// How the calibration weighed residuals, in words.
pub fn likelihood_text(report: &Report) -> String {
    match report.settings.robust_nu {
        None => "least squares (the paper's mean squared error)".to_string(),
        Some(nu) => format!(
            "Student-t, nu {} (in the polish and the uncertainty)",
            crate::snapshots::number(nu)
        ),
    }
}

/// How the polish weighed the readings by the model's finer grids, in words; none when
/// it did not.
pub fn grid_weighting_text(report: &Report) -> Option<String> {
    let weights: Vec<f64> = report.residuals.iter().filter_map(|r| r.weight).collect();
    (!weights.is_empty()).then(|| {
        format!(
            "in the polish each reading weighed by how far the finer grids move it ({} of {} \
             below 0.5)",
            weights.iter().filter(|w| **w < 0.5).count(),
            weights.len()
        )
    })
}

/// A percentage as the uncertainty's notes give it: whole percents from 1 % up, two
/// significant digits below (a shift of 0.04 % is not "0 %"), with a sign if `signed`.
pub fn percent(pct: f64, signed: bool) -> String {
    let a = pct.abs();
    let text = if !a.is_finite() || a >= 1.0 || a == 0.0 {
        format!("{a:.0}")
    } else {
        let decimals = (1 - a.log10().floor() as i32).clamp(1, 12) as usize;
        format!("{a:.decimals$}")
    };
    match (signed, pct < 0.0) {
        (true, true) => format!("-{text}"),
        (true, false) => format!("+{text}"),
        (false, _) => text,
    }
}

#[cfg(test)]
mod tests {
    use super::{percent, weighted_best_text};
    use kalibre_core::calibrate::{PassedOver, Report};

    /// A recalibration's report (trimmed) whose grid-weighted best, 1.238 C, is above
    /// the initial 1.226 C and iteration 13's 1.132 C.
    fn weighted_best() -> Report {
        serde_json::from_str(include_str!("fixtures/weighted-best.json")).unwrap()
    }

    #[test]
    fn a_weighted_best_above_a_lower_mae_is_explained() {
        let r = weighted_best();
        let text = weighted_best_text(&r, |m| format!("{m:.3} C")).expect("a note");
        assert!(
            text.starts_with("a run with a lower MAE (1.132 C, iteration 13)")
                && text.contains("under the grid weighting,"),
            "{text}"
        );
        // Unweighted, the best is the lowest: nothing to explain.
        let mut plain = r.clone();
        plain.residuals.iter_mut().for_each(|x| x.weight = None);
        assert_eq!(weighted_best_text(&plain, |m| format!("{m}")), None);
        // The prior's own note says why instead.
        let mut prior = r.clone();
        prior.best.passed_over = Some(PassedOver {
            iteration: 13,
            score: 1.13,
            prior: 2.0,
        });
        assert_eq!(weighted_best_text(&prior, |m| format!("{m}")), None);
        // A best that is the lowest needs no note, weighted or not.
        let mut lowest = r;
        lowest.best.mae_c = 1.1317;
        assert_eq!(weighted_best_text(&lowest, |m| format!("{m}")), None);
    }

    #[test]
    fn small_percentages_keep_two_significant_digits() {
        assert_eq!(percent(12.4, false), "12");
        assert_eq!(percent(-3.0, true), "-3");
        assert_eq!(percent(0.2, true), "+0.20");
        assert_eq!(percent(0.0421, false), "0.042");
        assert_eq!(percent(-0.00061, true), "-0.00061");
        assert_eq!(percent(0.0, true), "+0");
    }
}
