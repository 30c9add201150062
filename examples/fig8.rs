//! The paper's Fig. 8 on the synthetic `hall-a`: the search loss and gradient norm per
//! loop iteration, with differential evolution before Adam (Kalibre) and with Adam
//! alone, over 10 iterations and 3 seeds.
//!
//! ```sh
//! cargo run --release --example fig8 -- [--quick] [--out-dir target/experiments] [--seeds 3]
//! ```
//!
//! `--paper-loop` runs the paper's Algorithm 1 (no trust region, output correction or fit
//! focus) and writes `fig8-paper-loop.*` instead. `--quick`: 3 iterations of `demo`, 1 seed. Prints the table and writes `fig8.json`,
//! `fig8.md` and `fig8.svg`.

#[path = "experiments/mod.rs"]
mod experiments;

use experiments::fig8::{markdown, run_fig8, svg, Fig8Config, Fig8Result};
use experiments::{parse_args, write_file, write_json};

const USAGE: &str = "
fig8: the paper's Fig. 8 (search loss and gradient norm per loop iteration, DE then Adam
against Adam alone) on one synthetic hall; writes fig8.json, fig8.md and fig8.svg.

usage: fig8 [--quick] [--out-dir DIR] [--seeds N] [--presets HALL] [--paper-loop]
       fig8 --render DIR/fig8.json      (redraw the figure and table of an earlier run)

--presets takes one hall (hall-a by default), without a seed count (--seeds sets it).
--out-dir defaults to target/experiments (give docs/results to replace the stored
results). Threads: RAYON_NUM_THREADS.";

fn main() {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    experiments::exit_with_help_if_asked(&raw, USAGE);
    // `--render FILE.json`: redraw the figure and table of an earlier run beside it.
    if let Some(code) = experiments::render_if_asked::<Fig8Result>(&raw, "fig8", svg, markdown) {
        std::process::exit(code);
    }
    let paper_loop = raw.iter().any(|a| a == "--paper-loop");
    let args = parse_args(raw.into_iter().filter(|a| a != "--paper-loop")).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    experiments::one_hall(&args, "fig8");
    experiments::prepare_out_dir(&args.out_dir).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let mut cfg = if args.quick {
        Fig8Config::quick()
    } else {
        Fig8Config::full()
    };
    cfg.paper_loop = paper_loop;
    if let Some(n) = args.seeds {
        cfg.seeds = n;
    }
    if let Some((p, _)) = args.presets.as_ref().and_then(|v| v.first()) {
        cfg.preset = *p;
    }
    let r = run_fig8(&cfg, &|l| eprintln!("{l}")).unwrap_or_else(|e| {
        eprintln!("fig8: {e}");
        std::process::exit(1)
    });
    let md = markdown(&r);
    let written = write_json(
        &args.out_dir,
        if paper_loop {
            "fig8-paper-loop.json"
        } else {
            "fig8.json"
        },
        &r,
    )
    .and_then(|_| {
        write_file(
            &args.out_dir,
            if paper_loop {
                "fig8-paper-loop.md"
            } else {
                "fig8.md"
            },
            &md,
        )
    })
    .and_then(|_| {
        write_file(
            &args.out_dir,
            if paper_loop {
                "fig8-paper-loop.svg"
            } else {
                "fig8.svg"
            },
            &svg(&r),
        )
    });
    if let Err(e) = written {
        eprintln!("{e}");
        std::process::exit(1);
    }
    println!("{md}");
    let stem = if paper_loop {
        "fig8-paper-loop"
    } else {
        "fig8"
    };
    println!("wrote {}/{stem}.json, .md and .svg", args.out_dir.display());
}
