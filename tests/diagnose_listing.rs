//! `kalibre diagnose`'s listing says which fits lie outside their parameter's range (a
//! bypass at a negative share, say: the data lean the opposite way), as its JSON does,
//! and never names one, nor offers its entry; it is ordered by the BIC change, which
//! every line shows.

mod cli_support;

use cli_support::{data, kalibre, on_dataset, on_files, run, stderr, tmp, QUICK_CALIBRATION};

#[test]
fn fits_outside_their_range_are_flagged_in_text_and_json_alike() {
    let dir = tmp("listing");
    let cal = dir.join("cal");
    let o = run(on_dataset("calibrate", "of-dev-clean")
        .args(["--iterations", "2", "--polish", "0", "--quiet"])
        .arg("--out")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--json")
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    let hyps = d["hypotheses"].as_array().unwrap();
    // Its snapshots are steady: none is off at every sensor.
    assert_eq!(
        d["odd_snapshots"],
        serde_json::json!([]),
        "{}",
        d["odd_snapshots"]
    );
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = text.lines().collect();
    // The header says what the order is.
    assert!(
        text.contains("missing effects, best first: the significant ones, then the others, each in order of `BIC`"),
        "{text}"
    );
    // A fit outside its range has no entry to paste: clamped into the range it would be
    // the effect's absence (a bypass of fraction 0), an entry that does nothing.
    for h in hyps {
        let in_range = h["in_range"].as_bool().unwrap();
        assert_eq!(h["suggestion"].is_null(), !in_range, "{h}");
    }
    for zero in ["\"fraction\":0.0,", "\"fraction\":0.0}"] {
        assert!(!text.contains(zero), "{text}");
    }
    // The listing shows the first 8, in the JSON's order, each with its BIC change.
    let mut outside = 0;
    for h in hyps.iter().take(8) {
        let name = h["name"].as_str().unwrap();
        let at = lines
            .iter()
            .position(|l| l.trim_start().starts_with(&format!("{name} ")) && l.contains("explains"))
            .unwrap_or_else(|| panic!("{name} not listed:\n{text}"));
        let flagged = lines[at].contains("fitted outside its range");
        let in_range = h["in_range"].as_bool().unwrap();
        let bic = h["delta_bic"].as_f64().unwrap();
        assert!(
            lines[at].contains(&format!("  BIC {bic:+.1}  ")),
            "{name}: {}",
            lines[at]
        );
        assert_eq!(flagged, !in_range, "{name}: {}", lines[at]);
        if !in_range {
            outside += 1;
            assert_eq!(h["significant"], false, "{h}");
            // The next line gives the fitted values, which the JSON has too.
            let (param, value) = h["fitted"].as_object().unwrap().iter().next().unwrap();
            let value = value.as_f64().unwrap();
            assert!(
                lines[at + 1].contains(&format!("fitted {param} = {value:.4}"))
                    && lines[at + 1].contains("the data lean the opposite way")
                    && lines[at + 1].ends_with("no entry to add"),
                "{}",
                lines[at + 1]
            );
        }
    }
    // On this hall the model's own error looks like negative bypasses (more supply at the
    // tiles), so the listing has some to flag.
    assert!(outside > 0, "{text}");
    // The BIC orders those that are not significant (none is, here).
    let bics: Vec<f64> = hyps
        .iter()
        .map(|h| h["delta_bic"].as_f64().unwrap())
        .collect();
    assert!(bics.windows(2).all(|w| w[0] <= w[1]), "{bics:?}");
    // Nor does --write-hall write one: nothing significant, nothing written.
    let next = dir.join("next/hall.json");
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--calibration")
        .arg(&cal)
        .arg("--write-hall")
        .arg(&next));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!next.exists(), "{}", String::from_utf8_lossy(&o.stdout));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A snapshot whose setpoint was raised 3 C before its readings caught up is named on
/// its own, in the text and the JSON, rather than left spread over the sensors.
#[test]
fn a_snapshot_off_at_every_sensor_is_named() {
    let dir = tmp("listing-odd-snapshot");
    let text = std::fs::read_to_string(data("of-dev-clean/snapshots.csv")).unwrap();
    let shifted: String = text
        .lines()
        .map(|l| match l.split(',').collect::<Vec<_>>()[..] {
            ["t1", "setpoint_c", id, v] => {
                format!("t1,setpoint_c,{id},{}\n", v.parse::<f64>().unwrap() + 3.0)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    let snapshots = dir.join("snapshots.csv");
    std::fs::write(&snapshots, shifted).unwrap();
    let hall = data("of-dev-clean/hall.json");
    let cal = dir.join("cal");
    let o = run(on_files("calibrate", &hall, &snapshots)
        .args(["--iterations", "3", "--polish", "0", "--quiet"])
        .arg("--out")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let diagnose = |json: bool| {
        let mut c = on_files("diagnose", &hall, &snapshots);
        if json {
            c.arg("--json");
        }
        run(c.arg("--calibration").arg(&cal))
    };
    let o = diagnose(true);
    assert!(o.status.success(), "{}", stderr(&o));
    let d: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    let odd = d["odd_snapshots"].as_array().unwrap();
    assert_eq!(odd.len(), 1, "{odd:?}");
    assert_eq!(odd[0]["snapshot"], "t1");
    let shift = odd[0]["shift_c"].as_f64().unwrap();
    // The model reads warm there by most of the 3 C (the alphas take a little of it).
    assert!(shift > 2.0 && shift < 3.2, "{shift}");
    let o = diagnose(false);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains(&format!(
            "snapshot t1: the model reads {shift:.2} C too warm at "
        )) && text.contains("its conditions were likely not steady"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// On a hall whose CRACs all supply 1.5 C warm, the hall-wide offset is named and said to
/// be one the data cannot tell from the per-CRAC ones; those fit above their range of
/// 5 C, which the listing calls more than any entry gives, not the opposite of the effect.
#[test]
fn a_fit_above_its_range_and_an_unidentifiable_one_are_said_as_such() {
    let dir = tmp("listing-offset");
    let o = run(kalibre()
        .args(["synth", "--preset", "demo", "--seed", "3", "--effect"])
        .arg("crac_supply_offset:offset_c=1.5")
        .arg("--out")
        .arg(dir.join("hall")));
    assert!(o.status.success(), "{}", stderr(&o));
    let (hall, snapshots) = (dir.join("hall/hall.json"), dir.join("hall/snapshots.csv"));
    let cal = dir.join("cal");
    calibrate_quickly(&hall, &snapshots, &cal);
    let o = run(on_files("diagnose", &hall, &snapshots)
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains(
            "not identifiable: the data cannot tell it from crac_supply_offset(crac=crac-"
        ),
        "{text}"
    );
    assert!(
        text.contains(": above its range [-5, 5], more than any entry gives"),
        "{text}"
    );
    assert!(!text.contains("lean the opposite way"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two effects of one kind: the second's parameters are `<kind>#2/<name>`
/// (`docs/formats.md`), and the calibration's report.html and terminal summary say beside
/// each where its effect acts, so that `rack_recirculation#2/fraction` reads as the one in
/// rack B04.
#[test]
fn parameters_of_two_effects_of_one_kind_say_where_each_acts() {
    let dir = tmp("listing-two-of-a-kind");
    let o = run(kalibre()
        .args(["synth", "--preset", "demo", "--seed", "1", "--out"])
        .arg(dir.join("hall")));
    assert!(o.status.success(), "{}", stderr(&o));
    let (hall, snapshots) = (dir.join("hall/hall.json"), dir.join("hall/snapshots.csv"));
    let mut h: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&hall).unwrap()).unwrap();
    h["effects"] = serde_json::json!([
        { "kind": "rack_recirculation", "rack": "A05", "fraction": 0.1 },
        { "kind": "rack_recirculation", "rack": "B04", "fraction": 0.1 }
    ]);
    std::fs::write(&hall, serde_json::to_string_pretty(&h).unwrap()).unwrap();
    let cal = dir.join("cal");
    let stdout = calibrate_quickly(&hall, &snapshots, &cal);
    for label in [
        "rack_recirculation/fraction (rack A05)",
        "rack_recirculation#2/fraction (rack B04)",
    ] {
        assert!(
            stdout.lines().any(|l| l.trim_start().starts_with(label)),
            "{label} not among the best parameters: {stdout}"
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cal.join("report.json")).unwrap()).unwrap();
    let params = report["best"]["params"].as_object().unwrap();
    assert!(
        params.contains_key("rack_recirculation/fraction"),
        "{params:?}"
    );
    assert!(
        params.contains_key("rack_recirculation#2/fraction"),
        "{params:?}"
    );
    let html = std::fs::read_to_string(cal.join("report.html")).unwrap();
    for label in [
        "<td>rack_recirculation/fraction (rack A05)</td>",
        "<td>rack_recirculation#2/fraction (rack B04)</td>",
    ] {
        assert!(html.contains(label), "{label} not in report.html");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A quick calibration of `hall` against `snapshots` into `cal`, which must succeed; its
/// terminal output.
fn calibrate_quickly(
    hall: &std::path::Path,
    snapshots: &std::path::Path,
    cal: &std::path::Path,
) -> String {
    let o = run(on_files("calibrate", hall, snapshots)
        .args(QUICK_CALIBRATION)
        .arg("--out")
        .arg(cal));
    assert!(o.status.success(), "{}", stderr(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}
