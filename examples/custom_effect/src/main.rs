//! The cut-out story: a demo hall whose measurements hide a leaking cable cut-out tile;
//! calibrate alpha, diagnose with the built-in kinds plus `cutout_bypass`, add the
//! suggested entry, recalibrate alpha with the cut-out's flow fraction.

use kalibre::dc::calibration::HallCalibrationSettings;
use kalibre::dc::hall::EffectSpec;
use kalibre_custom_effect::story::{
    best_cutout, calibrate, demo_hall, diagnose, with_effect, DemoOptions,
};
use kalibre_custom_effect::{registry, KIND};

fn entry(s: &EffectSpec) -> String {
    serde_json::to_string(s).unwrap_or_else(|e| format!("<{e}>"))
}

fn main() {
    if let Err(e) = run() {
        eprintln!("custom_effect: error: {e}");
        std::process::exit(1);
    }
}

fn run() -> kalibre::dc::Result<()> {
    let registry = registry()?;
    println!("effect kinds: {}", registry.kinds().join(", "));
    let options = DemoOptions::default();
    let demo = demo_hall(&options, &registry)?;
    println!(
        "hall `{}`: {} sensors, {} snapshots, noise {} C; hidden: {}",
        demo.hall.name,
        demo.hall.sensors.len(),
        demo.snapshots.len(),
        options.noise_c,
        entry(&demo.hidden)
    );
    println!(
        "model at the true alphas: MAE {:.3} C with the cut-out (the floor), {:.3} C without; \
         noise alone {:.3} C",
        demo.floor_mae_c, demo.no_effect_mae_c, demo.noise_mae_c
    );

    let settings = HallCalibrationSettings::default();
    println!("\n1. calibrate alpha alone");
    let first = calibrate(&demo.hall, &demo.snapshots, &registry, &settings)?;
    let best = first.calibration.report.best.params.values();
    println!(
        "   MAE {:.3} C -> {:.3} C ({} model runs, {:.1} s)",
        first.mae_before(),
        first.mae_after(),
        first.calibration.report.runs.total,
        first.wall_s
    );

    println!("\n2. diagnose (built-in kinds + {KIND})");
    let d = diagnose(&demo.hall, &demo.snapshots, &best, &registry)?;
    println!(
        "   {} hypotheses; MAE at the calibration {:.3} C",
        d.diagnosis.hypotheses.len(),
        d.diagnosis.mae
    );
    println!(
        "   {:>4}  {:<44} {:>9} {:>9} {:>5} {:>6} {:>6}",
        "rank", "hypothesis", "explained", "pred MAE", "sig", "inert", "ident"
    );
    for (i, h) in d.diagnosis.hypotheses.iter().enumerate().take(8) {
        println!(
            "   {:>4}  {:<44} {:>9.3} {:>9.3} {:>5} {:>6} {:>6}",
            i + 1,
            h.name,
            h.explained_fraction,
            h.predicted_mae,
            h.significant,
            h.inert,
            h.identifiable
        );
    }
    let Some((rank, suggestion)) = best_cutout(&d) else {
        println!("   no {KIND} hypothesis was ranked; stopping");
        return Ok(());
    };
    let h = &d.diagnosis.hypotheses[rank];
    println!(
        "   best {KIND}: rank {} of {}, {}significant, explained {:.3}, predicted MAE {:.3} C",
        rank + 1,
        d.diagnosis.hypotheses.len(),
        if h.significant { "" } else { "not " },
        h.explained_fraction,
        h.predicted_mae
    );
    println!(
        "   entry to paste into hall.json `effects`: {}",
        entry(suggestion)
    );

    println!(
        "\n3. add it and recalibrate alpha + {KIND}/flow_fraction (hall.json guess as the start)"
    );
    let hall2 = with_effect(&demo.hall, suggestion);
    let second = calibrate(&hall2, &demo.snapshots, &registry, &settings)?;
    let report = &second.calibration.report;
    let names = second.calibration.model.layout().space().names();
    let values = report.best.params.values();
    let fraction = names
        .iter()
        .zip(&values)
        .find(|(n, _)| n.starts_with(KIND))
        .map(|(_, v)| *v)
        .unwrap_or(f64::NAN);
    println!(
        "   MAE {:.3} C -> {:.3} C ({} model runs, {:.1} s); flow_fraction {:.3} (true {})",
        second.mae_before(),
        second.mae_after(),
        report.runs.total,
        second.wall_s,
        fraction,
        options.flow_fraction
    );

    println!("\nsummary");
    println!(
        "   alpha alone:        MAE {:.3} C -> {:.3} C",
        first.mae_before(),
        first.mae_after()
    );
    println!(
        "   alpha + {KIND}: MAE {:.3} C -> {:.3} C",
        second.mae_before(),
        second.mae_after()
    );
    println!(
        "   floor (model at truth): {:.3} C; noise alone: {:.3} C",
        demo.floor_mae_c, demo.noise_mae_c
    );
    Ok(())
}
