//! The paper's Table 4 on the synthetic halls: Kalibre (the thermal graph in the
//! four-step loop) against the vanilla MLP in the same loop, the (1+1)-ES and the
//! expert's manual heuristic, on the same measurements (synth seed 1, 3 snapshots,
//! noise 0.2 C) and the same model.
//!
//! ```sh
//! cargo run --release --example table4 -- [--quick] [--out-dir target/experiments] \
//!     [--seeds 3] [--presets hall-a:3,hall-b:1] [--approaches kalibre,mlp,es,manual] \
//!     [--mlp-seeds 1] [--budgets mlp=60,es=150] [--paper-loop]
//! cargo run --release --example table4 -- --out-dir DIR --combine a/table4.json b/table4.json
//! ```
//!
//! `--approaches` runs a subset of the rows (default all). `--paper-loop` runs the loop
//! rows (Kalibre and the MLP) in the paper's Algorithm 1 instead of kalibre's loop (as
//! `fig8 --paper-loop`) and writes `table4-paper-loop.*`. `--combine` merges separate
//! invocations (run side by side, or some approaches each) into one table, by hall and
//! by approach: a later file's row replaces an earlier one's, the targets are recomputed,
//! and halls measured differently (initial MAE or model-at-truth MAE differ) are refused.
//!
//! Full mode: `hall-a` and `hall-b`, 3 seeds, budgets of 20 Kalibre, 60 MLP, 150 ES and
//! 30 manual iterations (`--budgets` overrides single ones). `--quick`: `demo`, 1 seed, a
//! few iterations each. Prints the table and writes `table4.json` and `table4.md` (after
//! each hall, so a long run that is stopped keeps what finished).

#[path = "experiments/mod.rs"]
mod experiments;

use experiments::table4::{combine, markdown, run_hall, Approach, Budgets, HallTable};
use experiments::{parse_args, write_file, write_json};
use kalibre::dc::synth::Preset;
use serde_json::json;

const USAGE: &str = "
table4: the paper's Table 4 (Kalibre, the MLP in the same loop, the (1+1)-ES, the manual
heuristic) on the synthetic halls; writes table4.json and table4.md.

usage: table4 [--quick] [--out-dir DIR] [--seeds N] [--presets hall-a[:N],hall-b[:N]]
              [--approaches kalibre,mlp,es,manual] [--mlp-seeds N]
              [--budgets kalibre=20,mlp=60,es=150,manual=30] [--paper-loop]
       table4 [--out-dir DIR] --combine A/table4.json B/table4.json ...   (last)

--out-dir defaults to target/experiments (give docs/results to replace the stored
results). Threads: RAYON_NUM_THREADS. docs/experiments.md explains each flag.";

fn main() {
    let mut raw: Vec<String> = std::env::args().skip(1).collect();
    experiments::exit_with_help_if_asked(&raw, USAGE);
    // `--combine A.json B.json ...`: merge the halls of earlier runs into one table.
    let mut combine_files = Vec::new();
    if let Some(i) = raw.iter().position(|a| a == "--combine") {
        combine_files = raw
            .drain(i..)
            .skip(1)
            .map(std::path::PathBuf::from)
            .collect();
        if combine_files.is_empty() {
            fail(2, "--combine needs table4.json files (and must come last)");
        }
    }
    // `--mlp-seeds N`: the MLP loop on the first N seeds only (it is the slowest row).
    let mlp_seeds = take_flag(&mut raw, "--mlp-seeds").map(|v| {
        v.parse::<usize>()
            .ok()
            .filter(|&n| n >= 1)
            .unwrap_or_else(|| fail(2, "--mlp-seeds needs a count of at least 1"))
    });
    let approaches = take_flag(&mut raw, "--approaches")
        .map(|v| Approach::parse_list(&v).unwrap_or_else(|e| fail(2, &e)))
        .unwrap_or_else(|| Approach::ALL.to_vec());
    let overrides = take_flag(&mut raw, "--budgets");
    // `--paper-loop`: the loop rows run the paper's Algorithm 1 instead of kalibre's loop.
    let paper_loop = take_switch(&mut raw, "--paper-loop");
    let args = parse_args(raw).unwrap_or_else(|e| fail(2, &e));
    experiments::prepare_out_dir(&args.out_dir).unwrap_or_else(|e| fail(2, &e.to_string()));
    if !combine_files.is_empty() {
        let tables = combine(&combine_files).unwrap_or_else(|e| fail(1, &e.to_string()));
        write_tables(&args.out_dir, &tables, args.quick);
        println!("{}", markdown(&tables));
        return;
    }
    let (mut budgets, default_halls) = if args.quick {
        (Budgets::quick(), vec![(Preset::Demo, None)])
    } else {
        (
            Budgets::full(),
            vec![(Preset::HallA, None), (Preset::HallB, None)],
        )
    };
    if let Some(list) = overrides {
        budgets = budgets
            .with_overrides(&list)
            .unwrap_or_else(|e| fail(2, &e));
    }
    budgets.mlp_seeds = mlp_seeds;
    let default_seeds = args.seeds.unwrap_or(if args.quick { 1 } else { 3 });
    let halls = args.presets.clone().unwrap_or(default_halls);
    let mut tables: Vec<HallTable> = Vec::new();
    for (preset, seeds) in halls {
        let seeds = seeds.unwrap_or(default_seeds);
        let t = run_hall(
            preset,
            seeds,
            budgets,
            &approaches,
            !args.quick,
            paper_loop,
            &|l| eprintln!("{l}"),
        )
        .unwrap_or_else(|e| fail(1, &format!("table4 on {preset}: {e}")));
        tables.push(t);
        write_tables(&args.out_dir, &tables, args.quick);
    }
    println!("{}", markdown(&tables));
    println!(
        "wrote {dir}/{stem}.json and {dir}/{stem}.md",
        dir = args.out_dir.display(),
        stem = stem(&tables)
    );
}

fn stem(tables: &[HallTable]) -> &'static str {
    if tables.iter().any(|t| t.paper_loop) {
        "table4-paper-loop"
    } else {
        "table4"
    }
}

/// Removes `flag` from `raw` and says whether it was there.
fn take_switch(raw: &mut Vec<String>, flag: &str) -> bool {
    let before = raw.len();
    raw.retain(|a| a != flag);
    raw.len() != before
}

/// Removes `flag VALUE` from `raw` and returns the value (exits when it is missing).
fn take_flag(raw: &mut Vec<String>, flag: &str) -> Option<String> {
    let i = raw.iter().position(|a| a == flag)?;
    if i + 1 >= raw.len() {
        fail(2, &format!("{flag} needs a value"));
    }
    let value = raw.remove(i + 1);
    raw.remove(i);
    Some(value)
}

fn fail(code: i32, message: &str) -> ! {
    eprintln!("{message}");
    std::process::exit(code)
}

/// Writes `table4.json` and `.md`, or `table4-paper-loop.*` when a hall's loop rows ran
/// the paper's loop.
fn write_tables(dir: &std::path::Path, tables: &[HallTable], quick: bool) {
    let doc = json!({ "experiment": "table4", "quick": quick, "halls": tables });
    let stem = stem(tables);
    let written = write_json(dir, &format!("{stem}.json"), &doc)
        .and_then(|_| write_file(dir, &format!("{stem}.md"), &markdown(tables)));
    if let Err(e) = written {
        fail(1, &e.to_string());
    }
}
