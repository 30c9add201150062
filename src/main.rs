//! The `kalibre` command-line tool (subcommands are wired as their crates land).

fn main() {
    eprintln!("kalibre: the command-line tool is being assembled; see README.md");
    std::process::exit(2);
}
