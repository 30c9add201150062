//! A diagnosis of a model of your own, in words and JSON.

use std::path::Path;

use kalibre_core::diagnose::{Diagnosis, HypothesisResult, Refit, CLOSE_ALTERNATIVE_BIC};
use kalibre_core::external::CommandModelConfig;
use kalibre_core::Model;

use super::super::super::calibrate::generic::errors_in;
use super::super::super::significant;
use super::{Checked, Floor, Outcome};

/// Parameters by name, as a JSON object.
fn params_json(params: &[(String, f64)]) -> serde_json::Value {
    let map: serde_json::Map<String, serde_json::Value> = (params.iter())
        .map(|(n, v)| (n.clone(), serde_json::json!(v)))
        .collect();
    serde_json::Value::Object(map)
}

impl Checked {
    fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "candidate": self.name,
            "params": params_json(&self.params),
            "mae": self.mae.as_ref().ok(),
            "failed": self.mae.as_ref().err(),
            "refuted": self.refuted,
            "from_refit": self.from_refit,
            "clamped": self.clamped,
        })
    }

    /// In words, beside `mae_now` (the calibrated point's) and `baseline` (what it had to
    /// read below).
    fn line(&self, mae_now: f64, baseline: f64, unit: &str) -> String {
        let against = if baseline < mae_now {
            format!(
                "the calibrated parameters alone, refit and run ({}{unit})",
                significant(baseline, 4)
            )
        } else {
            format!("now ({}{unit})", significant(mae_now, 4))
        };
        match &self.mae {
            Ok(m) if self.from_refit => format!(
                "its refit's best run (the calibrated parameters moved with it) reads MAE \
                 {}{unit}, against {against}",
                significant(*m, 4)
            ),
            Ok(m) if self.refuted && !self.clamped.is_empty() => format!(
                "the model run there reads MAE {}{unit}, no better than {against}, so it is \
                 not named; but the fit moved {} beyond its bounds, clamped there for the \
                 run: with a wider range it may read otherwise",
                significant(*m, 4),
                self.clamped.join(", ")
            ),
            Ok(m) if self.refuted => format!(
                "the model run there reads MAE {}{unit}, no better than {against}: the \
                 linearisation misleads, so it is not named",
                significant(*m, 4)
            ),
            Ok(m) => format!(
                "the model run there (the calibrated parameters moved with it) reads MAE \
                 {}{unit}, against {against}",
                significant(*m, 4)
            ),
            Err(why) => format!("the model could not run there ({why}): not checked"),
        }
    }
}

impl Floor {
    fn to_json(&self) -> serde_json::Value {
        let beyond: Vec<serde_json::Value> = (self.beyond.iter())
            .map(|(n, wanted, bound)| {
                serde_json::json!({ "param": n, "refit_to": wanted, "bound": bound })
            })
            .collect();
        serde_json::json!({
            "params": params_json(&self.params),
            "mae": self.mae.as_ref().ok(),
            "failed": self.mae.as_ref().err(),
            "beyond_bounds": beyond,
        })
    }
}

/// The diagnosis as JSON (`--json`).
pub(super) fn json(
    o: &Outcome<'_>,
    cfg: &CommandModelConfig,
    config: &Path,
    scaled: bool,
) -> serde_json::Value {
    serde_json::json!({
        "model": { "kind": "command", "config": config.display().to_string(),
                   "fingerprint": cfg.command.fingerprint(),
                   "errors_in": errors_in(scaled) },
        "diagnosis": o.d,
        // The diagnosis fits each candidate's change from absent; the model takes the
        // value.
        "fitted_values": fitted_values_json(o, cfg),
        "not_tried": o.not_tried.iter()
            .map(|(name, why)| serde_json::json!({ "candidate": name, "reason": why }))
            .collect::<Vec<_>>(),
        "floor": o.floor.as_ref().map(Floor::to_json),
        "refits": o.refits,
        "checked": o.checked.iter().map(Checked::to_json).collect::<Vec<_>>(),
        "baseline_mae": o.baseline,
        "runs": { "new": o.runs.0, "from_journal": o.runs.1 },
        "written": o.written,
    })
}

/// Each hypothesis's fitted values as the model takes them (the absent value plus the
/// fitted change, or its refit's best run), by hypothesis and parameter name.
fn fitted_values_json(o: &Outcome<'_>, cfg: &CommandModelConfig) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    for h in &o.d.hypotheses {
        let Some(effect) = cfg.candidates.iter().find(|c| c.name == h.name) else {
            continue;
        };
        let values: serde_json::Map<String, serde_json::Value> = (fitted_values(o, effect, h))
            .into_iter()
            .map(|(n, v)| (n, serde_json::json!(v)))
            .collect();
        out.insert(h.name.clone(), serde_json::Value::Object(values));
    }
    serde_json::Value::Object(out)
}

/// A hypothesis's values as the model takes them: its refit's best run where it has one,
/// else the absent value plus the fitted change.
fn fitted_values(
    o: &Outcome<'_>,
    effect: &kalibre_core::diagnose::CandidateEffect,
    h: &HypothesisResult,
) -> Vec<(String, f64)> {
    let best = (o.refits.iter().find(|r| r.name == h.name)).and_then(|r| r.best());
    (effect.params.iter())
        .map(|p| {
            let value = match best {
                Some(step) => step.values.get(&p.name),
                None => None,
            };
            let value = value.unwrap_or(p.absent + h.fitted.get(&p.name).unwrap_or(0.0));
            (p.name.clone(), value)
        })
        .collect()
}

/// The diagnosis in words: each candidate's verdict, how to add the one named, and the
/// outputs none explains.
pub(super) fn text(
    o: &Outcome<'_>,
    cfg: &CommandModelConfig,
    config: &Path,
    scaled: bool,
    (robust_nu, calibration_nu): (Option<f64>, Option<f64>),
) {
    let d = &o.d;
    let unit = if scaled { " sd" } else { "" };
    println!(
        "candidate effects, best first (MAE now {}{unit}; `explains`: the share of the \
         residual, as the ranking weighs the outputs, that the effect removes; `predicted \
         MAE`: linearised, with the calibrated parameters refitted beside it):",
        significant(d.mae, 4)
    );
    println!(
        "  ranked under {}",
        match robust_nu {
            Some(nu) => format!(
                "a Student-t likelihood ({nu} degrees of freedom: a few outputs the model \
                 misses count little; --likelihood gaussian for least squares)"
            ),
            None => "least squares (--likelihood gaussian)".to_string(),
        }
    );
    // The calibrated parameters alone, refitted: a calibration that had not converged
    // shows here, and no candidate earns the difference.
    if let Some(floor) = &o.floor {
        let run = match &floor.mae {
            Ok(m) if *m < d.mae => format!(
                "the model run there reads {}{unit}, which a candidate's own run must beat \
                 to be named",
                significant(*m, 4)
            ),
            Ok(m) => format!(
                "the model run there reads {}{unit}, no better than now, so a candidate's \
                 run must beat the calibrated MAE",
                significant(*m, 4),
            ),
            Err(why) => format!("the model could not run there ({why})"),
        };
        let no_better = floor.mae.as_ref().is_ok_and(|m| *m >= d.mae);
        if floor.beyond.is_empty() && no_better {
            // The run refutes the linearisation, not the calibration: more iterations
            // would not find what the refit promised.
            println!(
                "  refitting the calibrated parameters alone would give MAE {}{unit} \
                 (linearised), but {run}: the linearisation misleads there (the model is \
                 not linear over the refit's step), so the predicted MAEs below are \
                 optimistic by as much",
                significant(d.refit_mae, 4)
            );
        } else if floor.beyond.is_empty() {
            println!(
                "  refitting the calibrated parameters alone would already give MAE {}{unit} \
                 (linearised); {run}: the calibration has not converged, and every predicted \
                 MAE below includes that; more --iterations, or --polish N, settles it",
                significant(d.refit_mae, 4)
            );
        } else {
            let moves: Vec<String> = (floor.beyond.iter())
                .map(|(n, wanted, bound)| {
                    format!(
                        "{n} to {} (its bound is {})",
                        significant(*wanted, 4),
                        kalibre_core::number(*bound)
                    )
                })
                .collect();
            println!(
                "  refitting the calibrated parameters alone would give MAE {}{unit} \
                 (linearised), but it moves {}: the box stopped the calibration there, not \
                 its iterations. Widen that range in model.toml if such a value is plausible; \
                 a candidate may also explain it. Clamped into the box, {run}",
                significant(d.refit_mae, 4),
                moves.join(", ")
            );
        }
    }
    let significant_ones: Vec<&HypothesisResult> = d.significant().collect();
    let undecided = d.undecided();
    if !undecided.is_empty() {
        println!(
            "  no effect decided: {} fit about as well (BIC within {CLOSE_ALTERNATIVE_BIC:.0}), \
             each changing other outputs; the data say something is missing, not which. Add \
             each in turn, calibrate, and keep the one that lowers the error.",
            undecided.join(", ")
        );
    } else if d.hypotheses.is_empty() {
        println!("  no candidate could be tried (below: why)");
    } else if significant_ones.is_empty() {
        println!("  no significant missing effect among the candidates");
    }
    for h in &d.hypotheses {
        let flags = super::super::print::flags(h);
        println!(
            "  {:<32} explains {:>4.0}%  predicted MAE {}{unit}  BIC {:+.1}  {}",
            h.name,
            100.0 * h.explained_fraction,
            significant(h.predicted_mae, 4),
            h.delta_bic,
            flags
        );
        let Some(effect) = cfg.candidates.iter().find(|c| c.name == h.name) else {
            continue;
        };
        // The fit is of the change from absent; the model takes the value.
        let values: Vec<(String, f64, [f64; 2])> = (fitted_values(o, effect, h).into_iter())
            .zip(&effect.params)
            .map(|((n, v), p)| (n, v, [p.lower, p.upper]))
            .collect();
        let fitted: Vec<String> = (values.iter())
            .map(|(n, v, _)| format!("{n} = {}", significant(*v, 4)))
            .collect();
        if !h.in_range {
            let ranges: Vec<String> = (values.iter())
                .map(|(n, _, [lo, hi])| {
                    format!(
                        "{n} in [{}, {}]",
                        kalibre_core::number(*lo),
                        kalibre_core::number(*hi)
                    )
                })
                .collect();
            println!(
                "    fitted {}: outside model.toml's range ({}), which no value of it gives",
                fitted.join(", "),
                ranges.join(", ")
            );
            continue;
        }
        let check = o.checked.iter().find(|c| c.name == h.name);
        let check_line = check.map(|c| c.line(d.mae, o.baseline, unit));
        if h.significant {
            println!("    fitted {}", fitted.join(", "));
            if let Some(line) = &check_line {
                println!("    {line}");
            }
            if !h.identifiable {
                println!("    {}", super::super::print::not_identifiable(h));
            }
            let grouped = effect.params.len() > 1 || effect.name != effect.params[0].name;
            println!(
                "    to add it: in {}, delete `absent`{} from [[params]] {} and give `initial` \
                 (the fitted value is a good start), then calibrate again; the same --out \
                 keeps its journal, whose runs are read back wherever the loop asks for one \
                 again (--write-config FILE writes that model.toml, every parameter starting \
                 where the model ran at the fit)",
                config.display(),
                if grouped { " and `effect`" } else { "" },
                kalibre_core::some_names(
                    &effect
                        .params
                        .iter()
                        .map(|p| format!("`{}`", p.name))
                        .collect::<Vec<_>>()
                )
            );
            if significant_ones
                .first()
                .is_some_and(|best| best.name == h.name)
            {
                super::super::print::print_close_alternatives(d, h);
            }
        } else if let Some(line) = check_line.filter(|_| h.refuted) {
            println!("    fitted {}; {line}", fitted.join(", "));
        } else if undecided.contains(&h.name.as_str()) {
            println!(
                "    undecided (about as good: {}); fitted {}",
                h.ambiguous_with.join(", "),
                fitted.join(", ")
            );
        } else if let Some(output) = &h.carried_by {
            println!(
                "    rests on one output, {output}: without it the others do not prefer it \
                 (a faulty measurement, or the model's own error there, looks the same)"
            );
        }
    }
    print_unexplained(d, scaled, calibration_nu);
    print_refits(o, unit);
    if !o.not_tried.is_empty() {
        println!("\nnot tried:");
        for (name, why) in o.not_tried {
            println!("  {name}: {why}");
        }
    }
}

/// The outputs no candidate explains, in the units the diagnosis weighed them in;
/// `calibration_nu` is the calibration's likelihood, which the advice is about.
fn print_unexplained(d: &Diagnosis, scaled: bool, calibration_nu: Option<f64>) {
    if d.unexplained.is_empty() {
        return;
    }
    let after = match d.significant().next() {
        Some(h) => format!("left with {} added", h.name),
        None => "left with the calibrated parameters refit".to_string(),
    };
    println!(
        "\noutputs no candidate explains (the model's own form there, or a faulty \
         measurement; the ranking counts them little; residuals {after}):"
    );
    let unit = if scaled { " sd" } else { "" };
    for u in &d.unexplained {
        println!(
            "  {:<24} model minus measurement {}{unit} on average, {:.1} noise scales",
            u.output,
            significant(u.mean_residual, 3),
            u.rms_scales
        );
    }
    if calibration_nu.is_none() {
        println!(
            "  to calibrate weighing them down as a Student-t ranking does, add `--likelihood \
             student-t` to `kalibre calibrate`"
        );
    }
}

/// What `--refit` ran: each refit candidate's values and the model's MAE at each run.
fn print_refits(o: &Outcome<'_>, unit: &str) {
    let could = o.refit_asked.min(o.d.hypotheses.len());
    if o.refits.len() < could {
        let why = if o.refits.is_empty() {
            "no candidate could be refit"
        } else {
            "fewer candidates could be refit than --refit asked"
        };
        println!(
            "\n--refit {}: {why}: a refit takes a candidate fitted within its range, moving \
             the outputs and not refuted, and the others are not",
            o.refit_asked
        );
    }
    if o.refits.is_empty() {
        return;
    }
    println!(
        "\nrefit with the model (each run: the effect's value, the model's MAE there; \
         `worse`: not better than the best point before it, so the next step was halved, as \
         after a failed run; the best run is the value to take):"
    );
    for r in &o.refits {
        let steps: Vec<String> = (r.steps.iter())
            .map(|s| {
                let values: Vec<String> = (s.values.0.iter())
                    .map(|(n, v)| format!("{n} = {}", significant(*v, 6)))
                    .collect();
                let read = match (s.mae, &s.failed) {
                    (Some(m), _) if s.accepted => format!("{}{unit}", significant(m, 4)),
                    (Some(m), _) => format!("{}{unit} worse", significant(m, 4)),
                    (None, why) => format!("failed ({})", why.as_deref().unwrap_or("no reason")),
                };
                let held = if s.clamped.is_empty() {
                    String::new()
                } else {
                    format!(" ({} held at its bound)", s.clamped.join(", "))
                };
                format!("{}: {read}{held}", values.join(", "))
            })
            .collect();
        let stopped = (r.stopped.as_ref())
            .map(|w| format!(" (stopped: {w})"))
            .unwrap_or_default();
        println!("  {:<32} {}{stopped}", r.name, steps.join("; "));
        if let Some(note) = refuted_at_bounds(r) {
            println!("  {:<32} {note}", "");
        }
    }
}

/// A refit none of whose runs read better, where some run held calibrated parameters at
/// their bounds: the refutation may be the box's, as for the single check.
fn refuted_at_bounds(r: &Refit) -> Option<String> {
    let ran = r.steps.iter().any(|s| s.mae.is_some());
    if !ran || r.best().is_some() {
        return None;
    }
    let mut held: Vec<&str> = Vec::new();
    for name in r.steps.iter().flat_map(|s| &s.clamped) {
        if !held.contains(&name.as_str()) {
            held.push(name);
        }
    }
    (!held.is_empty()).then(|| {
        format!(
            "no run read better, but the fit moved {} beyond its bounds, held there for the \
             runs: with a wider range it may read otherwise",
            held.join(", ")
        )
    })
}
