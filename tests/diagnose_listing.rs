//! `kalibre diagnose`'s listing says which fits lie outside their parameter's range (a
//! bypass at a negative share, say: the data lean the opposite way), as its JSON does,
//! and never names one.

mod cli_support;

use cli_support::{on_dataset, run, stderr, tmp};

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
    let o = run(on_dataset("diagnose", "of-dev-clean")
        .arg("--calibration")
        .arg(&cal));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = text.lines().collect();
    // The listing shows the first 8, in the JSON's order.
    let mut outside = 0;
    for h in hyps.iter().take(8) {
        let name = h["name"].as_str().unwrap();
        let at = lines
            .iter()
            .position(|l| l.trim_start().starts_with(&format!("{name} ")) && l.contains("explains"))
            .unwrap_or_else(|| panic!("{name} not listed:\n{text}"));
        let flagged = lines[at].contains("fitted outside its range");
        let in_range = h["in_range"].as_bool().unwrap();
        assert_eq!(flagged, !in_range, "{name}: {}", lines[at]);
        if !in_range {
            outside += 1;
            assert_eq!(h["significant"], false, "{h}");
            // The next line gives the fitted values, which the JSON has too.
            let (param, value) = h["fitted"].as_object().unwrap().iter().next().unwrap();
            let value = value.as_f64().unwrap();
            assert!(
                lines[at + 1].contains(&format!("fitted {param} = {value:.4}"))
                    && lines[at + 1].contains("the data lean the opposite way"),
                "{}",
                lines[at + 1]
            );
        }
    }
    // On this hall the model's own error looks like negative bypasses (more supply at the
    // tiles), so the listing has some to flag.
    assert!(outside > 0, "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
