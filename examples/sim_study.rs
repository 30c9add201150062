//! Scratch: grid convergence on the synth demo and OpenFOAM realism vs diffusivity.
use kalibre_dc::hall::Hall;
use kalibre_dc::sim::{SimConfig, Simulator};
use kalibre_dc::snapshots::load_snapshots;
use kalibre_dc::synth::{generate, Preset, SynthOptions};

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().unwrap())
        .collect();
    let ds = if args.is_empty() {
        vec![0.01, 0.02, 0.03, 0.05]
    } else {
        args
    };
    let s = generate(&SynthOptions::new(Preset::Demo, 1).with_reference_runs(false)).unwrap();
    let alpha: Vec<f64> = s
        .truth
        .alpha_server_cfm_per_w
        .iter()
        .map(|a| a.alpha_cfm_per_w)
        .collect();
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
    for d in ds {
        let mut res = Vec::new();
        for cell in [0.2, 0.1] {
            let cfg = SimConfig {
                cell_m: cell,
                diffusivity_m2_s: d,
                ..SimConfig::default()
            };
            let sim = Simulator::new(&s.hall, cfg).unwrap();
            let r: Vec<Vec<f64>> = s
                .snapshots
                .iter()
                .map(|sn| {
                    sim.solve(&sn.state, &alpha, &[])
                        .unwrap()
                        .sensor_c()
                        .to_vec()
                })
                .collect();
            res.push(r);
        }
        let diffs: Vec<f64> = res[0]
            .iter()
            .zip(&res[1])
            .flat_map(|(a, b)| {
                a.iter()
                    .zip(b)
                    .map(|(x, y)| (x - y).abs())
                    .collect::<Vec<_>>()
            })
            .collect();
        let mut sd = diffs.clone();
        sd.sort_by(f64::total_cmp);
        let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
        // noise-free synth truth readings vs fine
        let cfg = SimConfig {
            diffusivity_m2_s: d,
            ..SimConfig::default()
        };
        let sim = Simulator::new(&of_hall, cfg).unwrap();
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
        let mut idx: Vec<(usize, usize, f64)> = Vec::new();
        for (k, (a, b)) in res[0].iter().zip(&res[1]).enumerate() {
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                idx.push((k, i, x - y));
            }
        }
        idx.sort_by(|a, b| b.2.abs().total_cmp(&a.2.abs()));
        for (k, i, dd) in idx.iter().take(8) {
            let sen = &s.hall.sensors[*i];
            println!(
                "  snap {k} {} at {:?}: 0.2 {:.2} 0.1 {:.2} diff {:+.2}",
                sen.id, sen.position_m, res[0][*k][*i], res[1][*k][*i], dd
            );
        }
        println!(
            "D {d}: grid 0.2->0.1 mean {:.3} p90 {:.3} max {:.3} | OF MAE {:.3} max {:.2}",
            mean,
            sd[sd.len() * 9 / 10],
            sd[sd.len() - 1],
            e / n,
            mx
        );
    }
}
