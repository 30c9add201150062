//! Subcommands of the `kalibre` tool.

mod calibrate;
mod calibrated_model;
mod demo;
mod diagnose;
mod error;
mod hall_changes;
mod hall_command;
mod inlets;
mod likelihood;
mod openfoam_args;
mod out_dir;
mod own_model;
mod params_file;
mod plausible;
mod same_file;
mod simulate;
mod simulate_command;
mod simulate_openfoam;
mod simulate_own;
mod synth;
mod what_if;

use clap::{Parser, Subcommand};

pub use error::{io_err, CliError, CliResult};

/// kalibre: calibrate a slow simulation model against measurements, with a physics-aware
/// surrogate doing the searching.
#[derive(Debug, Parser)]
#[command(name = "kalibre", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

// `allow_negative_numbers`: `--iterations -1` is then refused as a bad value of that
// flag, not as an unknown argument `-1` that names no flag.
#[derive(Debug, Subcommand)]
enum Command {
    /// Generate a synthetic hall with a hidden truth (hall.json, snapshots.csv, truth.json).
    #[command(allow_negative_numbers = true)]
    Synth(synth::SynthArgs),
    /// Run the built-in simulator (or OpenFOAM, or your own through `--config`) on a hall's
    /// snapshots and write the predicted sensor readings.
    #[command(allow_negative_numbers = true)]
    Simulate(simulate::SimulateArgs),
    /// Calibrate a hall's parameters (server air flow rates, effects) against its
    /// measurements, or a model of your own's (`--model command --config --measurements`).
    #[command(allow_negative_numbers = true)]
    Calibrate(Box<calibrate::CalibrateArgs>),
    /// Show where a calibrated model fails and rank the physical effects that may be missing
    /// (a hall's, or the candidate effects of a model of your own).
    #[command(allow_negative_numbers = true)]
    Diagnose(diagnose::DiagnoseArgs),
    /// The whole story on a synthetic hall with a hidden effect: calibrate, diagnose, add
    /// the missing effect, recalibrate, and write report.html.
    #[command(allow_negative_numbers = true)]
    Demo(demo::DemoArgs),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> CliResult {
    match cli.command {
        Command::Synth(a) => synth::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Calibrate(a) => calibrate::run(*a),
        Command::Diagnose(a) => diagnose::run(a),
        Command::Demo(a) => demo::run(a),
    }
}

pub use kalibre_core::some_names;

/// The most worker threads a command takes.
pub const MAX_THREADS: usize = 1024;

/// Builds the rayon pool for `--threads` (0 = all cores) and runs `f` in it.
pub fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> CliResult<T> {
    // Thousands of threads on a few cores only thrash (10,000 took minutes to start).
    if threads > MAX_THREADS {
        return Err(CliError::Input(format!(
            "--threads {threads}: expected at most {MAX_THREADS} (0 = all cores)"
        )));
    }
    // Far more threads than cores give the same results, only slower (1024 on 2 cores:
    // 25 times): said, not refused.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if threads > 4 * cores {
        eprintln!(
            "kalibre: warning: --threads {threads} on {cores} core(s): the same results, \
             more slowly than --threads 0 (one per core)"
        );
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| CliError::Run(format!("cannot start {threads} threads: {e}")))?;
    Ok(pool.install(f))
}

/// Set when `simulate --out` is this process's stdout (`--out /dev/stdout`): the summary
/// lines then go to stderr, so that stdout carries the predictions alone.
static SAY_TO_STDERR: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// `println!`, or `eprintln!` once an output file is stdout ([`say_to_stderr_if_stdout`]).
macro_rules! say {
    ($($arg:tt)*) => {
        if $crate::cli::says_to_stderr() {
            eprintln!($($arg)*)
        } else {
            println!($($arg)*)
        }
    };
}
pub(crate) use say;

/// Whether [`say!`] writes to stderr.
pub(crate) fn says_to_stderr() -> bool {
    SAY_TO_STDERR.load(std::sync::atomic::Ordering::Relaxed)
}

/// Sends [`say!`] to stderr when `out` is the file stdout writes to ([`is_stdout`]:
/// `/dev/stdout`, `/proc/self/fd/1`, or the file stdout is redirected to).
pub(crate) fn say_to_stderr_if_stdout(out: &std::path::Path) {
    if is_stdout(out) {
        SAY_TO_STDERR.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Whether `path` is the file stdout writes to (the same device and inode).
pub(crate) fn is_stdout(path: &std::path::Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let id = |p: &std::path::Path| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
        let stdout = id(std::path::Path::new("/dev/stdout"));
        stdout.is_some() && id(path) == stdout
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        false
    }
}

/// `path` as one shell word, for a command the user is told to run: as it is when every
/// character is safe in a POSIX shell, else in single quotes (a `'` as `'\''`), so that a
/// path with spaces pastes as one argument.
pub(crate) fn shell_word(path: &std::path::Path) -> String {
    let text = path.display().to_string();
    let safe = |c: char| c.is_ascii_alphanumeric() || "_@%+=:,./-".contains(c);
    if !text.is_empty() && text.chars().all(safe) {
        text
    } else {
        format!("'{}'", text.replace('\'', "'\\''"))
    }
}

/// `n` and `noun`, plural unless one: `1 snapshot`, `3 snapshots`.
pub(crate) fn counted(n: usize, noun: &str) -> String {
    match n {
        1 => format!("1 {noun}"),
        _ => format!("{n} {noun}s"),
    }
}

/// `v` to `digits` significant figures, without an exponent (a flow of 0.00356 m3/s
/// reads as such, not as 0.0035550000000000004) unless it would take many digits.
pub(crate) fn significant(v: f64, digits: usize) -> String {
    // -0 (a sum of nothing negated) reads as a sign where there is none.
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return v.to_string();
    }
    if !(1e-4..1e6).contains(&v.abs()) {
        let decimals = digits.saturating_sub(1);
        return format!("{v:.decimals$e}");
    }
    let decimals = (digits as i32 - 1 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.decimals$}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn shell_words_quote_only_what_needs_it() {
        use std::path::Path;
        assert_eq!(
            super::shell_word(Path::new("cal/run-1.toml")),
            "cal/run-1.toml"
        );
        assert_eq!(super::shell_word(Path::new("my cal")), "'my cal'");
        assert_eq!(super::shell_word(Path::new("it's")), "'it'\\''s'");
        assert_eq!(super::shell_word(Path::new("")), "''");
    }

    #[test]
    fn significant_figures_carry_no_sign_on_zero() {
        assert_eq!(super::significant(-0.0, 3), "0");
        assert_eq!(super::significant(0.0, 3), "0");
        assert_eq!(super::significant(-1.23456, 3), "-1.23");
        assert_eq!(super::significant(12345.6, 3), "12346");
        assert_eq!(super::significant(2.0e-5, 3), "2.00e-5");
    }
}
