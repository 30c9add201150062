//! Fig. 7's figure (SVG) and tables (markdown).

use super::super::chart::{panels, LineChart, Series};
use super::{AlphaGrain, Fig7Result, Point, FRACTIONS};

/// The figure: test MAE against the share of training data, mean and standard deviation
/// over seeds.
pub fn svg(r: &Fig7Result) -> String {
    let colours = ["#1f77b4", "#2ca02c", "#d62728", "#9467bd"];
    let chart = LineChart {
        title: format!(
            "Fig. 7 ({}, {} runs, 8:2 split; {})",
            r.config.preset,
            r.config.samples,
            r.config.draw.describe(),
        ) + &grain_caption(r.config.grain),
        x_label: "share of the training set (%)".into(),
        y_label: "test MAE (C)".into(),
        log_y: false,
        series: r
            .curves
            .iter()
            .zip(colours)
            .map(|(c, colour)| Series {
                name: c.surrogate.clone(),
                colour,
                points: c
                    .points
                    .iter()
                    .map(|p| (100.0 * p.fraction, p.mae_c.mean))
                    .collect(),
                spread: c.points.iter().map(|p| p.mae_c.sd).collect(),
                dashed: false,
            })
            .chain(std::iter::once(Series {
                name: "training mean".into(),
                colour: "#888888",
                points: FRACTIONS
                    .iter()
                    .map(|f| (100.0 * f, r.mean_predictor_mae_c))
                    .collect(),
                spread: Vec::new(),
                dashed: true,
            }))
            .collect(),
    };
    panels(&[chart])
}

/// ", one draw per rack" for the rack and server draws; nothing for the type draw, whose
/// captions predate the choice.
fn grain_caption(grain: AlphaGrain) -> String {
    match grain {
        AlphaGrain::Type => String::new(),
        g => format!(", {}", g.describe()),
    }
}

/// A markdown table with one row per curve and one column per share: `head` labels a
/// share's column, `cell` writes a point.
fn curve_table(
    r: &Fig7Result,
    head: impl Fn(&Point) -> String,
    cell: impl Fn(&Point) -> String,
) -> String {
    let points = &r.curves[0].points;
    let mut s = String::from("| surrogate |");
    for p in points {
        s.push_str(&format!(" {} |", head(p)));
    }
    s.push_str(&format!("\n|---|{}\n", "---|".repeat(points.len())));
    for c in &r.curves {
        s.push_str(&format!("| {} |", c.surrogate));
        for p in &c.points {
            s.push_str(&format!(" {} |", cell(p)));
        }
        s.push('\n');
    }
    s
}

/// The figure's numbers as a markdown table.
pub fn markdown(r: &Fig7Result) -> String {
    let mut s = curve_table(
        r,
        |p| format!("{:.0}% ({} samples)", 100.0 * p.fraction, p.train_samples),
        |p| p.mae_c.show(2),
    );
    s.push_str(&format!(
        "\nTest MAE (C), mean ± sd over {} seeds; {}; {} training / {} test runs; predicting the training mean: {:.2} C. \
         Fixed adjacency over MLP at 5%: {:.2} (target <= 0.5: {}).\n",
        r.config.seeds,
        r.config.draw.describe()
            + &grain_caption(r.config.grain)
            + if r.config.sharp_adjacency {
                "; server-sensor edges 1/d^4 with the height difference halved"
            } else {
                ""
            }
            + if r.config.local_recirculation {
                "; the whole-hall local recirculation term on the cold-aisle sensors"
            } else {
                ""
            }
            + if r.config.influence_adjacency {
                "; hot-aisle edges from the model's air flow"
            } else {
                ""
            },
        r.train,
        r.test,
        r.mean_predictor_mae_c,
        r.fixed_over_mlp_at_5pct,
        if r.target_met { "met" } else { "NOT met" }
    ));
    if let Some([Some(cold), Some(hot)]) = r.mean_predictor_by_aisle_c {
        s.push_str("\nBy aisle, cold / hot (C, means over seeds):\n\n");
        s.push_str(&curve_table(
            r,
            |p| format!("{:.0}%", 100.0 * p.fraction),
            |p| match (&p.cold_mae_c, &p.hot_mae_c) {
                (Some(c), Some(h)) => format!("{:.2} / {:.2}", c.mean, h.mean),
                _ => "-".into(),
            },
        ));
        s.push_str(&format!(
            "| training mean | {} |\n",
            vec![format!("{cold:.2} / {hot:.2}"); r.curves[0].points.len()].join(" | ")
        ));
    }
    s
}
