//! `kalibre simulate`'s account of the server intakes: per snapshot, how many are above
//! the limit, the hottest, the setpoint headroom, and how far the calibration's own
//! misfit says to trust that headroom ([`kalibre_dc::sim::coldest_under_read`]).

use kalibre_dc::sim::{setpoint_headroom_c, InletCheck};

/// One snapshot's server intakes against the limit, e.g.
/// `t0: 2 of 300 server intakes above 27.0 C; hottest A05-33 (rack A05) 28.4 C, ...;
/// 1.40 C over: ...`.
pub fn inlet_line(label: &str, check: &InletCheck) -> String {
    let hottest: Vec<String> = check
        .hottest
        .iter()
        .map(|s| format!("{} (rack {}) {:.1} C", s.server, s.rack, s.intake_c))
        .collect();
    format!(
        "{label}: {} of {} server intakes above {:.1} C; hottest {}{}",
        check.above_limit,
        check.servers,
        check.limit_c,
        hottest.join(", "),
        setpoint_headroom_c(check).map_or(String::new(), |room| {
            // Within a hundredth of the limit, two decimals would read 0.00.
            let digits = if room.abs() < 0.005 { 3 } else { 2 };
            if room >= 0.0 {
                format!(
                    "; headroom {room:.digits$} C: every setpoint could rise by that much at \
                     these flows"
                )
            } else {
                format!(
                    "; {:.digits$} C over: every setpoint would have to fall by that much at \
                     these flows",
                    -room
                )
            }
        })
    )
}

/// The note on the headroom: inlet sensors are the measurements nearest the intakes, and
/// where the calibrated model reads one colder than measured, intakes near it may be as
/// much warmer than it predicts.
pub fn under_read_note(
    under: &(String, f64),
    labels: &[String],
    headroom_c: &[Option<f64>],
) -> String {
    let (sensor, mean) = under;
    let safe: Vec<String> = labels
        .iter()
        .zip(headroom_c)
        .filter_map(|(l, h)| h.map(|h| format!("{l} {:.2} C", h + mean)))
        .collect();
    format!(
        "note: the calibrated model reads cold-aisle sensor {sensor} {:.2} C colder than measured \
         on average; intakes near it may be that much warmer than predicted. Headroom less that \
         (an allowance for the error the sensors show, not a bound): {}",
        -mean,
        safe.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibre_dc::sim::ServerAir;

    fn check(hottest_c: f64) -> InletCheck {
        InletCheck {
            limit_c: 27.0,
            servers: 1,
            above_limit: usize::from(hottest_c > 27.0),
            hottest: vec![ServerAir {
                snapshot: "t0".into(),
                server: "A1-01".into(),
                rack: "A1".into(),
                server_type: "web".into(),
                power_w: 300.0,
                flow_m3_s: 0.02,
                intake_c: hottest_c,
                exhaust_c: hottest_c + 10.0,
            }],
        }
    }

    #[test]
    fn headroom_is_the_limit_minus_the_hottest_intake_and_the_note_subtracts_the_misfit() {
        assert!(inlet_line("t0", &check(21.0)).contains("headroom 6.00 C"));
        assert!(inlet_line("t0", &check(28.5)).contains("1.50 C over"));
        let note = under_read_note(
            &("c-A1-lo".into(), -3.5),
            &["t0".into(), "t1".into()],
            &[check(21.0), check(25.0)].map(|c| setpoint_headroom_c(&c)),
        );
        assert!(note.contains("c-A1-lo 3.50 C colder"), "{note}");
        assert!(note.contains("t0 2.50 C, t1 -1.50 C"), "{note}");
    }
}
