use kalibre_baselines::*;
use kalibre_core::{Calibrator, Settings};
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::sim::SimConfig;
use kalibre_dc::snapshots::{load_snapshots, to_observations};
use kalibre_dc::HallModel;
#[test]
fn probe() {
    let dir =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/openfoam/of-dev-clean");
    for mode in [AlphaMode::PerType, AlphaMode::PerServer] {
        let mut hall = Hall::load(&dir.join("hall.json")).unwrap();
        hall.calibrate.alpha = mode;
        let snaps = load_snapshots(&hall, &dir.join("snapshots.csv")).unwrap();
        let obs = to_observations(&hall, &snaps).unwrap();
        let model = HallModel::new(&hall, SimConfig::default()).unwrap();
        let space = model.layout().space().clone();
        for seed in 1..=3 {
            let r = run_es(
                &model,
                &obs,
                &space,
                &OnePlusOneEs::default().with_seed(seed),
                None,
            )
            .unwrap();
            let at10 = r
                .history
                .iter()
                .find(|h| h.iteration == 10)
                .unwrap()
                .best_mae_c;
            eprintln!("{mode:?} ES seed {seed}: init {:.3} @10 {:.3} best {:.3} runs {} to1.0 {:?} {:.1}s", r.initial_mae_c, at10, r.best_mae_c, r.model_runs, r.runs_to_reach(1.0), r.wall_s);
        }
        let m =
            ManualHeuristic::new(&hall, model.layout().clone(), ManualSettings::default()).unwrap();
        let r = m.run(&model, &obs, None).unwrap();
        eprintln!(
            "{mode:?} manual: init {:.3} best {:.3} runs {} to1.0 {:?} {:.1}s",
            r.initial_mae_c,
            r.best_mae_c,
            r.model_runs,
            r.runs_to_reach(1.0),
            r.wall_s
        );
        for seed in 1..=2 {
            let t = std::time::Instant::now();
            let mlp = Mlp::new(&hall, model.layout().clone(), MlpSettings::default()).unwrap();
            let st = Settings {
                seed,
                max_iterations: 20,
                focus: Some(1.0),
                explore_on_repeat: Some(0.015),
                ..Settings::default()
            };
            let rep = Calibrator::new(&model, mlp, &obs, &space)
                .with_settings(st)
                .run()
                .unwrap();
            let at10 = rep
                .history
                .iter()
                .find(|h| h.iteration == 10)
                .and_then(|h| h.best_mae_c);
            eprintln!(
                "{mode:?} MLP seed {seed}: init {:?} @10 {:?} best {:.3} runs {} {:.1}s",
                rep.initial.mae_c,
                at10,
                rep.best.mae_c,
                rep.runs.total,
                t.elapsed().as_secs_f64()
            );
        }
    }
}
