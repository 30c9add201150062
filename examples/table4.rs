//! The paper's Table 4 on the synthetic halls: Kalibre (the thermal graph in the
//! four-step loop) against the vanilla MLP in the same loop, the (1+1)-ES and the
//! expert's manual heuristic, on the same measurements (synth seed 1, 3 snapshots,
//! noise 0.2 C) and the same model.
//!
//! ```sh
//! cargo run --release --example table4 -- [--quick] [--out-dir docs/results] \
//!     [--seeds 3] [--presets hall-a:3,hall-b:1] [--mlp-seeds 1]
//! cargo run --release --example table4 -- --out-dir DIR --combine a/table4.json b/table4.json
//! ```
//!
//! `--combine` merges the halls of separate invocations (run side by side) into one table.
//!
//! Full mode: `hall-a` and `hall-b`, 3 seeds, budgets of 20 Kalibre, 60 MLP, 150 ES and
//! 30 manual iterations. `--quick`: `demo`, 1 seed, a few iterations each. Prints the
//! table and writes `table4.json` and `table4.md` (after each hall, so a long run that
//! is stopped keeps what finished).

#[path = "experiments/mod.rs"]
mod experiments;

use experiments::table4::{combine, markdown, run_hall, Budgets, HallTable};
use experiments::{parse_args, write_file, write_json};
use kalibre::dc::synth::Preset;
use serde_json::json;

fn main() {
    let mut raw: Vec<String> = std::env::args().skip(1).collect();
    // `--mlp-seeds N`: the MLP loop on the first N seeds only (it is the slowest row).
    let mut mlp_seeds = None;
    if let Some(i) = raw.iter().position(|a| a == "--mlp-seeds") {
        let n = raw
            .get(i + 1)
            .and_then(|v| v.parse::<usize>().ok())
            .filter(|&n| n >= 1);
        let Some(n) = n else {
            eprintln!("--mlp-seeds needs a count of at least 1");
            std::process::exit(2)
        };
        mlp_seeds = Some(n);
        raw.drain(i..i + 2);
    }
    // `--combine A.json B.json ...`: merge the halls of earlier runs into one table.
    let mut combine_files = Vec::new();
    if let Some(i) = raw.iter().position(|a| a == "--combine") {
        combine_files = raw
            .drain(i..)
            .skip(1)
            .map(std::path::PathBuf::from)
            .collect();
        if combine_files.is_empty() {
            eprintln!("--combine needs table4.json files (and must come last)");
            std::process::exit(2);
        }
    }
    let args = parse_args(raw).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let (mut budgets, default_halls) = if args.quick {
        (Budgets::quick(), vec![(Preset::Demo, None)])
    } else {
        (
            Budgets::full(),
            vec![(Preset::HallA, None), (Preset::HallB, None)],
        )
    };
    budgets.mlp_seeds = mlp_seeds;
    let default_seeds = args.seeds.unwrap_or(if args.quick { 1 } else { 3 });
    let halls = args.presets.clone().unwrap_or(default_halls);
    let mut tables: Vec<HallTable> = Vec::new();
    if !combine_files.is_empty() {
        tables = combine(&combine_files).unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(1)
        });
        write_tables(&args.out_dir, &tables, args.quick);
        println!("{}", markdown(&tables));
        return;
    }
    for (preset, seeds) in halls {
        let seeds = seeds.unwrap_or(default_seeds);
        let t = run_hall(preset, seeds, budgets, !args.quick, &|l| eprintln!("{l}"))
            .unwrap_or_else(|e| {
                eprintln!("table4 on {preset}: {e}");
                std::process::exit(1)
            });
        tables.push(t);
        write_tables(&args.out_dir, &tables, args.quick);
    }
    println!("{}", markdown(&tables));
    println!("wrote {}/table4.json and table4.md", args.out_dir.display());
}

fn write_tables(dir: &std::path::Path, tables: &[HallTable], quick: bool) {
    let doc = json!({ "experiment": "table4", "quick": quick, "halls": tables });
    let written = write_json(dir, "table4.json", &doc)
        .and_then(|_| write_file(dir, "table4.md", &markdown(tables)));
    if let Err(e) = written {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
