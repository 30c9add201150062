//! What kalibre adds to every model run, apart from the model itself: issue 7's target
//! (kalibre's own work per run under 1 % of the solve), measured here rather than in
//! timed tests, which a loaded CI machine would make flaky.
//!
//! ```sh
//! cargo run --release --example run_overhead [-- --reps 6 --openfoam-runs 3]
//! ```
//!
//! Two parts:
//! - **External command**: a program that does nothing (`true(1)`), with two templates
//!   rendered and an output file parsed, `--reps` repetitions of 50 runs; the per-step
//!   times and the same program spawned bare. Kalibre's share is total minus bare spawn.
//! - **OpenFOAM**: the development hall `data/openfoam/of-dev-clean` at the true alphas,
//!   its three snapshots solved one after another (`--openfoam-runs` of them; 0 skips the
//!   part, which needs OpenFOAM in PATH). Kalibre's share is prepare + parse + cleanup
//!   against the solver's wall time.
//!
//! Writes `--out` (default `docs/results/run_overhead.json`).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use kalibre::core::external::{ExternalCommand, NamedScenario, OutputParser};
use kalibre::dc::hall::Hall;
use kalibre::dc::openfoam::{OpenFoamModel, OpenFoamSettings};
use kalibre::dc::snapshots;
use serde_json::{json, Value};

/// Runs per repetition of the external-command part.
const RUNS_PER_REP: usize = 50;
/// True alpha of the development datasets (cfm/W).
const TRUE_ALPHA: [(&str, f64); 3] = [("web", 0.13), ("db", 0.17), ("gpu", 0.12)];

fn main() {
    let mut reps = 6usize;
    let mut openfoam_runs = 3usize;
    let mut out = PathBuf::from("docs/results/run_overhead.json");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || {
            args.next()
                .unwrap_or_else(|| fail(&format!("{a} needs a value")))
        };
        match a.as_str() {
            "--reps" => reps = parse(&value(), "--reps"),
            "--openfoam-runs" => openfoam_runs = parse(&value(), "--openfoam-runs"),
            "--out" => out = PathBuf::from(value()),
            other => fail(&format!("unknown option {other}")),
        }
    }
    let scratch = std::env::temp_dir().join(format!("kalibre-overhead-{}", std::process::id()));
    let external = external_part(&scratch.join("external"), reps.max(1));
    let openfoam = if openfoam_runs == 0 {
        Value::Null
    } else {
        openfoam_part(&scratch.join("openfoam"), openfoam_runs)
    };
    let _ = std::fs::remove_dir_all(&scratch);
    let result = json!({
        "external_command": external,
        "openfoam": openfoam,
        "load_average": load_average(),
    });
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).unwrap_or_else(|e| fail(&format!("{}: {e}", dir.display())));
    }
    std::fs::write(&out, serde_json::to_string_pretty(&result).unwrap() + "\n")
        .unwrap_or_else(|e| fail(&format!("{}: {e}", out.display())));
    println!("wrote {}", out.display());
}

/// `reps` repetitions of 50 runs of `true(1)` through `ExternalCommand`, and of the
/// bare spawn; per-run milliseconds of each step, best and worst repetition.
fn external_part(root: &Path, reps: usize) -> Value {
    let program = ["/bin/true", "/usr/bin/true"]
        .into_iter()
        .find(|p| Path::new(p).exists())
        .unwrap_or_else(|| fail("true(1) is not at /bin/true or /usr/bin/true"));
    std::fs::create_dir_all(root).unwrap_or_else(|e| fail(&format!("{}: {e}", root.display())));
    let model: ExternalCommand = ExternalCommand::builder(program, root)
        .with_template_text("params", "a = {{a:.6}}\nb = {{b:e}}\n", "params.in")
        .with_template_text("out", "name,value\na,{{a}}\nb,{{b}}\n", "out.csv")
        .with_output("out.csv", OutputParser::CsvLong, ["a", "b"])
        .with_params(["a", "b"])
        .with_timeout(Duration::from_secs(10))
        .build()
        .unwrap_or_else(|e| fail(&format!("external command: {e}")));
    let scenario = NamedScenario::new("overhead");
    let ms = |x: f64| 1e3 * x / RUNS_PER_REP as f64;
    let mut rows = Vec::new();
    for rep in 0..reps {
        let (mut setup, mut process, mut parse, mut cleanup) = (0.0, 0.0, 0.0, 0.0);
        let t = Instant::now();
        for i in 0..RUNS_PER_REP {
            let r = model.run(&scenario, &[i as f64, 0.5]);
            match r.outcome {
                Ok(o) if o.values == [i as f64, 0.5] => {}
                other => fail(&format!("run {i} of repetition {rep}: {other:?}")),
            }
            let a = &r.attempts[0];
            setup += a.setup.as_secs_f64();
            process += a.process.as_secs_f64();
            parse += a.parse.as_secs_f64();
            cleanup += a.cleanup.as_secs_f64();
        }
        let total = t.elapsed().as_secs_f64();
        let t = Instant::now();
        for _ in 0..RUNS_PER_REP {
            let ok = std::process::Command::new(program)
                .status()
                .map(|s| s.success())
                .unwrap_or(false);
            if !ok {
                fail(&format!("{program} did not run"));
            }
        }
        let bare = t.elapsed().as_secs_f64();
        let row = json!({
            "setup_ms": ms(setup), "process_ms": ms(process), "parse_ms": ms(parse),
            "cleanup_ms": ms(cleanup), "total_ms": ms(total), "bare_spawn_ms": ms(bare),
            "added_ms": ms(total - bare),
        });
        println!(
            "external command, repetition {}: per run total {:.3} ms (setup {:.3}, process {:.3}, parse {:.3}, cleanup {:.3}); bare spawn {:.3} ms; added {:.3} ms",
            rep + 1,
            ms(total),
            ms(setup),
            ms(process),
            ms(parse),
            ms(cleanup),
            ms(bare),
            ms(total - bare)
        );
        rows.push(row);
    }
    let added: Vec<f64> = rows
        .iter()
        .map(|r| r["added_ms"].as_f64().unwrap())
        .collect();
    json!({
        "program": program,
        "runs_per_repetition": RUNS_PER_REP,
        "repetitions": rows,
        "added_ms_best": added.iter().copied().fold(f64::INFINITY, f64::min),
        "added_ms_worst": added.iter().copied().fold(0.0, f64::max),
    })
}

/// `runs` OpenFOAM solves of `of-dev-clean`'s snapshots (cycled) at the true alphas,
/// one at a time, with where each run's time went.
fn openfoam_part(root: &Path, runs: usize) -> Value {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/openfoam/of-dev-clean");
    let hall = Hall::load(&data.join("hall.json")).unwrap_or_else(|e| fail(&e.to_string()));
    let snaps = snapshots::load_snapshots(&hall, &data.join("snapshots.csv"))
        .unwrap_or_else(|e| fail(&e.to_string()));
    let model = OpenFoamModel::new(&hall, OpenFoamSettings::default().with_cache_root(root))
        .unwrap_or_else(|e| fail(&format!("OpenFOAM: {e}")));
    let params: Vec<f64> = model
        .layout()
        .space()
        .names()
        .iter()
        .map(|n| {
            let t = n.trim_start_matches("alpha/");
            TRUE_ALPHA
                .iter()
                .find(|(k, _)| *k == t)
                .unwrap_or_else(|| fail(&format!("no true value for {n}")))
                .1
        })
        .collect();
    let mut rows = Vec::new();
    let mut worst_share: f64 = 0.0;
    for i in 0..runs {
        let snap = &snaps[i % snaps.len()];
        let (_, t) = model
            .evaluate_timed(&snap.state, &params)
            .unwrap_or_else(|e| fail(&format!("{}: {e}", snap.state.label)));
        let added = t.prepare_s + t.parse_s + t.cleanup_s;
        let share = added / t.solve_s;
        worst_share = worst_share.max(share);
        println!(
            "OpenFOAM {}: solve {:.1} s; prepare {:.1} ms, parse {:.1} ms, cleanup {:.0} ms; kalibre's share {:.3} % (target < 1 %)",
            snap.state.label,
            t.solve_s,
            1e3 * t.prepare_s,
            1e3 * t.parse_s,
            1e3 * t.cleanup_s,
            100.0 * share
        );
        rows.push(json!({
            "snapshot": snap.state.label, "solve_s": t.solve_s, "prepare_s": t.prepare_s,
            "parse_s": t.parse_s, "cleanup_s": t.cleanup_s, "share": share,
            "energy_balance": t.energy_balance,
        }));
    }
    json!({
        "dataset": "of-dev-clean",
        "runs": rows,
        "worst_share": worst_share,
        "target_share": 0.01,
        "met": worst_share < 0.01,
    })
}

/// The 1-minute load average, when the machine says (the figures depend on it).
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn parse<T: std::str::FromStr>(s: &str, name: &str) -> T {
    s.parse()
        .unwrap_or_else(|_| fail(&format!("{name}: cannot read {s:?}")))
}

fn fail(msg: &str) -> ! {
    eprintln!("run_overhead: {msg}");
    std::process::exit(1)
}
