//! The paper's experiments (`examples/table4.rs`, `fig7.rs`, `fig8.rs`) in their quick
//! mode, through the same code the binaries run, so they cannot rot. About 30 s in a
//! release build (`cargo test --release --test experiments`).

#[path = "../examples/experiments/mod.rs"]
mod experiments;

use std::path::PathBuf;

use experiments::{fig7, fig8, table4};
use kalibre::dc::calibration::{calibrate_hall, HallCalibrationSettings};
use kalibre::dc::synth::Preset;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("kalibre-experiments-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn quiet(_: &str) {}

#[test]
fn table4_quick_every_approach_improves_and_files_are_written() {
    let t = table4::run_hall(
        Preset::Demo,
        1,
        table4::Budgets::quick(),
        &table4::Approach::ALL,
        false,
        false,
        &quiet,
    )
    .unwrap();
    assert_eq!(t.rows.len(), 4);
    assert!(t.initial_mae_c.is_finite() && t.initial_mae_c > 1.0);
    for row in &t.rows {
        assert!(!row.runs.is_empty(), "{}", row.approach);
        for r in &row.runs {
            assert!(
                (r.initial_mae_c - t.initial_mae_c).abs() < 1e-9,
                "{}: same model and measurements",
                row.approach
            );
            assert!(r.lowest_mae_c.is_finite() && r.mae_after_10_c.is_finite());
            assert!(r.lowest_mae_c <= r.mae_after_10_c + 1e-12);
            assert!(
                r.lowest_mae_c < 0.9 * r.initial_mae_c,
                "{}: lowest {} vs initial {}",
                row.approach,
                r.lowest_mae_c,
                r.initial_mae_c
            );
            assert!(r.model_runs_to_lowest <= r.model_runs && r.model_runs > 0);
            // The history's best never rises and its run count never falls.
            for w in r.history.windows(2) {
                assert!(w[1].1 >= w[0].1 && w[1].2 <= w[0].2, "{}", row.approach);
            }
        }
    }
    let dir = temp_dir("table4");
    let json = experiments::write_json(&dir, "table4.json", &vec![&t]).unwrap();
    let md = experiments::write_file(
        &dir,
        "table4.md",
        &table4::markdown(std::slice::from_ref(&t)),
    )
    .unwrap();
    let back: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    assert_eq!(back[0]["rows"].as_array().unwrap().len(), 4);
    let text = std::fs::read_to_string(md).unwrap();
    assert!(text.contains("Kalibre") && text.contains("(1+1)-ES") && text.contains("Manual"));
    // The quick budgets stop before iteration 10: the column says where they stopped.
    assert!(text.contains(" (ran 4 it.)"), "{text}");
    // And the budgets each row ran with are stated.
    assert!(
        text.contains(
            "budgets: Kalibre 4 iterations, MLP 3 iterations, (1+1)-ES 12 mutations, manual 6 \
             iterations"
        ),
        "{text}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn the_kalibre_row_is_calibrate_hall() {
    // The experiments assemble the loop themselves (to swap surrogate or searcher);
    // with Kalibre's parts it must be exactly `calibrate_hall`.
    let s = experiments::setup(Preset::Demo, false).unwrap();
    let mut st = HallCalibrationSettings::default();
    st.core.max_iterations = 2;
    st.core.seed = 3;
    // The experiments run no grid check (`run_loop`'s doc); with it the polish would
    // weigh the sensors by the finer grids.
    st.grid_check.clear();
    let ours = experiments::run_loop(
        &s,
        experiments::kalibre_surrogate(&s, &st).unwrap(),
        st.searcher.clone(),
        &st,
        None,
    )
    .unwrap();
    let theirs = calibrate_hall(&s.hall, &s.snaps, &st, None, Vec::new())
        .unwrap()
        .report;
    // Two loop iterations, then whatever polish steps the hall defaults add.
    assert!(ours.history.len() >= 2);
    assert_eq!(ours.history.len(), theirs.history.len());
    for (a, b) in ours.history.iter().zip(&theirs.history) {
        assert_eq!(a.mae_c, b.mae_c);
        assert_eq!(a.params, b.params);
    }
    assert_eq!(ours.best.mae_c, theirs.best.mae_c);
}

#[test]
fn fig7_quick_is_finite_and_some_surrogate_learns() {
    let r = fig7::run_fig7(&fig7::Fig7Config::quick(), &quiet).unwrap();
    assert_eq!(r.curves.len(), fig7::SURROGATES.len());
    assert_eq!(r.train + r.test + r.failed_runs, 40);
    for c in &r.curves {
        assert_eq!(c.points.len(), 4);
        for p in &c.points {
            assert!(
                p.mae_c.mean.is_finite() && p.mae_c.mean > 0.0,
                "{}",
                c.surrogate
            );
        }
        // More data never means fewer samples.
        assert!(c
            .points
            .windows(2)
            .all(|w| w[1].train_samples > w[0].train_samples));
    }
    // With half the training set, the best surrogate beats predicting the training mean.
    let best_at_50 = r
        .curves
        .iter()
        .map(|c| c.points[3].mae_c.mean)
        .fold(f64::INFINITY, f64::min);
    assert!(
        best_at_50 < r.mean_predictor_mae_c,
        "{best_at_50} vs {}",
        r.mean_predictor_mae_c
    );
    let dir = temp_dir("fig7");
    let svg = experiments::write_file(&dir, "fig7.svg", &fig7::svg(&r)).unwrap();
    let text = std::fs::read_to_string(svg).unwrap();
    assert!(
        text.starts_with("<svg")
            && text.contains("polyline")
            && text.trim_end().ends_with("</svg>")
    );
    experiments::write_json(&dir, "fig7.json", &r).unwrap();
    std::fs::remove_dir_all(dir).unwrap();
}

/// A graph option changes both graphs' test MAE in one aisle (`hot`) and leaves the other
/// aisle as it was, up to rounding, and the MLP exactly as it was.
fn assert_only_one_aisle_changes(base: &fig7::Fig7Result, changed: &fig7::Fig7Result, hot: bool) {
    let mae = |r: &fig7::Fig7Result, i: usize| -> Vec<f64> {
        r.curves[i].points.iter().map(|p| p.mae_c.mean).collect()
    };
    assert_eq!(base.curves[2].surrogate, "vanilla MLP");
    assert_eq!(mae(changed, 2), mae(base, 2));
    for graph in [0, 1] {
        let aisle = |r: &fig7::Fig7Result, hot: bool| -> Vec<f64> {
            r.curves[graph]
                .points
                .iter()
                .map(|p| if hot { &p.hot_mae_c } else { &p.cold_mae_c })
                .map(|m| m.as_ref().unwrap().mean)
                .collect()
        };
        let name = &base.curves[graph].surrogate;
        assert_ne!(aisle(changed, hot), aisle(base, hot), "{name}");
        for (a, b) in aisle(changed, !hot).iter().zip(aisle(base, !hot)) {
            assert!((a - b).abs() <= 1e-6 * b, "{name}: {a} vs {b}");
        }
    }
}

#[test]
fn fig7_rise_draw_varies_the_sensors_and_the_thermal_graph_learns_it() {
    let linear = fig7::run_fig7(&fig7::Fig7Config::quick(), &quiet).unwrap();
    let cfg = fig7::Fig7Config {
        draw: fig7::AlphaDraw::Rise,
        ..fig7::Fig7Config::quick()
    };
    let r = fig7::run_fig7(&cfg, &quiet).unwrap();
    // Rises of 5-20 K move the sensors more than alphas spread over [0.01, 3] cfm/W,
    // whose rises are mostly under 2 K.
    assert!(
        r.mean_predictor_mae_c > linear.mean_predictor_mae_c,
        "{} vs {}",
        r.mean_predictor_mae_c,
        linear.mean_predictor_mae_c
    );
    let fixed_at_50 = r.curves[0].points[3].mae_c.mean;
    assert!(
        fixed_at_50 < r.mean_predictor_mae_c,
        "{fixed_at_50} vs {}",
        r.mean_predictor_mae_c
    );
    let back: fig7::Fig7Result = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
    assert_eq!(back.config.draw, fig7::AlphaDraw::Rise);
    assert!(fig7::markdown(&r).contains("temperature rise uniform in [5, 20] K"));

    // Sharper server-sensor edges change both graphs and leave the MLP as it was.
    let sharp = fig7::run_fig7(
        &fig7::Fig7Config {
            sharp_adjacency: true,
            ..cfg
        },
        &quiet,
    )
    .unwrap();
    let curve = |r: &fig7::Fig7Result, i: usize| -> Vec<f64> {
        r.curves[i].points.iter().map(|p| p.mae_c.mean).collect()
    };
    assert_eq!(r.curves[2].surrogate, "vanilla MLP");
    assert_eq!(curve(&sharp, 2), curve(&r, 2));
    for graph in [0, 1] {
        assert_ne!(
            curve(&sharp, graph),
            curve(&r, graph),
            "{}",
            r.curves[graph].surrogate
        );
    }
    assert!(fig7::markdown(&sharp).contains("1/d^4 with the height difference halved"));

    // The local recirculation term changes both graphs' cold-aisle predictions only.
    let local = fig7::run_fig7(
        &fig7::Fig7Config {
            local_recirculation: true,
            ..cfg
        },
        &quiet,
    )
    .unwrap();
    // Hot-aisle sensors take a zero feature: the same up to rounding.
    assert_only_one_aisle_changes(&r, &local, false);
    assert!(fig7::markdown(&local).contains("whole-hall local recirculation term"));

    // Edges from the model's air flow change both graphs' hot-aisle predictions only.
    let influence = fig7::run_fig7(
        &fig7::Fig7Config {
            influence_adjacency: true,
            ..cfg
        },
        &quiet,
    )
    .unwrap();
    assert_only_one_aisle_changes(&r, &influence, true);
    assert!(fig7::markdown(&influence).contains("edges from the model's air flow"));
}

#[test]
fn fig7_per_rack_draw_gives_each_rack_one_alpha_and_the_graph_learns_it() {
    let setup = experiments::setup(Preset::Demo, false).unwrap();
    let mut hall = setup.hall.clone();
    hall.calibrate.alpha = kalibre::dc::hall::AlphaMode::PerServer;
    let layout = kalibre::dc::ParamLayout::new(&hall, &[]).unwrap();
    let rack_of: Vec<usize> = hall.servers().map(|s| s.rack_index).collect();
    let draw = |grain| {
        let cfg = fig7::Fig7Config {
            grain,
            samples: 5,
            draw: fig7::AlphaDraw::Rise,
            ..fig7::Fig7Config::quick()
        };
        let mut rng = rand::SeedableRng::seed_from_u64(1);
        fig7::draw_alphas(&cfg, layout.space(), &rack_of, &mut rng).unwrap()
    };
    let same_rack = |a: usize, b: usize| rack_of[a] == rack_of[b];
    for (grain, shared_in_rack) in [
        (fig7::AlphaGrain::Rack, true),
        (fig7::AlphaGrain::Server, false),
    ] {
        for x in draw(grain) {
            assert_eq!(x.len(), rack_of.len());
            for i in 1..x.len() {
                if same_rack(i - 1, i) {
                    assert_eq!(x[i - 1] == x[i], shared_in_rack, "{grain:?}, servers {i}");
                } else {
                    assert_ne!(x[i - 1], x[i], "{grain:?}: racks draw apart");
                }
            }
        }
    }
    // A per-rack draw on a per-type layout is refused, not guessed.
    let cfg = fig7::Fig7Config {
        grain: fig7::AlphaGrain::Rack,
        ..fig7::Fig7Config::quick()
    };
    let mut rng = rand::SeedableRng::seed_from_u64(1);
    assert!(fig7::draw_alphas(&cfg, setup.model.layout().space(), &rack_of, &mut rng).is_err());

    let r = fig7::run_fig7(
        &fig7::Fig7Config {
            draw: fig7::AlphaDraw::Rise,
            ..cfg
        },
        &quiet,
    )
    .unwrap();
    assert_eq!(r.params, rack_of.len());
    // The fixed-adjacency graph knows which racks feed which sensor: with half the
    // training set it beats predicting the training mean.
    let fixed_at_50 = &r.curves[0].points[3];
    assert!(
        fixed_at_50.mae_c.mean < r.mean_predictor_mae_c,
        "{} vs {}",
        fixed_at_50.mae_c.mean,
        r.mean_predictor_mae_c
    );
    // The overall MAE lies between the two aisles' (a mean over both).
    let (cold, hot) = (
        fixed_at_50.cold_mae_c.as_ref().unwrap().mean,
        fixed_at_50.hot_mae_c.as_ref().unwrap().mean,
    );
    let all = fixed_at_50.mae_c.mean;
    assert!(
        cold.min(hot) <= all + 1e-12 && all <= cold.max(hot) + 1e-12,
        "{cold} {all} {hot}"
    );
    let md = fig7::markdown(&r);
    assert!(md.contains("one draw per rack") && md.contains("By aisle, cold / hot"));
}

#[test]
fn fig8_quick_records_every_iteration_of_both_searchers() {
    let cfg = fig8::Fig8Config::quick();
    let r = fig8::run_fig8(&cfg, &quiet).unwrap();
    assert_eq!(r.variants.len(), 2);
    for v in &r.variants {
        assert_eq!(v.runs.len(), cfg.seeds);
        assert_eq!(v.mean_loss.len(), cfg.iterations, "{}", v.name);
        for run in &v.runs {
            for t in run {
                assert!(t.mean_loss.is_finite() && t.mean_loss >= 0.0, "{}", v.name);
                assert!(t.mean_grad_norm.is_finite() && t.mean_grad_norm >= 0.0);
                assert!(
                    t.final_loss <= t.mean_loss + 1e-9,
                    "the proposal is the best point"
                );
                assert!(t.best_mae_c.is_finite());
            }
            let last = run.last().unwrap();
            assert!(
                last.best_mae_c < r.initial_mae_c,
                "{}: {} vs {}",
                v.name,
                last.best_mae_c,
                r.initial_mae_c
            );
        }
    }
    let dir = temp_dir("fig8");
    let svg = experiments::write_file(&dir, "fig8.svg", &fig8::svg(&r)).unwrap();
    assert!(
        std::fs::read_to_string(svg)
            .unwrap()
            .matches("<svg")
            .count()
            == 5
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bad_arguments_are_named() {
    let parse = |v: &[&str]| experiments::parse_args(v.iter().map(|s| s.to_string()));
    let a = parse(&["--quick", "--presets", "hall-a:3,hall-b", "--out-dir", "x"]).unwrap();
    assert!(a.quick);
    assert_eq!(
        a.presets.unwrap(),
        vec![(Preset::HallA, Some(3)), (Preset::HallB, None)]
    );
    assert!(parse(&["--seeds", "0"]).unwrap_err().contains("--seeds"));
    assert!(parse(&["--seeds"]).unwrap_err().contains("--seeds"));
    assert!(parse(&["--presets", "hall-c"])
        .unwrap_err()
        .contains("hall-c"));
    assert!(parse(&["--presets", "hall-a:x"])
        .unwrap_err()
        .contains("hall-a:x"));
    assert!(parse(&["--fast"]).unwrap_err().contains("--fast"));
}

#[test]
fn table4_paper_loop_runs_the_loop_rows_in_algorithm_1() {
    let run = |paper_loop| {
        table4::run_hall(
            Preset::Demo,
            1,
            table4::Budgets::quick(),
            &[table4::Approach::Kalibre],
            false,
            paper_loop,
            &quiet,
        )
        .unwrap()
    };
    let (ours, paper) = (run(false), run(true));
    assert!(paper.paper_loop && !ours.paper_loop);
    let (a, b) = (&ours.rows[0].runs[0], &paper.rows[0].runs[0]);
    assert_eq!(
        a.initial_mae_c, b.initial_mae_c,
        "same measurements and model"
    );
    assert!(
        b.lowest_mae_c < b.initial_mae_c,
        "the paper's loop improves too"
    );
    // Another loop: the trajectories differ.
    assert_ne!(a.mae_after_10_c, b.mae_after_10_c);
    assert!(table4::markdown(std::slice::from_ref(&paper)).contains("in the paper's loop"));
    // Algorithm 1 keeps the run with the lowest error: kalibre's rule for halls (error
    // plus the rise prior) must not leak into it.
    let mut st = HallCalibrationSettings::default();
    assert!(
        st.core.prior_in_best,
        "kalibre's loop ranks by error plus prior"
    );
    experiments::use_paper_loop(&mut st).unwrap();
    assert!(
        !st.core.prior_in_best,
        "the paper's loop ranks by error alone"
    );
}

#[test]
fn table4_combine_merges_approaches_and_refuses_other_measurements() {
    use table4::Approach;
    let run = |a: &[Approach]| {
        table4::run_hall(
            Preset::Demo,
            1,
            table4::Budgets::quick(),
            a,
            false,
            false,
            &quiet,
        )
        .unwrap()
    };
    let (es, manual) = (run(&[Approach::Es]), run(&[Approach::Manual]));
    assert_eq!(es.rows.len(), 1);
    assert!(es.targets.best_after_10.is_none() && es.targets.es_ratio_met.is_none());
    let dir = temp_dir("table4-combine");
    let write = |name: &str, t: &table4::HallTable| {
        experiments::write_json(&dir, name, &serde_json::json!({ "halls": [t] })).unwrap()
    };
    // A second manual row that must win over the first (the later file).
    let mut later = manual.clone();
    later.rows[0].lowest_mae_c.mean = 0.125;
    let files = [
        write("manual.json", &manual),
        write("es.json", &es),
        write("later.json", &later),
    ];
    let merged = table4::combine(&files).unwrap();
    assert_eq!(merged.len(), 1);
    let names: Vec<&str> = merged[0].rows.iter().map(|r| r.approach.as_str()).collect();
    assert_eq!(names, [Approach::Es.title(), Approach::Manual.title()]);
    assert_eq!(merged[0].rows[1].lowest_mae_c.mean, 0.125);
    // Tables not on the same footing are refused, naming the file: other measurements
    // (another initial MAE), or the paper's loop against kalibre's.
    let refused = |name: &str, change: &dyn Fn(&mut table4::HallTable)| {
        let mut other = es.clone();
        change(&mut other);
        let bad = write(name, &other);
        let err = table4::combine(&[files[0].clone(), bad])
            .unwrap_err()
            .to_string();
        assert!(err.contains(name), "{err}");
        err
    };
    let err = refused("other.json", &|t| t.initial_mae_c += 0.01);
    assert!(err.contains("initial MAE"), "{err}");
    let err = refused("paper.json", &|t| t.paper_loop = true);
    assert!(err.contains("paper's loop"), "{err}");
    assert_eq!(
        Approach::parse_list("manual, kalibre,manual").unwrap(),
        [Approach::Kalibre, Approach::Manual]
    );
    assert!(Approach::parse_list("kalibre,nn")
        .unwrap_err()
        .contains("nn"));
    let b = table4::Budgets::full().with_overrides("mlp=5").unwrap();
    assert_eq!((b.mlp, b.es), (5, 150));
    assert!(table4::Budgets::full().with_overrides("es=0").is_err());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn ratio_interval_is_a_seeded_percentile_bootstrap() {
    use experiments::ratio_interval;
    // Constant samples: every resample gives the ratio itself.
    assert_eq!(ratio_interval(&[30.0; 4], &[15.0; 16]), Some((2.0, 2.0)));
    // Two values: resampled means 18, 31.5 or 45 with chances 1/4, 1/2, 1/4, so the
    // 2.5 % and 97.5 % points are the extremes.
    assert_eq!(ratio_interval(&[18.0, 45.0], &[15.0; 3]), Some((1.2, 3.0)));
    // Varied samples: the interval holds the ratio of means and repeats exactly.
    let mlp = [27.0, 18.0, 30.0, 18.0, 33.0, 30.0, 45.0, 18.0];
    let kalibre = [15.0, 15.0, 18.0, 15.0];
    let (lo, hi) = ratio_interval(&mlp, &kalibre).unwrap();
    let point = (mlp.iter().sum::<f64>() / 8.0) / (kalibre.iter().sum::<f64>() / 4.0);
    assert!(lo < point && point < hi, "{lo} {point} {hi}");
    assert_eq!(ratio_interval(&mlp, &kalibre), Some((lo, hi)));
    assert_eq!(ratio_interval(&[], &kalibre), None);
    // One seed resamples to itself: no interval.
    assert_eq!(ratio_interval(&[30.0], &kalibre), None);
    assert_eq!(ratio_interval(&mlp, &[0.0]), None);
}
