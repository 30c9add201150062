//! The paper's Fig. 7 on the synthetic `hall-a`: test MAE of the thermal graph with fixed
//! and with trainable adjacency and of the vanilla MLP, trained on 5, 15, 30 and 50 % of
//! the training set (213 model runs at uniformly random alpha, 8:2 split).
//!
//! ```sh
//! cargo run --release --example fig7 -- [--quick] [--out-dir target/experiments] [--seeds 3]
//! ```
//!
//! Alpha is drawn uniformly in cfm/W; `--log-box` draws it uniformly on the log scale;
//! `--rise-box` draws each server type's temperature rise uniformly in the default rise
//! prior's range (5-20 K), the plausible band the calibration searches.
//! One alpha is drawn per server type; `--per-rack` draws one per rack and `--per-server`
//! one per server (the paper's alpha vector), with the model and the graph taking one
//! alpha per server. Files get `-per-rack` / `-per-server` after the draw's name.
//! `--sharp-adjacency` gives both graphs server-sensor edges `1 / d^4` with the height
//! difference halved (`examples/fig7_edges.rs`); files get `-sharp` at the end.
//! `--local-recirculation` gives both graphs the whole-hall local recirculation term on
//! their cold-aisle sensors; files get `-local` at the end.
//! `--influence-adjacency` gives both graphs hot-aisle edges from the model's own air
//! flow at the initial alphas (`Simulator::sensor_influence`); files get `-influence`.
//! `--quick`: 40 runs of `demo`, 1 seed. Prints the table and writes `fig7.json`,
//! `fig7.md` and `fig7.svg`.

#[path = "experiments/mod.rs"]
mod experiments;

use experiments::fig7::{markdown, run_fig7, svg, AlphaDraw, AlphaGrain, Fig7Config, Fig7Result};
use experiments::{parse_args, write_file, write_json};

const USAGE: &str = "
fig7: the paper's Fig. 7 (test MAE of the thermal graph with fixed and trainable
adjacency and of the MLP, trained on 5-50 % of the runs) on one synthetic hall; writes
fig7.json, fig7.md and fig7.svg (the draw's and options' names appended).

usage: fig7 [--quick] [--out-dir DIR] [--seeds N] [--presets HALL]
            [--log-box | --rise-box] [--per-rack | --per-server]
            [--sharp-adjacency] [--local-recirculation] [--influence-adjacency]
       fig7 --render DIR/fig7.json      (redraw the figure and table of an earlier run)

--presets takes one hall (hall-a by default), without a seed count (--seeds sets it).
--out-dir defaults to target/experiments (give docs/results to replace the stored
results). Threads: RAYON_NUM_THREADS. docs/experiments.md explains each option.";

fn main() {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    experiments::exit_with_help_if_asked(&raw, USAGE);
    for pair in [["--log-box", "--rise-box"], ["--per-rack", "--per-server"]] {
        if pair.iter().all(|f| raw.iter().any(|a| a == f)) {
            eprintln!("{} and {}: give one of the two", pair[0], pair[1]);
            std::process::exit(2);
        }
    }
    // `--render FILE.json`: redraw the figure and table of an earlier run beside it.
    if let Some(code) = experiments::render_if_asked::<Fig7Result>(&raw, "fig7", svg, markdown) {
        std::process::exit(code);
    }
    let draw = if raw.iter().any(|a| a == "--log-box") {
        AlphaDraw::Log
    } else if raw.iter().any(|a| a == "--rise-box") {
        AlphaDraw::Rise
    } else {
        AlphaDraw::Linear
    };
    let grain = if raw.iter().any(|a| a == "--per-server") {
        AlphaGrain::Server
    } else if raw.iter().any(|a| a == "--per-rack") {
        AlphaGrain::Rack
    } else {
        AlphaGrain::Type
    };
    let raw_sharp = raw.iter().any(|a| a == "--sharp-adjacency");
    let raw_local = raw.iter().any(|a| a == "--local-recirculation");
    let raw_influence = raw.iter().any(|a| a == "--influence-adjacency");
    let args = parse_args(raw.into_iter().filter(|a| {
        !matches!(
            a.as_str(),
            "--log-box"
                | "--rise-box"
                | "--per-rack"
                | "--per-server"
                | "--sharp-adjacency"
                | "--local-recirculation"
                | "--influence-adjacency"
        )
    }))
    .unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    experiments::one_hall(&args, "fig7");
    experiments::prepare_out_dir(&args.out_dir).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let mut cfg = if args.quick {
        Fig7Config::quick()
    } else {
        Fig7Config::full()
    };
    cfg.draw = draw;
    cfg.grain = grain;
    cfg.sharp_adjacency = raw_sharp;
    cfg.local_recirculation = raw_local;
    cfg.influence_adjacency = raw_influence;
    if let Some(n) = args.seeds {
        cfg.seeds = n;
    }
    if let Some((p, _)) = args.presets.as_ref().and_then(|v| v.first()) {
        cfg.preset = *p;
    }
    let r = run_fig7(&cfg, &|l| eprintln!("{l}")).unwrap_or_else(|e| {
        eprintln!("fig7: {e}");
        std::process::exit(1)
    });
    let md = markdown(&r);
    let sharp = if cfg.sharp_adjacency { "-sharp" } else { "" };
    let local = if cfg.local_recirculation {
        "-local"
    } else {
        ""
    };
    let influence = if cfg.influence_adjacency {
        "-influence"
    } else {
        ""
    };
    let stem = format!("{}{}{sharp}{local}{influence}", draw.stem(), grain.suffix());
    let written = write_json(&args.out_dir, &format!("{stem}.json"), &r)
        .and_then(|_| write_file(&args.out_dir, &format!("{stem}.md"), &md))
        .and_then(|_| write_file(&args.out_dir, &format!("{stem}.svg"), &svg(&r)));
    if let Err(e) = written {
        eprintln!("{e}");
        std::process::exit(1);
    }
    println!("{md}");
    println!("wrote {}/{stem}.json, .md and .svg", args.out_dir.display());
}
