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

fn main() {
    // A reader that closes early (`kalibre simulate ... | head`) ends the process quietly,
    // as it does other Unix tools, instead of a panic on the next line printed.
    #[cfg(unix)]
    // SAFETY: restoring the default action of a signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let args = cli::Cli::parse();
    // Output that cannot be written is an error of this run, not a bug: no panic report
    // for it (every other panic keeps the default one).
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if print_failure(info.payload()).is_none() {
            default_hook(info);
        }
    }));
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| cli::run(args)));
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
