//! `kalibre demo`: the whole story on a synthetic `demo` hall whose measurements hide an
//! effect the model lacks: calibrate alpha (the error stalls), diagnose (the effect is
//! named), add it, recalibrate (the error falls), and write the report.

use std::path::PathBuf;

use clap::Args;
use kalibre_dc::diagnosis::{hypothesis_flags, worst_sensors};
use kalibre_dc::hall::{EffectSpec, Hall};
use kalibre_dc::sim::RackHeat;
use kalibre_dc::story::{run_story, StoryEvent, StoryOutcome, StoryReport, StorySettings};
use kalibre_dc::synth::{self, parse_effect_arg, Preset, SynthOptions};

use super::diagnose::{sensor_line, warming_racks};
use super::{with_threads, CliError, CliResult};

/// The effect hidden in the demo's truth when `--effect` is not given.
pub const DEFAULT_EFFECT: &str = "rack_recirculation";

/// The demo's placement and size of each built-in kind: strong enough to stall an
/// alpha-only calibration well above the noise.
const EFFECT_PRESETS: [(&str, &str); 4] = [
    (
        "rack_recirculation",
        "rack_recirculation:rack=A05,fraction=0.3",
    ),
    ("bypass", "bypass:behind_rack=A03,fraction=0.2"),
    (
        "containment_leakage",
        "containment_leakage:open_fraction=0.3",
    ),
    ("crac_supply_offset", "crac_supply_offset:offset_c=-1.5"),
];

/// Measurement noise of the demo (C).
const DEMO_NOISE_C: f64 = 0.15;

/// Options of `kalibre demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Output directory: the synthetic hall (hall.json, snapshots.csv, truth.json),
    /// story.json, hall-with-effect.json, step-N/report.json, diagnosis-N.json, report.html.
    #[arg(long, default_value = "kalibre-demo")]
    out: PathBuf,
    /// Seed of the synthetic hall and of every calibration.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The effect hidden in the measurements: a kind (`rack_recirculation`, `bypass`,
    /// `containment_leakage`, `crac_supply_offset`) at the demo's placement, a full entry
    /// `KIND:key=value,...`, or `none` for a clean truth.
    #[arg(long, default_value = DEFAULT_EFFECT, value_name = "KIND")]
    effect: String,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
}

/// The hidden effect of `--effect`.
fn hidden_effect(arg: &str) -> CliResult<Option<EffectSpec>> {
    if arg == "none" {
        return Ok(None);
    }
    let full = EFFECT_PRESETS
        .iter()
        .find(|(kind, _)| *kind == arg)
        .map_or(arg, |(_, entry)| entry);
    let effect = parse_effect_arg(full).map_err(|e| CliError::Input(e.to_string()))?;
    // As `synth` does: a size-0 effect would leave the story nothing to find.
    super::synth::refuse_inert(arg, &effect)?;
    Ok(Some(effect))
}

fn entry_json(e: &EffectSpec) -> String {
    serde_json::to_string(e).unwrap_or_default()
}

/// Removes what an earlier demo in `out` wrote that this one may not write again
/// (`step-N/report.json`, `diagnosis-N.json`, `hall-with-effect.json`) or writes only at
/// its end (`story.json`, `report.html`), so that no file beside the new story belongs
/// to the old one, even when this one is interrupted. Only those names are touched.
fn clear_previous_story(out: &std::path::Path) -> CliResult {
    let Ok(entries) = std::fs::read_dir(out) else {
        return Ok(()); // a new directory
    };
    let numbered = |name: &str, prefix: &str, suffix: &str| {
        name.strip_prefix(prefix)
            .and_then(|r| r.strip_suffix(suffix))
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    };
    let remove = |path: &std::path::Path| {
        std::fs::remove_file(path).map_err(|e| {
            CliError::Input(format!(
                "--out: {}: an earlier demo's file could not be removed: {e}",
                path.display()
            ))
        })
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let path = entry.path();
        let whole_story = ["hall-with-effect.json", "story.json", "report.html"];
        if whole_story.contains(&name.as_str()) || numbered(&name, "diagnosis-", ".json") {
            remove(&path)?;
        } else if numbered(&name, "step-", "") && path.is_dir() {
            let report = path.join("report.json");
            if report.exists() {
                remove(&report)?;
            }
            // Left in place when it holds anything else (not the demo's).
            let _ = std::fs::remove_dir(&path);
        }
    }
    Ok(())
}

/// Runs `kalibre demo`.
pub fn run(args: DemoArgs) -> CliResult {
    let hidden = hidden_effect(&args.effect)?;
    let mut opts = SynthOptions::new(Preset::Demo, args.seed).with_noise_c(DEMO_NOISE_C);
    if let Some(e) = &hidden {
        opts = opts.with_effect(e.clone());
    }
    super::synth::check_out_dir(
        &args.out,
        &["report.json", "runs.jsonl", "report.html", "story.json"],
    )?;
    let synth = with_threads(args.threads, || synth::generate(&opts))??;
    // Taken once the effect is known to build: bad input leaves no directory behind.
    let _lock = super::out_dir::lock(&args.out, "--out", "demo")?;
    clear_previous_story(&args.out)?;
    synth::write_dir(&args.out, &synth)?;
    let hall = &synth.hall;
    let reference = synth.truth.reference.clone();
    println!(
        "kalibre demo: synthetic hall `{}` ({} servers, {} CRACs, {} sensors, {} snapshots, noise {DEMO_NOISE_C} C)",
        hall.name,
        hall.servers().count(),
        hall.cracs.len(),
        hall.sensors.len(),
        synth.snapshots.len()
    );
    match synth.truth.hidden_effects.first() {
        Some(h) => println!(
            "hidden in the measurements (the model is not told): {}",
            entry_json(&h.resolved)
        ),
        None => println!("nothing hidden in the measurements: a clean truth"),
    }
    if let Some(r) = &reference {
        println!(
            "a complete model at the true parameters reaches an MAE of {:.3} C (noise alone: {:.3} C)",
            r.model_at_truth_mae_c, r.noise_only_mae_c
        );
    }
    println!(
        "wrote {}/{{hall.json, snapshots.csv, truth.json}}",
        args.out.display()
    );
    // The truth's server intakes, in the snapshots' order (each truth snapshot is
    // labelled as its measured one).
    let true_intakes_c = synth
        .snapshots
        .iter()
        .map(|snap| {
            synth
                .truth
                .snapshots
                .iter()
                .find(|t| t.label == snap.state.label)
                .and_then(|t| t.server_intake_c.clone())
        })
        .collect::<Option<Vec<_>>>();
    let settings = StorySettings {
        reference_mae_c: reference.as_ref().map(|r| r.model_at_truth_mae_c),
        true_intakes_c,
        calibration: kalibre_dc::calibration::HallCalibrationSettings {
            core: kalibre_core::Settings {
                seed: args.seed,
                ..kalibre_dc::calibration::HallCalibrationSettings::loop_defaults()
            },
            ..Default::default()
        },
        ..StorySettings::default()
    };
    let floor = settings.reference_mae_c;
    let observer = |e: &StoryEvent<'_>| print_event(hall, floor, e);
    let story = with_threads(args.threads, || {
        run_story(
            hall,
            &synth.snapshots,
            &settings,
            Some(&args.out),
            &observer,
        )
    })??;
    print_summary(&story);
    if let (Some(h), Some(added)) = (synth.truth.hidden_effects.first(), story.added.first()) {
        if added.kind == h.resolved.kind {
            println!("the diagnosis named the hidden kind ({})", h.resolved.kind);
        } else {
            println!(
                "the diagnosis named {} but the hidden effect is {}",
                added.kind, h.resolved.kind
            );
        }
    }
    // Steps count calibrations, as report.html and the step-K/ folders do; each
    // diagnosis goes with the step it diagnoses.
    let dirs: Vec<String> = (1..=story.steps.len())
        .map(|k| format!("step-{k}/"))
        .collect();
    println!(
        "wrote {}, {}; each step's report.json in {}",
        args.out.join("story.json").display(),
        args.out.join("report.html").display(),
        dirs.join(", ")
    );
    Ok(())
}

/// Prints each step as it happens.
fn print_event(hall: &Hall, floor: Option<f64>, e: &StoryEvent<'_>) {
    match e {
        StoryEvent::CalibrationStarted { name, index } => {
            println!("\nstep {}: {name}", index + 1)
        }
        StoryEvent::CalibrationDone { step, index } => {
            // After a diagnosis the start is the model run with the entry added (the
            // diagnosis's predicted MAE was a linear estimate of it).
            let start = if *index > 0 {
                " with the entry added, before recalibrating,"
            } else {
                ""
            };
            println!(
                "  MAE {}{start} -> {:.3} C ({} model runs, {:.1} s)",
                step.mae_before_c
                    .map_or("-".into(), |m| format!("{m:.3} C")),
                step.mae_after_c,
                step.model_runs,
                step.wall_s
            );
            if let Some(f) = floor {
                println!(
                    "  {:.1} times the {f:.3} C a complete model reaches{}",
                    step.mae_after_c / f,
                    if step.mae_after_c > 2.0 * f {
                        ": the fit stalls, something is missing"
                    } else if step.mae_after_c < f {
                        " (below it: fitted parameters also take in some of the noise)"
                    } else {
                        ""
                    }
                );
            }
            if let Some(i) = &step.intakes {
                println!(
                    "  where no sensor measures: the servers' intake air is {:.2} C from the truth on average, \
                     at most {:+.1} C ({} in {})",
                    i.mae_c, i.worst_error_c, i.worst_server, i.worst_snapshot,
                );
            }
        }
        StoryEvent::DiagnosisStarted { after_step } => println!(
            "\ndiagnosis after step {}: diagnose where the calibrated model fails",
            after_step + 1
        ),
        StoryEvent::DiagnosisDone {
            step,
            calibration,
            heat,
            ..
        } => {
            print_where(hall, calibration, heat);
            println!(
                "  missing effects, best first: the significant ones, then the others, each in \
                 order of `BIC`, the change of the Bayesian information criterion (lower is \
                 better supported) (MAE now {:.3} C, {:.1} s):",
                step.mae_c, step.wall_s
            );
            let top = step.top_significant();
            for h in step.hypotheses.iter().take(5) {
                let flags =
                    hypothesis_flags(h.significant, false, h.inert, h.identifiable, h.in_range);
                println!(
                    "    {:<46} explains {:>3.0}%  predicted MAE {:.3} C  BIC {}  {flags}",
                    h.name,
                    100.0 * h.explained_fraction,
                    h.predicted_mae_c,
                    h.delta_bic.map_or("-".into(), |b| format!("{b:+.1}"))
                );
                if let Some(note) = step.alternative_note(h) {
                    println!("      {note}");
                }
            }
            match top.and_then(|t| t.entry.as_ref()) {
                Some(entry) => println!(
                    "  suggested entry for hall.json \"effects\": {}",
                    entry_json(entry)
                ),
                None => println!("  no significant missing effect: nothing to add"),
            }
        }
        StoryEvent::DiagnosisFailed { error, .. } => {
            println!("  the diagnosis failed: {error}")
        }
        StoryEvent::EffectAdded { entry, .. } => {
            println!("  added {} (hall-with-effect.json)", entry_json(entry))
        }
        _ => {}
    }
}

/// The worst sensors, in words, each with the racks that warm it in the model's flow
/// (`heat`).
fn print_where(hall: &Hall, report: &kalibre_core::calibrate::Report, heat: &[RackHeat]) {
    println!("  worst sensors (mean over the snapshots):");
    for (sensor, mean) in worst_sensors(&report.residuals).iter().take(3) {
        println!("    {}", sensor_line(hall, sensor, *mean));
        println!("      {}", warming_racks(heat, sensor, *mean));
    }
}

/// The table of steps: calibrations and diagnoses with their errors, runs and times.
fn print_summary(story: &StoryReport) {
    // (step, what, MAE before, MAE after, model runs, wall s): steps count calibrations,
    // as report.html and the step-K/ folders do; a diagnosis row follows its step.
    let mut rows: Vec<[String; 6]> = Vec::new();
    for (i, s) in story.steps.iter().enumerate() {
        rows.push([
            (i + 1).to_string(),
            s.name.clone(),
            s.mae_before_c.map_or("-".into(), |m| format!("{m:.3}")),
            format!("{:.3}", s.mae_after_c),
            s.model_runs.to_string(),
            format!("{:.1}", s.wall_s),
        ]);
        if let Some(d) = story.diagnoses.iter().find(|d| d.after_step == i) {
            let (what, predicted) = match d.top_significant() {
                Some(t) => (
                    format!("diagnose: {}", t.name),
                    format!("{:.3}*", t.predicted_mae_c),
                ),
                None => ("diagnose: no significant missing effect".into(), "-".into()),
            };
            rows.push([
                String::new(),
                what,
                format!("{:.3}", d.mae_c),
                predicted,
                "-".into(),
                format!("{:.1}", d.wall_s),
            ]);
        }
    }
    if story.final_diagnosis_error.is_some() {
        rows.push([
            String::new(),
            "diagnose: failed (see above)".into(),
            "-".into(),
            "-".into(),
            "-".into(),
            "-".into(),
        ]);
    }
    let w = rows.iter().map(|r| r[1].len()).max().unwrap_or(0);
    println!("\nsummary");
    println!(
        "  {:<4} {:<w$} {:>10} {:>10} {:>6} {:>7}",
        "step", "", "MAE before", "MAE after", "runs", "wall s"
    );
    for r in &rows {
        println!(
            "  {:<4} {:<w$} {:>10} {:>10} {:>6} {:>7}",
            r[0], r[1], r[2], r[3], r[4], r[5]
        );
    }
    println!(
        "  (MAE in C; * predicted by the diagnosis)   total wall time {:.1} s",
        story.wall_s
    );
    match story.outcome {
        StoryOutcome::NothingSignificant => {
            println!("the diagnosis found no significant missing effect; nothing was added")
        }
        _ => println!("{}", kalibre_dc::report::outcome_text(story)),
    }
}
