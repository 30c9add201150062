//! The `kalibre` command-line tool.

mod cli;

use clap::Parser;

fn main() {
    // A reader that closes early (`kalibre simulate ... | head`) ends the process quietly,
    // as it does other Unix tools, instead of a panic on the next line printed.
    #[cfg(unix)]
    // SAFETY: restoring the default action of a signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let args = cli::Cli::parse();
    if let Err(e) = cli::run(args) {
        eprintln!("kalibre: error: {e}");
        std::process::exit(e.exit_code());
    }
}
