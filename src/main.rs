//! The `kalibre` command-line tool.

mod cli;

use std::any::Any;
use std::io::Write;

use clap::Parser;

/// The message of `print!`'s panic when stdout or stderr cannot be written (a full disk
/// under `diagnose --json > file`), which `main` turns into an error and exit code 1.
fn print_failure(payload: &(dyn Any + Send)) -> Option<&str> {
    let text = payload
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| payload.downcast_ref::<&str>().copied())?;
    text.starts_with("failed printing to std").then_some(text)
}

/// clap's refusal of the command line as one line, `kalibre: error: ...`, as every
/// other error is; help and version requests are printed as clap prints them.
fn usage_error(e: clap::Error) -> ! {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let _ = writeln!(
        std::io::stderr(),
        "kalibre: error: {}",
        one_line(&e.render().to_string())
    );
    std::process::exit(2);
}

/// clap's message (`error: ...`, indented continuation lines, `tip:` lines, a `Usage:`
/// line and a pointer to `--help`) joined into one line.
fn one_line(text: &str) -> String {
    let mut message: Vec<String> = Vec::new();
    let mut tips: Vec<String> = Vec::new();
    let mut usage = None;
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if let Some(u) = line.strip_prefix("Usage:") {
            usage = Some(u.trim().to_string());
        } else if let Some(t) = line.strip_prefix("tip:") {
            tips.push(t.trim().to_string());
        } else if !line.starts_with("For more information") {
            message.push(
                line.strip_prefix("error:")
                    .unwrap_or(line)
                    .trim()
                    .to_string(),
            );
        }
    }
    // "...not provided:" followed by one argument per line reads as a list; a
    // "[possible values: ...]" line belongs to the line before it.
    let mut out = String::new();
    for (i, part) in message.iter().enumerate() {
        if i > 0 {
            let joined = message[i - 1].ends_with(':') || part.starts_with('[');
            out.push_str(if joined { " " } else { ", " });
        }
        out.push_str(part);
    }
    for t in tips {
        out.push_str(&format!("; {t}"));
    }
    match usage {
        Some(u) => out.push_str(&format!(" (usage: {u}; more with --help)")),
        None => out.push_str(" (more with --help)"),
    }
    out
}

fn main() {
    // A reader that closes early (`kalibre simulate ... | head`) ends the process quietly,
    // as it does other Unix tools, instead of a panic on the next line printed.
    #[cfg(unix)]
    // SAFETY: restoring the default action of a signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let args = cli::Cli::try_parse().unwrap_or_else(|e| usage_error(e));
    // Model runs have process groups of their own, which Ctrl-C does not reach: end
    // them with kalibre rather than leave solvers running.
    kalibre_core::external::end_runs_with_kalibre();
    // Output that cannot be written is an error of this run, not a bug: no panic report
    // for it (every other panic keeps the default one).
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if print_failure(info.payload()).is_none() {
            default_hook(info);
        }
    }));
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| cli::run(args)));
    // Stopped by a signal while its runs were being ended: the handler ends the process
    // as the signal would, with its message, not this command's outcome.
    kalibre_core::external::await_stop();
    // Writes to stderr are tried, never unwrapped: stderr may be the full device too.
    match outcome {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let _ = writeln!(std::io::stderr(), "kalibre: error: {e}");
            std::process::exit(e.exit_code());
        }
        Err(payload) => match print_failure(payload.as_ref()) {
            Some(message) => {
                let _ = writeln!(std::io::stderr(), "kalibre: error: {message}");
                std::process::exit(1);
            }
            None => std::panic::resume_unwind(payload),
        },
    }
}
