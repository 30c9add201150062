//! `kalibre synth`: synthetic halls with a hidden truth.

use std::path::PathBuf;

use clap::Args;
use kalibre_dc::synth::{self, Preset, SynthOptions};

use super::{CliError, CliResult};

/// Options of `kalibre synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Hall preset: `demo` (~300 servers, 4 CRACs, 24 sensors), `hall-a` or `hall-b`
    /// (thousands of servers, 8-10 CRACs, 50-70 sensors, hot-aisle containment).
    #[arg(long, default_value = "demo")]
    preset: String,
    /// Seed of every random choice (geometry, true alphas, powers, noise).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Hide an effect in the truth: `KIND[:key=value,...]`, e.g. `bypass:fraction=0.1,behind_rack=A03`.
    /// Repeatable. Kinds: containment_leakage, bypass, crac_supply_offset, rack_recirculation.
    #[arg(long = "effect", value_name = "KIND[:key=value,...]")]
    effects: Vec<String>,
    /// Standard deviation of the Gaussian sensor noise (C).
    #[arg(long = "noise-c", default_value_t = 0.2)]
    noise_c: f64,
    /// Number of snapshots (operating states varying fan speeds, setpoints and powers).
    #[arg(long, default_value_t = 3)]
    snapshots: usize,
}

/// Runs `kalibre synth`.
pub fn run(args: SynthArgs) -> CliResult {
    let preset: Preset = args
        .preset
        .parse()
        .map_err(|e| CliError::Input(format!("--preset: {e}")))?;
    if !(args.noise_c.is_finite() && args.noise_c >= 0.0) {
        return Err(CliError::Input(format!(
            "--noise-c: expected a finite value >= 0, got {}",
            args.noise_c
        )));
    }
    if args.snapshots == 0 {
        return Err(CliError::Input("--snapshots: expected at least 1".into()));
    }
    let effects = args
        .effects
        .iter()
        .map(|e| synth::parse_effect_arg(e))
        .collect::<Result<Vec<_>, _>>()?;
    for (arg, e) in args.effects.iter().zip(&effects) {
        refuse_inert(arg, e)?;
    }
    let mut options = SynthOptions::new(preset, args.seed)
        .with_noise_c(args.noise_c)
        .with_snapshots(args.snapshots);
    for e in effects {
        options = options.with_effect(e);
    }
    check_out_dir(&args.out, &[])?;
    let out = synth::generate(&options)?;
    synth::write_dir(&args.out, &out)?;
    println!(
        "wrote {}: hall `{}` ({} servers, {} CRACs, {} sensors), {} snapshot{}, truth.json",
        args.out.display(),
        out.hall.name,
        out.hall.server_count(),
        out.hall.cracs.len(),
        out.hall.sensors.len(),
        out.snapshots.len(),
        if out.snapshots.len() == 1 { "" } else { "s" }
    );
    Ok(())
}

/// Each built-in kind's size and its value when not given (`None`: a non-zero default).
const SIZES: [(&str, &str, Option<f64>); 4] = [
    ("crac_supply_offset", "offset_c", Some(0.0)),
    ("bypass", "fraction", None),
    ("rack_recirculation", "fraction", None),
    ("containment_leakage", "open_fraction", None),
];

/// Refuses a hidden effect of size 0: its measurements would be the clean hall's while
/// truth.json lists it, and a diagnosis that finds nothing there would look wrong.
pub(super) fn refuse_inert(arg: &str, effect: &kalibre_dc::hall::EffectSpec) -> CliResult {
    let Some((_, field, default)) = SIZES.iter().find(|(k, _, _)| *k == effect.kind) else {
        return Ok(());
    };
    // A value that is not a number is the effect's own check to refuse, by type.
    let size = match effect.fields.get(*field) {
        Some(v) => v.as_f64(),
        None => *default,
    };
    if size == Some(0.0) {
        return Err(CliError::Input(format!(
            "--effect `{arg}`: {field} is 0{}, which hides nothing (the measurements would \
             be the clean hall's); give a size, e.g. `{}:{field}={}`",
            if effect.fields.contains_key(*field) {
                ""
            } else {
                " (its default)"
            },
            effect.kind,
            if *field == "offset_c" { "-1.5" } else { "0.1" },
        )));
    }
    Ok(())
}

/// Refuses an `--out` that holds a hall or measurements `synth` did not write (no
/// `truth.json` of kalibre's beside them: a user's own files, or another tool's dataset
/// with a truth of its own), or any of `also`, rather than replace them; an earlier
/// synthetic hall is replaced, as asked.
pub(super) fn check_out_dir(out: &std::path::Path, also: &[&str]) -> CliResult {
    super::out_dir::check_is_dir(out)?;
    let truth = out.join("truth.json");
    let ours = std::fs::read(&truth)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<serde_json::Value>(&bytes).ok())
        .is_some_and(|v| v["schema"] == kalibre_dc::synth::TRUTH_SCHEMA);
    if ours {
        return Ok(());
    }
    let theirs = ["hall.json", "snapshots.csv", "truth.json"]
        .iter()
        .chain(also)
        .find(|name| out.join(name).exists());
    let not_ours = format!(
        "a truth.json that is not kalibre's (no `schema` {})",
        kalibre_dc::synth::TRUTH_SCHEMA
    );
    let what = match theirs {
        None => return Ok(()),
        Some(&"truth.json") => not_ours,
        Some(name) if truth.exists() => format!("{name} with {not_ours} beside it"),
        Some(name) => format!("{name} with no truth.json beside it"),
    };
    Err(CliError::Input(format!(
        "--out {}: holds {what}, so not a synthetic hall kalibre wrote; kalibre does not \
         replace it: give another --out",
        out.display(),
    )))
}
