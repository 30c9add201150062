//! A hall, or an effect's place in it, that the built-in simulator's grid cannot hold is
//! bad input (exit 2), found before any run: a rack thinner than a cell, cells too coarse
//! for the tiles, a recirculation band that covers no cell. Before, the first two failed
//! as the model (exit 1), and the band failed every run that gave the effect a share, so
//! `calibrate` learned from the share-zero runs only and reported their fit.

mod cli_support;

use std::path::{Path, PathBuf};

use cli_support::{assert_input_error, data, on_files, run, tmp};

/// The clean development hall with `edit` applied, written to `dir/hall.json`.
fn dev_hall_with(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
    let text = std::fs::read_to_string(data("of-dev-clean/hall.json")).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    edit(&mut doc);
    let path = dir.join("hall.json");
    std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    path
}

#[test]
fn a_rack_thinner_than_a_cell_and_too_coarse_cells_are_input_errors() {
    let dir = tmp("grid-geometry-rack");
    let snaps = data("of-dev-clean/snapshots.csv");
    let thin = dev_hall_with(&dir, |doc| {
        doc["racks"][0]["size_m"] = serde_json::json!([0.6, 1e-6, 2.0]);
    });
    let o = run(on_files("simulate", &thin, &snaps)
        .arg("--out")
        .arg(dir.join("thin.csv")));
    assert_input_error(
        &o,
        "its rack is 1e-6 m across in y, less than a cell of 0.2 m",
    );
    assert!(!dir.join("thin.csv").exists());

    let o = run(
        on_files("simulate", &data("of-dev-clean/hall.json"), &snaps)
            .args(["--grid-m", "3", "--out"])
            .arg(dir.join("coarse.csv")),
    );
    assert_input_error(&o, "use finer cells (`--grid-m`)");
}

#[test]
fn an_effect_that_acts_on_no_cell_is_refused_before_any_run() {
    let dir = tmp("grid-geometry-band");
    let snaps = data("of-dev-clean/snapshots.csv");
    // One micrometre of rack height, on the cell boundary at z = 1.0 m.
    let band = dev_hall_with(&dir, |doc| {
        doc["effects"] = serde_json::json!([{
            "kind": "rack_recirculation", "rack": "A2", "fraction": 0.1,
            "z_m": [1.0, 1.000001]
        }]);
    });
    // Named as the hall file's entry, as a bad field of it would be.
    let needle = format!(
        "{}: /effects/0: effect `rack_recirculation`: rack `A2`'s recirculation in z \
         1-1.000001 m, at its exhaust face, covers no open cell on cells of 0.2 m",
        band.display()
    );
    let needle = needle.as_str();
    let o = run(on_files("simulate", &band, &snaps)
        .arg("--out")
        .arg(dir.join("band.csv")));
    assert_input_error(&o, needle);

    let out = dir.join("cal");
    let o = run(on_files("calibrate", &band, &snaps)
        .args(["--iterations", "1", "--out"])
        .arg(&out));
    assert_input_error(&o, needle);
    assert!(!out.join("runs.jsonl").exists(), "no run was made");

    // The same band two cells high acts, and simulates.
    let band = dev_hall_with(&dir, |doc| {
        doc["effects"] = serde_json::json!([{
            "kind": "rack_recirculation", "rack": "A2", "fraction": 0.1,
            "z_m": [1.0, 1.4]
        }]);
    });
    let o = run(on_files("simulate", &band, &snaps)
        .arg("--out")
        .arg(dir.join("band.csv")));
    assert!(o.status.success(), "{}", cli_support::stderr(&o));
}
