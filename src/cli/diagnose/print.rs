//! What `kalibre diagnose` (and the demo) print beside the ranking: close alternatives,
//! the sensors no candidate explains, the worst sensors and the racks that warm them.

use std::collections::BTreeMap;

use kalibre_core::calibrate::Report;
use kalibre_core::diagnose::{Diagnosis, HypothesisResult, CLOSE_ALTERNATIVE_BIC};
use kalibre_dc::diagnosis::{worst_sensors, OddSnapshot, WORST_SENSORS_SHOWN};
use kalibre_dc::hall::Hall;
use kalibre_dc::report::WARMING_RACK_MIN_SHARE;
use kalibre_dc::sim::{sensor_warming, RackHeat};

/// The hypotheses the data hardly tell from the best one, under it: a neighbouring
/// placement is often among them, and the place to look is then either.
pub(crate) fn print_close_alternatives(d: &Diagnosis, best: &HypothesisResult) {
    let close = d.close_alternatives();
    if close.is_empty() {
        return;
    }
    let describe = |h: &&HypothesisResult| {
        let why = match &h.carried_by {
            Some(sensor) => format!(", rests on {sensor} alone"),
            None => String::new(),
        };
        format!("{} (BIC {:+.1}{why})", h.name, h.delta_bic - best.delta_bic)
    };
    // Those with a lower BIC than the best are not significant for another reason (one
    // sensor carries them, say): they fit better, which is not "hardly told apart".
    let (better, near): (Vec<_>, Vec<_>) = close.iter().partition(|h| h.delta_bic < best.delta_bic);
    if !near.is_empty() {
        let names: Vec<String> = near.iter().map(describe).collect();
        println!(
            "    the data hardly tell it from (BIC within {CLOSE_ALTERNATIVE_BIC:.0}): {}",
            names.join(", ")
        );
    }
    if !better.is_empty() {
        let names: Vec<String> = better.iter().map(describe).collect();
        println!(
            "    fit better, but are not significant: {}",
            names.join(", ")
        );
    }
}

/// The sensors no candidate explains: the model's own error there, or a faulty sensor.
/// `robust_nu` is the calibration's Student-t likelihood, if it had one.
pub(crate) fn print_unexplained(d: &kalibre_core::diagnose::Diagnosis, robust_nu: Option<f64>) {
    if d.unexplained.is_empty() {
        return;
    }
    // Their residuals are those the ranking compares: left with the best significant
    // hypothesis added, else with the calibrated parameters refit (linearised, as every
    // hypothesis is); so they can differ from the worst sensors' above, which are the
    // calibrated model's own.
    let best = d.significant().next().map(|h| h.name.as_str());
    let after = match best {
        Some(name) => format!("left with {name} added"),
        None => "left with the calibrated parameters refit".to_string(),
    };
    println!(
        "\nsensors no candidate explains (the model's own physics there, or a faulty or misplaced sensor; \
         the ranking above counts them little; residuals {after}):"
    );
    for u in &d.unexplained {
        // A candidate may explain it and still not count: one that rests on it alone.
        let resting: Vec<&str> = d
            .hypotheses
            .iter()
            .filter(|h| h.carried_by.as_deref() == Some(u.output.as_str()))
            .map(|h| h.name.as_str())
            .collect();
        let mut notes = Vec::new();
        if !resting.is_empty() {
            let verb = if resting.len() == 1 { "rests" } else { "rest" };
            notes.push(format!("{} {verb} on it alone", resting.join(", ")));
        }
        // How far other plausible physics (the model-form variants) moves it: when that
        // is of the residual's size, the model's own physics there is the likely cause.
        if let Some(form) = u.model_form_c {
            notes.push(format!(
                "tile jets, which the model lacks, would move it by {form:.2} C"
            ));
        }
        let note = if notes.is_empty() {
            String::new()
        } else {
            format!(" ({})", notes.join("; "))
        };
        println!(
            "  {:<12} model minus measurement {:+.2} C on average, {:.1} noise scales{note}",
            u.output, u.mean_residual, u.rms_scales
        );
    }
    match (robust_nu, best) {
        (Some(nu), _) => println!(
            "  the calibration already weighed them down (Student-t likelihood, {nu} degrees of \
             freedom), as this ranking does"
        ),
        (None, Some(_)) => println!(
            "  to calibrate again with the suggested effect, weighing them down as this ranking \
             does, add `--likelihood student-t` to `kalibre calibrate`"
        ),
        (None, None) => println!(
            "  to calibrate again weighing them down as this ranking does, add `--likelihood \
             student-t` to `kalibre calibrate`"
        ),
    }
}

/// One worst sensor in words: where it is and how far off the model reads.
pub(crate) fn sensor_line(hall: &Hall, sensor: &str, mean_c: f64) -> String {
    let s = hall.sensors.iter().find(|s| s.id == sensor);
    let (aisle, pos) = s.map_or(("?", [0.0; 3]), |s| (s.aisle.as_str(), s.position_m));
    format!(
        "{sensor:<12} {aisle:>4} aisle at ({:.1}, {:.1}, {:.1}) m: the model reads {:.2} C {}",
        pos[0],
        pos[1],
        pos[2],
        mean_c.abs(),
        if mean_c > 0.0 { "too warm" } else { "too cold" }
    )
}

/// The racks that warm `sensor` in the model's flow, in words (`rows`: every rack's
/// share, no cut).
pub(crate) fn warming_racks(rows: &[RackHeat], sensor: &str, mean_c: f64) -> String {
    let Some(warming) = sensor_warming(rows, sensor, WARMING_RACK_MIN_SHARE) else {
        let none = "no exhaust reaches it in the model (under 0.01 K)";
        return if mean_c < 0.0 {
            format!(
                "{none}: the measured warmth takes a path the model lacks, or the sensor is off"
            )
        } else {
            format!("{none}: the model's supply air reaching it is warmer than measured, or the sensor is off")
        };
    };
    let racks: Vec<String> = warming
        .racks
        .iter()
        .map(|r| format!("{} {:.0} %", r.rack, 100.0 * r.share))
        .collect();
    // Too warm by more than the exhausts add: the excess is in the supply air itself.
    let supply = if mean_c > 0.0 && warming.warming_k < 0.5 * mean_c {
        "; less than the excess: the model's supply air reaching it is warmer than measured"
    } else {
        ""
    };
    format!(
        "in the model, exhausts warm it by {:.2} K in {}: {}{supply}",
        warming.warming_k,
        warming.snapshot,
        if racks.is_empty() {
            format!(
                "no rack gives {:.0} % of that",
                100.0 * WARMING_RACK_MIN_SHARE
            )
        } else {
            format!("racks {}", racks.join(", "))
        }
    )
}

/// The note on each odd snapshot, for the text listing.
pub(crate) fn print_odd_snapshots(odd: &[OddSnapshot]) {
    for o in odd {
        let side = if o.shift_c > 0.0 { "warm" } else { "cold" };
        println!(
            "\nsnapshot {}: the model reads {:.2} C too {side} at {} of its {} sensors, beyond \
             each sensor's usual residual in the other snapshots. No effect of the hall shifts \
             one snapshot alone: its conditions were likely not steady (a setpoint or load \
             change the sensors had not caught up with), its setpoint, fan or power rows are \
             wrong, or the model errs at its conditions alone. Check it, or leave it out of \
             the snapshots and calibrate again; the ranking below takes it as it is, and its \
             shift is spread over the sensors listed as unexplained",
            o.snapshot,
            o.shift_c.abs(),
            o.sensors_off,
            o.sensors
        );
    }
}

/// The worst sensors and the residual by aisle and snapshot, in words.
pub(crate) fn print_where_it_fails(hall: &Hall, report: &Report, heat: Option<&[RackHeat]>) {
    println!("where the calibrated model fails (model minus measurement):");
    let mut by_group: BTreeMap<(String, String), (f64, usize)> = BTreeMap::new();
    for r in &report.residuals {
        let aisle = hall
            .sensors
            .iter()
            .find(|s| s.id == r.sensor)
            .map_or("?", |s| s.aisle.as_str());
        let g = by_group
            .entry((aisle.to_string(), r.snapshot.clone()))
            .or_default();
        g.0 += r.predicted_c - r.measured_c;
        g.1 += 1;
    }
    for (sensor, mean) in worst_sensors(&report.residuals)
        .iter()
        .take(WORST_SENSORS_SHOWN)
    {
        println!("  {}", sensor_line(hall, sensor, *mean));
        if let Some(rows) = heat {
            println!("  {:<12} {}", "", warming_racks(rows, sensor, *mean));
        }
    }
    for ((aisle, snap), (s, n)) in &by_group {
        println!(
            "  {aisle:>4} aisle, snapshot {snap:<6} mean residual {:+.2} C",
            s / *n as f64
        );
    }
}

/// Why a fit lies outside its range, in words. Below a range that starts at the effect's
/// absence (a bypass at a negative share), the data ask for the opposite of the effect;
/// beyond its range otherwise (an offset of 5.7 C where 5 is the most), more of it than
/// any entry gives.
pub(crate) fn outside_range(h: &HypothesisResult) -> String {
    let fitted: Vec<String> = h
        .fitted
        .0
        .iter()
        .map(|(name, v)| format!("{name} = {v:.4}"))
        .collect();
    let opposite = h
        .fitted
        .0
        .iter()
        .zip(&h.ranges)
        .any(|((_, v), [lower, _])| *v < *lower && *lower >= 0.0);
    let beyond: Vec<String> = h
        .fitted
        .0
        .iter()
        .zip(&h.ranges)
        .filter(|((_, v), [lower, upper])| *v < *lower || *v > *upper)
        .map(|((_, v), [lower, upper])| {
            let side = if *v > *upper { "above" } else { "below" };
            format!("{side} its range [{lower}, {upper}]")
        })
        .collect();
    if opposite || beyond.is_empty() {
        format!(
            "fitted {}: the data lean the opposite way, which no entry gives",
            fitted.join(", ")
        )
    } else {
        format!(
            "fitted {}: {}, more than any entry gives",
            fitted.join(", "),
            beyond.join(", ")
        )
    }
}

/// Why a significant hypothesis is not identifiable: another candidate, or the
/// calibrated parameters, move the readings the same way, so its place or size is not
/// the data's alone.
pub(crate) fn not_identifiable(h: &HypothesisResult) -> String {
    if h.collinear_with.is_empty() {
        "not identifiable: the calibrated parameters move the readings much as it does, so \
         its size may trade against theirs (calibrating with it settles both)"
            .to_string()
    } else {
        format!(
            "not identifiable: the data cannot tell it from {}, which move the readings the \
             same way; calibrating with it settles its size",
            kalibre_core::some_names(&h.collinear_with)
        )
    }
}

/// A hypothesis's verdict flags in words (`significant`, `not identifiable`, ...).
pub(super) fn flags(h: &HypothesisResult) -> String {
    kalibre_dc::diagnosis::hypothesis_flags(
        h.significant,
        h.refuted,
        h.inert,
        h.identifiable,
        h.in_range,
    )
}
