//! A hall, or an effect's place in it, that the built-in simulator's grid cannot hold is
//! bad input (exit 2), found before any run: a rack thinner than a cell, cells too coarse
//! for the tiles, a recirculation band that covers no cell. Before, the first two failed
//! as the model (exit 1), and the band failed every run that gave the effect a share, so
//! `calibrate` learned from the share-zero runs only and reported their fit.

mod cli_support;

use std::path::{Path, PathBuf};

use cli_support::{assert_input_error, data, on_files, run, stderr, tmp};

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
    // Cells wider than a rack that the simulator still builds: it solves a blur of the
    // hall, and says so, naming the thinnest equipment and cells that would hold it.
    let o = run(
        on_files("simulate", &data("of-dev-clean/hall.json"), &snaps)
            .args(["--grid-m", "0.8", "--out"])
            .arg(dir.join("blur.csv")),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "/racks/0/size_m is 0.6 m across in x, less than the built-in simulator's cells \
             of 0.8 m"
        ) && stderr(&o).contains("(--grid-m 0.15)"),
        "{}",
        stderr(&o)
    );
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

/// Cells that do not divide the room are not the cells solved on: the built-in
/// simulator puts a whole number on each side, and says which.
#[test]
fn cells_that_do_not_divide_the_room_are_named_as_solved() {
    let dir = tmp("grid-geometry-cells");
    let o = run(on_files(
        "simulate",
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
    )
    .args(["--grid-m", "0.25", "--out"])
    .arg(dir.join("pred.csv")));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    // 7.2 x 4.8 x 3.0 m: 28.8, 19.2 and 12 cells of 0.25 m, rounded.
    assert!(
        err.contains("cells of 0.25 m do not divide the room (7.2 x 4.8 x 3 m)")
            && err.contains("29 x 19 x 12 cells of 0.2483 x 0.2526 x 0.25 m"),
        "{err}"
    );
    let o = run(on_files(
        "simulate",
        &data("of-dev-clean/hall.json"),
        &data("of-dev-clean/snapshots.csv"),
    )
    .args(["--grid-m", "0.2", "--out"])
    .arg(dir.join("pred2.csv")));
    assert!(!String::from_utf8_lossy(&o.stderr).contains("do not divide"));
}

/// A hall whose CRAC blows through its front with no ceiling grilles is one the
/// built-in simulator reads far off (its air has no momentum): said once, with the
/// measured figures and the model that solves it; with grilles it is not warned of.
#[test]
fn front_supply_the_built_in_model_reads_far_off_is_warned_of() {
    let dir = tmp("grid-geometry-front");
    let snaps = data("of-dev-clean/snapshots.csv");
    let front = |returns: bool| {
        move |doc: &mut serde_json::Value| {
            doc["cracs"][0]["supply"] = serde_json::json!("front");
            doc.as_object_mut().unwrap().remove("tiles");
            if !returns {
                doc.as_object_mut().unwrap().remove("returns");
            }
        }
    };
    let bare = dev_hall_with(&dir, front(false));
    let o = run(on_files("simulate", &bare, &snaps)
        .arg("--out")
        .arg(dir.join("bare.csv")));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    let warned: Vec<&str> = err.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(warned.len(), 1, "{err}");
    assert!(
        warned[0].contains("/cracs/0 (`crac-1`) supplies through its front")
            && warned[0].contains("returns into the CRAC tops")
            && warned[0].contains("`--model openfoam` solves this hall"),
        "{err}"
    );
    let grilles = dir.join("grilles");
    std::fs::create_dir_all(&grilles).unwrap();
    let with = dev_hall_with(&grilles, front(true));
    let o = run(on_files("simulate", &with, &snaps)
        .arg("--out")
        .arg(dir.join("with.csv")));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("supplies through its front"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
