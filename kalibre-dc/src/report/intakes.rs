//! The calibration report's server intakes: what the calibrated model says where no
//! sensor measures, the setpoint headroom, and how far the calibration's own misfit says
//! to trust it.

use std::fmt::Write;

use crate::sim::{setpoint_headroom_c, InletCheck};

use super::svg::esc;

/// The section: per snapshot (`checks`, labelled) the intakes above the limit, the
/// hottest, the setpoint headroom and, with `under` (the cold-aisle sensor the model
/// reads coldest against the measurements and by how much, negative), the headroom less
/// that misfit.
pub fn intakes_html(checks: &[(String, InletCheck)], under: Option<&(String, f64)>) -> String {
    let mut h = String::from(
        "<h2>Server intakes</h2><p>The calibrated model's intake air at every server, where no \
         sensor measures. The headroom is the limit less the hottest intake: at these flows \
         every setpoint could rise by that much (the model's temperatures move one for one \
         with the supply's).</p>",
    );
    let misfit_header = under.map_or(String::new(), |(s, _)| {
        format!("<th>headroom less the misfit at {} (C)</th>", esc(s))
    });
    let _ = write!(
        h,
        "<table><tr><th>snapshot</th><th>intakes above the limit</th><th>hottest intakes (C)</th>\
         <th>setpoint headroom (C)</th>{misfit_header}</tr>"
    );
    for (label, c) in checks {
        let hottest: Vec<String> = c
            .hottest
            .iter()
            .map(|s| format!("{} ({}) {:.1}", esc(&s.server), esc(&s.rack), s.intake_c))
            .collect();
        let room = setpoint_headroom_c(c);
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{} of {} above {:.1} C</td><td>{}</td><td>{}</td>{}</tr>",
            esc(label),
            c.above_limit,
            c.servers,
            c.limit_c,
            hottest.join(", "),
            room.map_or("-".into(), |r| format!("{r:.2}")),
            match (under, room) {
                (Some((_, m)), Some(r)) => format!("<td>{:.2}</td>", r + m),
                (Some(_), None) => "<td>-</td>".into(),
                (None, _) => String::new(),
            }
        );
    }
    h.push_str("</table>");
    if let Some((sensor, mean)) = under {
        let _ = write!(
            h,
            "<p class=\"note\">The calibrated model reads cold-aisle sensor <code>{}</code> \
             {:.2} C colder than measured on average: intakes near it may be that much warmer \
             than predicted. The headroom less that allows for the error the sensors show; \
             an error where no sensor is (an effect the model lacks, its grid) is not in it \
             (<code>kalibre diagnose</code> looks for the first).</p>",
            esc(sensor),
            -mean
        );
    }
    h
}
