//! The end-of-run summary of `kalibre calibrate`: errors, runs, stop reason, which
//! parameters the data identify, and the best parameters.

use kalibre_core::calibrate::Report;

/// What is calibrated: a hall (errors in C, per aisle, a temperature-rise prior) or a
/// model of your own (errors in its outputs' units, which kalibre does not know, or with
/// `scaled` in units of each measurement's `sd`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Style {
    Hall,
    Generic { scaled: bool },
}

impl Style {
    /// An error as the summary shows it, with its unit where it has one.
    pub(super) fn error(self, v: Option<f64>) -> String {
        let unit = match self {
            Style::Hall => " C",
            Style::Generic { scaled: false } => "",
            Style::Generic { scaled: true } => " sd",
        };
        v.filter(|v| v.is_finite())
            .map_or("-".into(), |v| format!("{v:.3}{unit}"))
    }
}

/// Which parameters the measurements pin down (the report's linearised uncertainty).
fn print_uncertainty(report: &Report, style: Style) {
    let u = &report.uncertainty;
    if u.is_empty() {
        return;
    }
    let poor: Vec<String> = u
        .iter()
        .filter(|p| !p.identified)
        .map(|p| {
            // The numerics' move, where it is what keeps the value from being claimed.
            let grid = p
                .rel_numerical()
                .filter(|n| *n >= 0.5 * kalibre_core::calibrate::IDENTIFIED_REL_STD)
                .map_or(String::new(), |n| {
                    format!(", the model's numerics move it {:.0}%", 100.0 * n)
                });
            match (p.rel_std, p.rel_shift()) {
                (Some(r), Some(d)) if !p.settled() => format!(
                    "{} (+/-{}%{grid}, not settled: the data point {}% away)",
                    p.name,
                    kalibre_dc::report::percent(100.0 * r, false),
                    kalibre_dc::report::percent(100.0 * d, true)
                ),
                (Some(r), _) => format!("{} (+/-{:.0}%{grid})", p.name, 100.0 * r),
                // No finite spread: the slopes the spreads used (see "slopes of the
                // spreads"; the surrogate's are crude early on) do not pin it, which
                // need not mean the data cannot.
                (None, _) => format!("{} (no finite spread from these slopes)", p.name),
            }
        })
        .collect();
    let with_numerics = if u.iter().any(|p| p.numerical.is_some()) {
        ", with the model's numerics' move,"
    } else {
        ""
    };
    println!(
        "  {:<28} {} of {} (one standard deviation{with_numerics} within {:.0}%, and the data point within {:.0} of them or {:.2}% of the value)",
        "parameters identified",
        u.len() - poor.len(),
        u.len(),
        100.0 * kalibre_core::calibrate::IDENTIFIED_REL_STD,
        kalibre_core::calibrate::CONVERGED_SHIFT_STDS,
        100.0 * kalibre_core::calibrate::SETTLED_REL_SHIFT
    );
    // The uncertainty leaves out what equal bounds fix; said, so none seems forgotten.
    let fixed: Vec<&str> = (report.best.params.0.iter())
        .map(|(name, _)| name.as_str())
        .filter(|name| u.iter().all(|p| p.name != *name))
        .collect();
    if !fixed.is_empty() {
        let why = match style {
            Style::Hall => "equal bounds: given, not calibrated",
            // model.toml's candidate effects are held where they are absent.
            Style::Generic { .. } => {
                "equal bounds, or a candidate effect held absent: not calibrated"
            }
        };
        println!("  {:<28} {} ({why})", "fixed", fixed.join(", "));
    }
    print_numerical_checks(report);
    if let Some(src) = report.uncertainty_slopes {
        println!("  {:<28} {}", "slopes of the spreads", src.describe());
    }
    if let Some(note) = repeated_residual_note(report, style) {
        println!("  {:<28} {note}", "model error");
    }
    if !poor.is_empty() {
        const SHOWN: usize = 8;
        let more = poor.len().saturating_sub(SHOWN);
        println!(
            "  {:<28} {}{}",
            "poorly identified",
            poor[..poor.len().min(SHOWN)].join(", "),
            if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            }
        );
    }
}

/// The report's note on a residual that repeats at the same outputs, in a model of your
/// own's words: its outputs and scenarios, and no `kalibre diagnose`, which needs a hall.
fn repeated_residual_note(report: &Report, style: Style) -> Option<String> {
    match style {
        Style::Hall => report.repeated_residual_note(),
        Style::Generic { .. } => {
            let icc = report
                .residual_icc
                .filter(|r| *r > kalibre_core::calibrate::REPEATED_RESIDUAL_ICC)?;
            Some(format!(
                "{:.0}% of the residual repeats at the same outputs in every scenario: the \
                 model misses something its parameters cannot absorb, or the fit has not \
                 finished (more --iterations, or --polish N on the model itself), and the \
                 values may be off by more than their spreads",
                100.0 * icc
            ))
        }
    }
}

/// What the model's numerical variants (finer grids) changed at the best run, and the
/// largest move of a parameter they cause.
fn print_numerical_checks(report: &Report) {
    if report.numerical_checks.is_empty() {
        return;
    }
    let changes: Vec<String> = report
        .numerical_checks
        .iter()
        .map(|c| c.describe())
        .collect();
    let largest = report
        .uncertainty
        .iter()
        .filter_map(|p| p.rel_numerical().map(|n| (n, &p.name)))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    println!(
        "  {:<28} {}{}",
        "numerics (at the best run)",
        changes.join("; "),
        largest.map_or(String::new(), |(n, name)| format!(
            "; largest move: {name} {:.1}%",
            100.0 * n
        ))
    );
    let weighed: Vec<(&str, &str, f64)> = report
        .residuals
        .iter()
        .filter_map(|r| {
            r.weight
                .map(|w| (r.sensor.as_str(), r.snapshot.as_str(), w))
        })
        .collect();
    if let Some(lowest) = weighed.iter().min_by(|a, b| a.2.total_cmp(&b.2)) {
        println!(
            "  {:<28} {} of {} readings count less than half (the grid moves them more than the noise); lowest: {} in {} ({:.2})",
            "grid weighting (polish)",
            weighed.iter().filter(|w| w.2 < 0.5).count(),
            weighed.len(),
            lowest.0,
            lowest.1,
            lowest.2
        );
    }
}

/// Calibrated parameters the data would move beyond the bound they sit at: the box, not
/// the iterations, holds them (a summary line), or nothing.
pub(super) fn held_at_bounds(report: &Report, space: &kalibre_core::ParamSpace) -> Option<String> {
    let held: Vec<String> = (report.uncertainty.iter())
        .filter_map(|u| {
            let p = space.params().iter().find(|p| p.name == u.name)?;
            // A settled value at its bound is where the data put it.
            let shift = u.shift.filter(|_| !u.settled())?;
            let tol = 1e-9 * (p.upper - p.lower);
            let (side, bound) = if u.value >= p.upper - tol && shift > 0.0 {
                ("upper", p.upper)
            } else if u.value <= p.lower + tol && shift < 0.0 {
                ("lower", p.lower)
            } else {
                return None;
            };
            Some(format!(
                "{} at its {side} bound {} (the data point to {})",
                u.name,
                kalibre_core::number(bound),
                super::super::significant(u.value + shift, 4)
            ))
        })
        .collect();
    (!held.is_empty()).then(|| {
        format!(
            "  {:<28} {}: the range, not the iterations, stops it; widen it in model.toml if \
             such a value is plausible (a candidate effect may also explain it)",
            "held at a bound",
            held.join(", ")
        )
    })
}

/// What the summary of a hall's calibration adds: the rise prior at the best point, the
/// server intakes there, and where each effect of a kind the hall has more than once acts
/// (`kalibre_dc::report::effect_locations`), so that `rack_recirculation#2/fraction`
/// reads with its rack.
pub(super) struct HallFacts<'a> {
    pub penalty: &'a kalibre_dc::surrogate::PenaltyReport,
    pub intakes: Option<&'a Intakes>,
    pub locations: &'a [(String, String)],
}

/// The end-of-run summary table.
pub(super) fn print_summary(
    report: &Report,
    wall_s: f64,
    style: Style,
    hall: Option<HallFacts>,
    fluctuation: Option<&str>,
    failed_at_bounds: Option<&str>,
) {
    let fmt_c = |v| style.error(v);
    println!();
    println!("calibration summary");
    match style {
        Style::Generic { scaled: false } => println!(
            "  {:<28} mean absolute error over every measured output and scenario, in the \
             outputs' units",
            "MAE"
        ),
        Style::Generic { scaled: true } => println!(
            "  {:<28} mean absolute error over every measured output and scenario, each \
             divided by its measurement's sd",
            "MAE"
        ),
        Style::Hall => {}
    }
    println!(
        "  {:<28} {}",
        "initial MAE",
        report.initial.mae_c.map_or_else(
            || "- (a run at the initial parameters failed)".to_string(),
            |m| fmt_c(Some(m))
        )
    );
    println!(
        "  {:<28} {} (found in {})",
        "best MAE",
        fmt_c(Some(report.best.mae_c)),
        report.best_found_in()
    );
    println!("  {:<28} {}", "best RMSE", fmt_c(Some(report.best.rmse_c)));
    println!(
        "  {:<28} {}",
        "best max abs error",
        fmt_c(Some(report.best.max_abs_c))
    );
    if let Some(rec) = report
        .history
        .iter()
        .find(|h| h.iteration == report.best.iteration)
    {
        for (group, e) in rec.per_group.iter().filter(|_| style == Style::Hall) {
            println!(
                "  {:<28} {}",
                format!("best MAE, {group} aisle"),
                fmt_c(Some(e.mae_c))
            );
        }
    }
    // With nothing in the journal at the start, a run read back is a point this
    // calibration asked for again, not an earlier calibration's.
    let fresh = report.journal.as_ref().is_none_or(|j| j.loaded == 0);
    let cached = if fresh && report.runs.cached > 0 {
        "asked for again and read back"
    } else {
        "from the journal"
    };
    println!(
        "  {:<28} {} ({} new, {} {cached}, {} failed)",
        "model runs", report.runs.total, report.runs.new, report.runs.cached, report.runs.failed
    );
    println!("  {:<28} {}", "stopped", report.stop_reason);
    println!(
        "  {:<28} {}",
        "likelihood",
        kalibre_dc::report::likelihood_text(report)
    );
    print_uncertainty(report, style);
    let (penalty, intakes) = (
        hall.as_ref().map(|h| h.penalty),
        hall.as_ref().and_then(|h| h.intakes),
    );
    if let Some(line) = intakes.and_then(intakes_line) {
        println!("  {:<28} {line}", "server intakes (model)");
    }
    if let Some(line) = fluctuation {
        println!("  {:<28} {line}", "OpenFOAM probe fluctuation");
    }
    println!("  {:<28} {wall_s:.1} s", "wall time");
    if let Some(penalty) = penalty.filter(|p| !p.violations.is_empty()) {
        // Which alpha, the rise it gives and the bound: what to check, and the range that
        // would hold it.
        let worst: Vec<String> = penalty
            .violations
            .iter()
            .take(3)
            .map(|v| {
                let side = match v.bound {
                    kalibre_dc::surrogate::RiseBound::Below => "below",
                    kalibre_dc::surrogate::RiseBound::Above => "above",
                };
                format!(
                    "{} = {:.4} cfm/W gives {} server(s) a rise of {:.1} K, {side} the {}-{} K range",
                    v.source, v.alpha_cfm_per_w, v.servers, v.rise_c, penalty.range_c[0], penalty.range_c[1]
                )
            })
            .collect();
        let servers: usize = penalty.violations.iter().map(|v| v.servers).sum();
        println!(
            "  note: the temperature-rise prior binds at the best parameters for {servers} \
             server(s): a prior-data conflict ({}); if that rise is real, widen --rise-range",
            worst.join("; ")
        );
    }
    if report.runs.failed > 0 {
        // A failed run teaches the surrogate nothing: where failures cluster (often near
        // a corner of the box, or the truth) the loop searches blind, and the fit can be
        // poor for that reason, not the model's form.
        println!(
            "  note: {} of {} model runs failed (each one's reason is in runs.jsonl); the \
             loop learned from the rest, so a poor fit may be the failures' doing. Fix what \
             failed and calibrate again into this --out: failed runs run again (unless \
             --replay-failed), the rest are replayed{}",
            report.runs.failed,
            report.runs.total,
            failed_at_bounds.map_or(String::new(), |c| format!("; {c}"))
        );
    }
    for text in [
        kalibre_dc::report::passed_over_text(report),
        kalibre_dc::report::weighted_best_text(report, |m| style.error(Some(m))),
    ]
    .into_iter()
    .flatten()
    {
        println!("  note: {text}");
    }
    if report.settings.robust_nu.is_some() && report.settings.polish_iterations == 0 {
        println!(
            "  note: the Student-t likelihood weighs residuals in the polish steps, and none ran \
             (--polish 0, or more than 64 parameters): only the reported uncertainty used it"
        );
    }
    println!("  best parameters:");
    let locations = hall.as_ref().map_or(&[][..], |h| h.locations);
    for (name, value) in &report.best.params.0 {
        let label = kalibre_dc::report::param_label(name, locations);
        println!("    {label:<30} {value:.5}");
    }
}

/// Each snapshot's server intakes at the best parameters, and the cold-aisle sensor the
/// model reads coldest against the measurements (if any).
pub(super) struct Intakes {
    pub checks: Vec<(String, kalibre_dc::sim::InletCheck)>,
    pub under_read: Option<(String, f64)>,
}

/// The snapshot with the least setpoint headroom, in words: its hottest intake, the
/// headroom, and the headroom less the misfit.
fn intakes_line(i: &Intakes) -> Option<String> {
    let (label, check, room) = i
        .checks
        .iter()
        .filter_map(|(l, c)| kalibre_dc::sim::setpoint_headroom_c(c).map(|r| (l, c, r)))
        .min_by(|a, b| a.2.total_cmp(&b.2))?;
    let hottest = check.hottest.first()?;
    let misfit = i.under_read.as_ref().map_or(String::new(), |(s, m)| {
        format!(
            "; less the {:.2} C the model under-reads {s}: {:.2} C",
            -m,
            room + m
        )
    });
    Some(format!(
        "hottest {:.1} C ({} in {label}, {} of {} above {:.0} C); setpoint headroom {room:.2} C{misfit} (report.html)",
        hottest.intake_c, hottest.server, check.above_limit, check.servers, check.limit_c
    ))
}

/// A journal holding a better point than this calibration reached (it stopped sooner than
/// the calibration that wrote the journal): said on stderr, since `report.json` now holds
/// the worse answer.
pub(super) fn warn_unreached(journal: &std::path::Path, report: &Report, style: Style) {
    let Some(u) = &report.unreached else {
        return;
    };
    let Some(best) = u.best.as_ref().filter(|b| b.score < report.best.score) else {
        return;
    };
    let (theirs, ours) = (
        style.error(Some(best.mae_c)),
        style.error(Some(report.best.mae_c)),
    );
    eprintln!(
        "kalibre: warning: {}: {} journaled run(s) of this model were not used by this \
         calibration (it stopped: {}); among them, line {} has MAE {}, better than \
         its best, {}. They are kept: the calibration that made them (its budget, \
         --max-runs, --iterations or --max-wall-s, where this one stopped early; or its \
         seed, settings or initial values, where those changed since) replays them \
         without running the model again{}",
        journal.display(),
        u.runs,
        report.stop_reason,
        best.line,
        theirs,
        if theirs == ours {
            // Equal to the printed digits: the difference, so that "better" is seen.
            format!("{ours} (by {:.1e})", report.best.mae_c - best.mae_c)
        } else {
            ours
        },
        match style {
            // A diagnosis steps each calibrated parameter from the calibration's best,
            // which can land lower when the loop had not converged.
            Style::Generic { .. } => {
                "; a diagnosis's step from the best may be one, which says the loop had \
                 not converged: more --iterations, or --polish N, would get there"
            }
            Style::Hall => "",
        }
    );
}
