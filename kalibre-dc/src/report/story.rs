//! The HTML report of a story ([`crate::story`]): the steps and their errors, the
//! diagnoses, where the model fails before and after, thermal planes before and after
//! calibration, and the error falling as effects are added.

use std::fmt::Write;

use super::svg::{esc, Chart};
use super::thermal::{thermal_svg, ColourScale, Marker};
use super::{
    effect_locations, history_svg, mean_residual_per_sensor, param_label, parity_svg, plan_svg,
    STYLE,
};
use crate::diagnosis::hypothesis_flags;
use crate::hall::Hall;
use crate::snapshots::HallSnapshot;
use crate::story::{StoryOutcome, StoryReport};

/// The error after each calibration of the story, with the MAE each started from and the
/// floor of a complete model when known.
pub fn story_error_svg(story: &StoryReport) -> String {
    let after: Vec<(f64, f64)> = story
        .steps
        .iter()
        .enumerate()
        .map(|(i, s)| ((i + 1) as f64, s.mae_after_c))
        .collect();
    let before: Vec<(f64, f64)> = story
        .steps
        .iter()
        .enumerate()
        .filter_map(|(i, s)| s.mae_before_c.map(|m| ((i + 1) as f64, m)))
        .collect();
    let ymax = after
        .iter()
        .chain(&before)
        .map(|p| p.1)
        .chain(story.reference_mae_c)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let n = story.steps.len().max(1) as f64;
    // One tick per calibration, named by the effect it added.
    let x_ticks = story
        .steps
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let label = match (i, s.effects.last()) {
                (0, _) | (_, None) => "alpha only".to_string(),
                (_, Some(e)) => format!("+ {}", e.kind),
            };
            ((i + 1) as f64, format!("{}: {label}", i + 1))
        })
        .collect();
    let mut c = Chart::new(
        (520.0, 300.0),
        (0.5, n + 0.5),
        (0.0, ymax * 1.15),
        "calibration",
        "MAE (C)",
    )
    .with_x_ticks(x_ticks);
    if let Some(floor) = story.reference_mae_c {
        c.line(&[(0.5, floor), (n + 0.5, floor)], "#16a34a", true);
        c.legend(2, "#16a34a", "complete model at the true parameters");
    }
    for (i, s) in story.steps.iter().enumerate() {
        let x = (i + 1) as f64;
        if let Some(b) = s.mae_before_c {
            c.line(&[(x, b), (x, s.mae_after_c)], "#9ca3af", true);
            c.dot(x, b, 4.0, "#9ca3af", &format!("{}: start {b:.3} C", s.name));
        }
        c.dot(
            x,
            s.mae_after_c,
            5.0,
            "#2563eb",
            &format!("{}: calibrated {:.3} C", s.name, s.mae_after_c),
        );
        c.text(x, s.mae_after_c, &format!("{:.3} C", s.mae_after_c));
    }
    c.line(&after, "#2563eb", false);
    c.legend(0, "#2563eb", "calibrated MAE");
    c.legend(1, "#9ca3af", "MAE at the start of the calibration");
    c.finish()
}

/// The story's report: every step, what the diagnosis found, and how the error fell.
/// `hall` is the last calibration's hall (with the effects added).
pub fn story_html(hall: &Hall, snaps: &[HallSnapshot], story: &StoryReport) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>kalibre: {}</title><style>{STYLE}</style></head><body>",
        esc(&story.hall)
    );
    let _ = write!(
        h,
        "<h1>Calibration and diagnosis of hall <code>{}</code></h1><p>{}</p>",
        esc(&story.hall),
        esc(&outcome_text(story))
    );
    // The steps.
    h.push_str("<table><tr><th>step</th><th>effects in the model</th><th>MAE before (C)</th><th>MAE after (C)</th><th>model runs</th><th>wall time (s)</th></tr>");
    for (i, s) in story.steps.iter().enumerate() {
        let effects: Vec<String> = s
            .effects
            .iter()
            .map(|e| serde_json::to_string(e).unwrap_or_default())
            .collect();
        let _ = write!(
            h,
            "<tr><td>{}. {}</td><td><code>{}</code></td><td>{}</td><td>{:.3}</td><td>{}</td><td>{:.1}</td></tr>",
            i + 1,
            esc(&s.name),
            esc(&if effects.is_empty() { "none".into() } else { effects.join(" ") }),
            s.mae_before_c.map_or("-".into(), |m| format!("{m:.3}")),
            s.mae_after_c,
            s.model_runs,
            s.wall_s
        );
        if let Some(d) = story.diagnoses.iter().find(|d| d.after_step == i) {
            let top = d.top_significant();
            let _ = write!(
                h,
                "<tr><td>diagnosis</td><td>{}</td><td>{:.3}</td><td>{}</td><td>-</td><td>{:.1}</td></tr>",
                esc(&top.map_or("no significant missing effect".into(), |t| format!(
                    "missing: {}",
                    t.name
                ))),
                d.mae_c,
                top.map_or("-".into(), |t| format!("{:.3} (predicted)", t.predicted_mae_c)),
                d.wall_s
            );
        }
    }
    h.push_str("</table>");
    if let Some(e) = &story.final_diagnosis_error {
        let _ = write!(
            h,
            "<p class=\"note\">The diagnosis after the last calibration failed: {}</p>",
            esc(e)
        );
    }
    if let Some(floor) = story.reference_mae_c {
        let _ = write!(
            h,
            "<p>A complete model at the true parameters reaches {floor:.3} C on these data (noise and grid error).</p>"
        );
    }
    if story.steps.iter().any(|s| s.intakes.is_some()) {
        h.push_str(
            "<p>Where no sensor measures: each calibrated model's intake air at every server \
             against the truth's.</p><table><tr><th>step</th><th>intakes: MAE (C)</th>\
             <th>largest error (C)</th><th>warmest true intake (C)</th></tr>",
        );
        for (i, s) in story.steps.iter().enumerate() {
            if let Some(x) = &s.intakes {
                let _ = write!(
                    h,
                    "<tr><td>{}. {}</td><td>{:.2}</td><td>{:+.2} ({} in {})</td>\
                     <td>{:.1} ({} in {}; model {:.1})</td></tr>",
                    i + 1,
                    esc(&s.name),
                    x.mae_c,
                    x.worst_error_c,
                    esc(&x.worst_server),
                    esc(&x.worst_snapshot),
                    x.warmest_true_c,
                    esc(&x.warmest_server),
                    esc(&x.warmest_snapshot),
                    x.warmest_model_c
                );
            }
        }
        h.push_str("</table>");
    }
    let _ = write!(
        h,
        "<h2>The error as effects are added</h2>{}",
        story_error_svg(story)
    );
    // The diagnoses.
    for d in &story.diagnoses {
        let _ = write!(
            h,
            "<h2>Diagnosis after calibration {} (MAE {:.3} C)</h2>",
            d.after_step + 1,
            d.mae_c
        );
        if d.top_significant().is_none() {
            h.push_str("<p class=\"note\">No significant missing effect: none of the candidates explains enough of the residual, on held-out data, to be worth its parameters.</p>");
        }
        h.push_str(
            "<p>Best first: the significant hypotheses, then the others, each in order of the \
             BIC change it brings (lower is better supported).</p>\
             <table><tr><th>hypothesis</th><th>explains</th><th>predicted MAE (C)</th>\
             <th>BIC change</th><th>flags</th><th>entry for hall.json <code>effects</code></th></tr>",
        );
        for s in &d.hypotheses {
            // The story keeps no refit: nothing is refuted by model runs.
            let mut flags =
                hypothesis_flags(s.significant, false, s.inert, s.identifiable, s.in_range);
            if let Some(note) = d.alternative_note(s) {
                flags = format!("{flags}: {note}");
            }
            // A fit outside its range clamps to an entry that does nothing: none is offered.
            let entry = match &s.entry {
                Some(e) => format!(
                    "<code>{}</code>",
                    esc(&serde_json::to_string(e).unwrap_or_default())
                ),
                None => "none (fitted outside its range, which no entry gives)".to_string(),
            };
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{:.0}%</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{entry}</td></tr>",
                esc(&s.name),
                100.0 * s.explained_fraction,
                s.predicted_mae_c,
                s.delta_bic.map_or("-".into(), |b| format!("{b:+.1}")),
                esc(&flags),
            );
        }
        h.push_str("</table>");
    }
    // Where the model fails, first and last calibration on one scale.
    let first = story.steps.first();
    let last = story.steps.last();
    if let (Some(first), Some(last)) = (first, last) {
        let r0 = mean_residual_per_sensor(hall, &first.report);
        let r1 = mean_residual_per_sensor(hall, &last.report);
        let scale = r0
            .iter()
            .chain(&r1)
            .filter(|v| v.is_finite())
            .fold(0.5f64, |m, v| m.max(v.abs()));
        h.push_str("<h2>Where the model fails</h2><p>Mean residual (model minus measurement) per sensor over all snapshots, at the best parameters, on one colour scale.</p><div class=\"grid\">");
        let _ = write!(
            h,
            "<div><h3>after calibration 1 ({})</h3>{}</div>",
            esc(&first.name),
            plan_svg(hall, &r0, scale, "C")
        );
        if story.steps.len() > 1 {
            let _ = write!(
                h,
                "<div><h3>after calibration {} ({})</h3>{}</div>",
                story.steps.len(),
                esc(&last.name),
                plan_svg(hall, &r1, scale, "C")
            );
        }
        h.push_str("</div>");
    }
    // Thermal planes on one colour scale.
    let planes: Vec<_> = story.thermal.iter().collect();
    if let Some(scale) = ColourScale::spanning(&planes) {
        let snap = snaps.iter().find(|s| {
            planes[0]
                .title
                .ends_with(&format!("snapshot {}", s.state.label))
        });
        let markers: Vec<Marker> = snap
            .map(|s| {
                hall.sensors
                    .iter()
                    .zip(&s.sensor_c)
                    .filter(|(sensor, _)| (sensor.position_m[2] - planes[0].z_m).abs() < 0.5)
                    .filter_map(|(sensor, v)| {
                        v.map(|v| Marker {
                            label: sensor.id.clone(),
                            position_m: [sensor.position_m[0], sensor.position_m[1]],
                            value_c: v,
                        })
                    })
                    .collect()
            })
            .unwrap_or_default();
        let _ = write!(
            h,
            "<h2>Thermal plane at z = {:.2} m, before and after calibration</h2><p>The simulator's air temperature at inlet height; circles are the sensors within 0.5 m of the plane, filled with their measured temperature on the same scale.</p><div class=\"grid\">",
            planes[0].z_m
        );
        for p in &planes {
            let _ = write!(
                h,
                "<div><h3>{}</h3>{}</div>",
                esc(&p.title),
                thermal_svg(hall, p, &scale, &markers)
            );
        }
        h.push_str("</div>");
    }
    // Each calibration's iterations, and measured against model for the last.
    h.push_str("<h2>Error per iteration</h2><div class=\"grid\">");
    for (i, s) in story.steps.iter().enumerate() {
        let _ = write!(
            h,
            "<div><h3>calibration {}: {}</h3>{}</div>",
            i + 1,
            esc(&s.name),
            history_svg(&s.report)
        );
    }
    h.push_str("</div>");
    if let (Some(first), Some(last)) = (first, last) {
        h.push_str("<h2>Measured against model</h2><div class=\"grid\">");
        let _ = write!(
            h,
            "<div><h3>after calibration 1</h3>{}</div>",
            parity_svg(hall, &first.report)
        );
        if story.steps.len() > 1 {
            let _ = write!(
                h,
                "<div><h3>after calibration {}</h3>{}</div>",
                story.steps.len(),
                parity_svg(hall, &last.report)
            );
        }
        h.push_str("</div>");
        h.push_str("<h2>Calibrated parameters</h2><table><tr><th>parameter</th>");
        for i in 0..story.steps.len() {
            let _ = write!(h, "<th>calibration {}</th>", i + 1);
        }
        h.push_str("</tr>");
        // `hall` is the last calibration's: every effect added so far.
        let locations = effect_locations(hall);
        for (name, _) in &last.best_params.0 {
            let _ = write!(h, "<tr><td>{}</td>", esc(&param_label(name, &locations)));
            for s in &story.steps {
                let _ = write!(
                    h,
                    "<td>{}</td>",
                    s.best_params
                        .get(name)
                        .map_or("-".into(), |v| format!("{v:.5}"))
                );
            }
            h.push_str("</tr>");
        }
        h.push_str("</table>");
    }
    h.push_str(
        "<p>Generated by kalibre (<code>story.json</code> holds every figure).</p></body></html>",
    );
    h
}

/// The outcome in one sentence.
pub fn outcome_text(story: &StoryReport) -> String {
    let first = story.steps.first().map_or(f64::NAN, |s| s.mae_after_c);
    let last = story.steps.last().map_or(f64::NAN, |s| s.mae_after_c);
    match story.outcome {
        StoryOutcome::NothingSignificant => format!(
            "Calibrating alpha reached {first:.3} C; the diagnosis found no significant missing effect, so nothing was added."
        ),
        StoryOutcome::Improved => format!(
            "Calibrating alpha reached {first:.3} C; adding {} and recalibrating brought it to {last:.3} C ({:.0}% lower).",
            added_names(story),
            100.0 * (1.0 - last / first)
        ),
        StoryOutcome::NotImproved => format!(
            "Calibrating alpha reached {first:.3} C; adding {} and recalibrating did not lower it ({last:.3} C).",
            added_names(story)
        ),
    }
}

fn added_names(story: &StoryReport) -> String {
    story
        .added
        .iter()
        .map(|e| e.kind.as_str())
        .collect::<Vec<_>>()
        .join(", then ")
}
