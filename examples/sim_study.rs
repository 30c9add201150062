//! Simulator study: grid convergence on the synth `demo` preset (0.2 m against 0.1 m),
//! realism against OpenFOAM (`of-dev-clean`), and seconds per solve on the benchmark's
//! demo and hall-a halls, per advection scheme and diffusivity.
//!
//! `cargo run --release --example sim_study -- [--advection upwind|van_leer|minmod]...
//! [--passes MAX:TOL_C] [--panel-m T] [--diagnose] [--no-timing] [DIFFUSIVITY...]` (run from the workspace root; defaults: upwind and
//! van_leer, diffusivity 0.01; `--panel-m T|none`: containment panel thickness,
//! `SimConfig::containment_panel_m`, default 0.2 m; `none`: one cell thick). Prints a markdown table; `--diagnose`
//! prints instead how row A's containment, rack A01 and sensor `c-A01-17` land on both
//! grids and the flow through each containment side.

#[path = "../kalibre-dc/tests/support/sim_halls.rs"]
mod sim_halls;

use std::time::Instant;

use kalibre_dc::hall::{Aabb, Containment, Hall};
use kalibre_dc::sim::{Advection, Grid, SimConfig, Simulator, Solution};
use kalibre_dc::snapshots::{load_snapshots, OperatingState};
use kalibre_dc::synth::{generate, Preset, SynthOptions};

/// The study's configuration: default grid, `d`, `advection`, optional pass settings and
/// containment panel thickness.
fn config(
    d: f64,
    advection: Advection,
    passes: Option<(usize, f64)>,
    panel_m: Option<f64>,
) -> SimConfig {
    let cfg = SimConfig::default()
        .with_diffusivity_m2_s(d)
        .with_advection(advection)
        .with_containment_panel_m(panel_m);
    match passes {
        Some((m, t)) => cfg.with_advection_outer(m, t),
        None => cfg,
    }
}

fn parse_advection(s: &str) -> Advection {
    serde_json::from_value(serde_json::Value::String(s.to_string()))
        .unwrap_or_else(|e| panic!("--advection {s}: {e}"))
}

/// Median seconds per solve (and the last solve's figures) of `hall` at the default grid.
fn timing(hall: &Hall, power_w: f64, cfg: SimConfig) -> (f64, usize, usize, f64) {
    let sim = Simulator::new(hall, cfg).expect("sim");
    let state = sim_halls::varied_state(hall, 18.0, 0.9, power_w);
    let alpha = vec![0.12; hall.server_count()];
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..5 {
        let t = Instant::now();
        let sol = sim.solve(&state, &alpha, &[]).expect("solve");
        times.push(t.elapsed().as_secs_f64());
        last = Some(sol);
    }
    times.sort_by(f64::total_cmp);
    let sol = last.expect("solved");
    (
        times[times.len() / 2],
        sol.advection_stats.passes,
        sol.heat_stats.iterations,
        sol.energy_balance_error(),
    )
}

fn main() {
    let mut schemes = Vec::new();
    let mut ds = Vec::new();
    let mut with_timing = true;
    let mut passes_cfg: Option<(usize, f64)> = None;
    let mut diagnose_only = false;
    // The simulator's default panels; `--panel-m none` gives the old one-cell panels.
    let mut panel_m: Option<f64> = SimConfig::default().containment_panel_m;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--advection" => schemes.push(parse_advection(&args.next().expect("scheme"))),
            "--no-timing" => with_timing = false,
            "--diagnose" => diagnose_only = true,
            "--panel-m" => {
                let v = args.next().expect("PANEL_M");
                panel_m = if v == "none" {
                    None
                } else {
                    Some(v.parse().expect("PANEL_M: a thickness in m or `none`"))
                };
            }
            "--passes" => {
                let v = args.next().expect("MAX:TOL");
                let (m, t) = v.split_once(':').expect("--passes MAX:TOL");
                passes_cfg = Some((m.parse().expect("MAX"), t.parse().expect("TOL")));
            }
            v => ds.push(v.parse::<f64>().expect("diffusivity")),
        }
    }
    if schemes.is_empty() {
        schemes = vec![Advection::Upwind, Advection::VanLeer];
    }
    if ds.is_empty() {
        ds = vec![0.01];
    }
    let s = generate(&SynthOptions::new(Preset::Demo, 1).with_reference_runs(false)).unwrap();
    let alpha = s.truth.alpha_per_server();
    if diagnose_only {
        let states: Vec<OperatingState> = s.snapshots.iter().map(|sn| sn.state.clone()).collect();
        diagnose(
            &s.hall,
            &alpha,
            &states,
            &config(ds[0], schemes[0], passes_cfg, panel_m),
        );
        return;
    }
    let root = std::path::Path::new("data/openfoam/of-dev-clean");
    let of_hall = Hall::load(&root.join("hall.json")).unwrap();
    let of_snaps = load_snapshots(&of_hall, &root.join("snapshots.csv")).unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("truth.json")).unwrap()).unwrap();
    let of_alpha: Vec<f64> = of_hall
        .servers()
        .map(|sv| {
            truth["alpha_true_cfm_per_w"][&sv.server.server_type]
                .as_f64()
                .unwrap()
        })
        .collect();
    let mut rows = Vec::new();
    for &adv in &schemes {
        for &d in &ds {
            let mut res = Vec::new();
            let mut secs = Vec::new();
            let mut passes = 0;
            for cell in [0.2, 0.1] {
                let cfg = config(d, adv, passes_cfg, panel_m).with_cell_m(cell);
                let sim = Simulator::new(&s.hall, cfg).unwrap();
                let r: Vec<Vec<f64>> = s
                    .snapshots
                    .iter()
                    .map(|sn| {
                        let t = Instant::now();
                        let sol = sim.solve(&sn.state, &alpha, &[]).unwrap();
                        secs.push((cell, t.elapsed().as_secs_f64()));
                        passes = passes.max(sol.advection_stats.passes);
                        eprintln!(
                            "  {adv:?} cell {cell}: {} passes, last change {:.2e} C, {} BiCGSTAB iterations",
                            sol.advection_stats.passes,
                            sol.advection_stats.last_change_c,
                            sol.heat_stats.iterations
                        );
                        sol.sensor_c().to_vec()
                    })
                    .collect();
                res.push(r);
            }
            let mut diffs: Vec<(usize, usize, f64)> = Vec::new();
            for (k, (a, b)) in res[0].iter().zip(&res[1]).enumerate() {
                for (i, (x, y)) in a.iter().zip(b).enumerate() {
                    diffs.push((k, i, x - y));
                }
            }
            diffs.sort_by(|a, b| b.2.abs().total_cmp(&a.2.abs()));
            for (k, i, dd) in diffs.iter().take(4) {
                let sen = &s.hall.sensors[*i];
                println!(
                    "  {adv:?} D {d}: snap {k} {} at {:?}: 0.2 {:.2} 0.1 {:.2} diff {:+.2}",
                    sen.id, sen.position_m, res[0][*k][*i], res[1][*k][*i], dd
                );
            }
            let mut sd: Vec<f64> = diffs.iter().map(|x| x.2.abs()).collect();
            sd.sort_by(f64::total_cmp);
            let mean = sd.iter().sum::<f64>() / sd.len() as f64;
            let demo_s = secs
                .iter()
                .filter(|x| x.0 == 0.2)
                .map(|x| x.1)
                .fold(0.0, f64::max);
            // Realism against OpenFOAM at the default grid.
            let sim = Simulator::new(&of_hall, config(d, adv, passes_cfg, panel_m)).unwrap();
            let (mut e, mut n, mut mx) = (0.0, 0.0, 0.0f64);
            for sn in &of_snaps {
                let sol = sim.solve(&sn.state, &of_alpha, &[]).unwrap();
                let of = &truth["snapshots"][&sn.state.label]["sensor_c_noise_free"];
                for (sen, p) in of_hall.sensors.iter().zip(sol.sensor_c()) {
                    let o = of[&sen.id].as_f64().unwrap();
                    e += (p - o).abs();
                    n += 1.0;
                    mx = mx.max((p - o).abs());
                }
            }
            let timing_cols = if with_timing {
                let (td, pd, _, ed) = timing(
                    &sim_halls::demo_hall(),
                    400.0,
                    config(d, adv, passes_cfg, panel_m),
                );
                let (ta, pa, _, ea) = timing(
                    &sim_halls::hall_a(),
                    250.0,
                    config(d, adv, passes_cfg, panel_m),
                );
                format!("{td:.3} ({pd} passes, err {ed:.1e}) | {ta:.3} ({pa} passes, err {ea:.1e})")
            } else {
                "- | -".to_string()
            };
            rows.push(format!(
                "| {adv:?} | {d} | {mean:.3} | {:.3} | {:.3} | {:.3} | {mx:.2} | {demo_s:.3} ({passes} passes) | {timing_cols} |",
                sd[sd.len() * 9 / 10],
                sd[sd.len() - 1],
                e / n,
            ));
        }
    }
    println!("\n| advection | diffusivity m2/s | grid 0.2->0.1 mean C | p90 C | max C | MAE vs OpenFOAM C | max abs vs OpenFOAM C | synth demo s/solve (max of 3) | bench demo s/solve (median) | bench hall-a s/solve (median) |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        println!("{r}");
    }
}

/// `--diagnose`: how the containment of row A, rack A01 and sensor `c-A01-17` land on the
/// 0.2 m and 0.1 m grids, the flow through each containment side, and the temperatures
/// along the sensor's line (why the sensor moves between grids).
fn diagnose(hall: &Hall, alpha: &[f64], states: &[OperatingState], cfg: &SimConfig) {
    let sensor = hall
        .sensors
        .iter()
        .position(|s| s.id == "c-A01-17")
        .expect("sensor c-A01-17");
    let p = hall.sensors[sensor].position_m;
    for cell in [0.2, 0.1] {
        let sim = Simulator::new(hall, cfg.clone().with_cell_m(cell)).unwrap();
        let g = sim.grid().clone();
        let solid = sim.solid();
        println!("## cell {cell}: n {:?} d {:?}", g.n, g.d);
        for (ci, cb) in hall.containment.iter().enumerate() {
            let snapped: Vec<String> = (0..3)
                .map(|a| {
                    let lo = (cb.min_m[a] / g.d[a]).round() * g.d[a];
                    let hi = (cb.max_m[a] / g.d[a]).round() * g.d[a];
                    format!(
                        "{:.3}..{:.3} (given {}..{})",
                        lo, hi, cb.min_m[a], cb.max_m[a]
                    )
                })
                .collect();
            println!("containment {ci} wall planes: {}", snapped.join(", "));
        }
        let rack = &hall.racks[0];
        let rb = Aabb::from_position_size(rack.position_m, rack.size_m);
        let cells = g.cells_in_box(&rb);
        let ext: Vec<String> = (0..3)
            .map(|a| {
                let lo = cells.iter().map(|&c| g.ijk(c)[a]).min().unwrap();
                let hi = cells.iter().map(|&c| g.ijk(c)[a]).max().unwrap();
                format!(
                    "{:.3}..{:.3} (given {:.3}..{:.3})",
                    lo as f64 * g.d[a],
                    (hi + 1) as f64 * g.d[a],
                    rb.min[a],
                    rb.max[a]
                )
            })
            .collect();
        println!("rack {} solid cells: {}", rack.id, ext.join(", "));
        // The trilinear stencil as the topology builds it.
        let corners = g.trilinear_corners(p);
        println!("sensor c-A01-17 at {p:?}");
        let sols: Vec<_> = states
            .iter()
            .map(|st| sim.solve(st, alpha, &[]).unwrap())
            .collect();
        for (c, w) in corners.into_iter().filter(|&(_, w)| w > 1e-12) {
            println!(
                "  corner {:?} centre {:.3?} weight {w:.3} solid {} T(snap 3) {:.2}",
                g.ijk(c),
                g.cell_centre(c),
                solid[c],
                sols[2].temperature_c[c]
            );
        }
        for (k, sol) in sols.iter().enumerate() {
            print!("snap {k}: sensor {:.2} C;", sol.sensor_c()[sensor]);
            for (ci, cb) in hall.containment.iter().enumerate() {
                let flows = containment_flows(&g, sol, cb);
                print!(" containment {ci} outflow per side -x,+x,-y,+y: {flows:.4?} m3/s;");
            }
            println!(" supply {:.3} m3/s", sol.supply_flow_m3_s);
        }
        // Temperatures along x through the sensor (snapshot 3), and along z at x = 2.3.
        let j = g.cell_of(1, p[1]);
        let k = g.cell_of(2, p[2]);
        let row: Vec<String> = (0..g.n[0])
            .filter(|&i| g.centre(0, i) > 1.4 && g.centre(0, i) < 3.4)
            .map(|i| {
                format!(
                    "{:.2}:{:.1}",
                    g.centre(0, i),
                    sols[2].temperature_c[g.idx(i, j, k)]
                )
            })
            .collect();
        println!(
            "T along x at y {:.3} z {:.3}: {}",
            g.centre(1, j),
            g.centre(2, k),
            row.join(" ")
        );
    }
}

/// Net outflow (m3/s) through each vertical side of a containment box (-x, +x, -y, +y).
fn containment_flows(g: &Grid, sol: &Solution, cb: &Containment) -> [f64; 4] {
    let mut out = [0.0; 4];
    for (si, (a, at_max)) in [(0, false), (0, true), (1, false), (1, true)]
        .into_iter()
        .enumerate()
    {
        for low in g.box_side_faces(a, at_max, cb.min_m, cb.max_m) {
            let q = sol.face_flux_m3_s[a][low];
            out[si] += if at_max { q } else { -q };
        }
    }
    out
}
