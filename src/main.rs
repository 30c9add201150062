//! The `kalibre` command-line tool.

mod cli;

use clap::Parser;

fn main() {
    let args = cli::Cli::parse();
    if let Err(e) = cli::run(args) {
        eprintln!("kalibre: error: {e}");
        std::process::exit(e.exit_code());
    }
}
