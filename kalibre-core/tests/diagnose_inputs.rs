//! The diagnosis's inputs and outputs: residuals stacked from observations, clear errors
//! for bad shapes, values and settings, a JSON round trip, and no calibrated parameter.

use kalibre_core::diagnose::{
    diagnose, measured_rows, DiagnoseSettings, Diagnosis, Hypothesis, HypothesisParam, Residuals,
};
use kalibre_core::{Error, Observations, OutputInfo, Snapshot};
use ndarray::Array2;

mod diagnose_support;
use diagnose_support::*;

#[test]
fn diagnosis_round_trips_through_json() {
    let p = Problem::new(81, 2, 30);
    let d = diagnose(
        &p.residuals(0.5),
        &p.hypotheses(),
        &DiagnoseSettings::new().with_noise_sigma(SIGMA),
    )
    .unwrap();
    let json = serde_json::to_string(&d).unwrap();
    assert!(json.contains("\"fitted\":{\"b/q0\":"), "{json}");
    let back: Diagnosis = serde_json::from_str(&json).unwrap();
    assert_eq!(back, d);
}

#[test]
fn stacking_from_observations_skips_unmeasured_values() {
    let outputs = ["x", "y", "z"]
        .map(|n| OutputInfo {
            name: n.into(),
            group: "cold".into(),
        })
        .to_vec();
    let obs = Observations::new(
        outputs,
        vec![
            Snapshot {
                label: "t0".into(),
                scenario: (),
                measured: vec![Some(1.0), None, Some(3.0)],
            },
            Snapshot {
                label: "t1".into(),
                scenario: (),
                measured: vec![Some(2.0), Some(2.0), Some(2.0)],
            },
        ],
    )
    .unwrap();
    let predicted = vec![vec![1.5, 9.0, 2.0], vec![2.0, 2.5, 1.0]];
    let jac = |s: f64| Array2::from_shape_fn((3, 1), |(i, _)| s + i as f64);
    let res =
        Residuals::from_observations(&obs, &predicted, &[jac(0.0), jac(10.0)], vec!["k".into()])
            .unwrap();
    assert_eq!(res.residuals(), &[0.5, -1.0, 0.0, 0.5, -1.0]);
    assert_eq!(
        res.jacobian().column(0).to_vec(),
        vec![0.0, 2.0, 10.0, 11.0, 12.0]
    );
    let rows = measured_rows(&obs);
    assert_eq!(rows.len(), 5);
    assert_eq!(
        (rows[1].output.as_str(), rows[1].snapshot.as_str()),
        ("z", "t0")
    );
    let h = Hypothesis::from_snapshots(
        "h",
        vec![HypothesisParam::with_scale("h/q", 1.0)],
        &obs,
        &[jac(1.0), jac(2.0)],
    )
    .unwrap();
    assert_eq!(h.jacobian.column(0).to_vec(), vec![1.0, 3.0, 2.0, 3.0, 4.0]);
    // A block of the wrong shape names the snapshot.
    let err = Hypothesis::from_snapshots("h", vec![], &obs, &[jac(1.0), Array2::zeros((2, 1))])
        .unwrap_err();
    assert!(err.to_string().contains("snapshot `t1`"), "{err}");
}

#[test]
fn bad_input_gets_clear_errors() {
    let p = Problem::new(91, 2, 10);
    let n = p.n;
    let j = matrix(n, &p.j);
    let names = || vec!["u".to_string(), "v".to_string()];
    let msg = |e: Error| e.to_string();
    // Shapes.
    let e = Residuals::new(p.rows.clone(), vec![0.0; n - 1], j.clone(), names()).unwrap_err();
    assert!(msg(e).contains("19 residuals for 20"));
    let e = Residuals::new(p.rows.clone(), vec![0.0; n], j.clone(), vec!["u".into()]).unwrap_err();
    assert!(msg(e).contains("Jacobian is 20x2, expected 20x1"));
    let e = Residuals::new(vec![], vec![], Array2::zeros((0, 0)), vec![]).unwrap_err();
    assert!(msg(e).contains("at least one residual"));
    // NaN, named by output and snapshot.
    let mut r = vec![0.1; n];
    r[13] = f64::NAN;
    let e = Residuals::new(p.rows.clone(), r, j.clone(), names()).unwrap_err();
    assert!(msg(e).contains("output `s3` in snapshot `t1` is NaN"));
    let mut jn = j.clone();
    jn[[2, 1]] = f64::INFINITY;
    let e = Residuals::new(p.rows.clone(), vec![0.1; n], jn, names()).unwrap_err();
    assert!(msg(e).contains("parameter `v` is inf"));
    let res = Residuals::new(p.rows.clone(), p.noise.clone(), j, names()).unwrap();
    let s = DiagnoseSettings::new();
    let run = |h: Vec<Hypothesis>| msg(diagnose(&res, &h, &s).unwrap_err());
    let bad_rows = Hypothesis::new(
        "h",
        vec![HypothesisParam::bounded("h/q", 0.0, 1.0)],
        Array2::zeros((n + 1, 1)),
    );
    assert!(run(vec![bad_rows]).contains("hypothesis `h`: Jacobian is 21x1, expected 20x1"));
    let bad_cols = Hypothesis::new(
        "h",
        vec![HypothesisParam::bounded("h/q", 0.0, 1.0)],
        Array2::zeros((n, 2)),
    );
    assert!(run(vec![bad_cols]).contains("expected 20x1"));
    let mut hn = Array2::zeros((n, 1));
    hn[[0, 0]] = f64::NAN;
    let nan = Hypothesis::new("h", vec![HypothesisParam::bounded("h/q", 0.0, 1.0)], hn);
    assert!(run(vec![nan]).contains("parameter `h/q` is NaN"));
    let inverted = hyp1("h", &p.a);
    let inverted = Hypothesis::new(
        "h",
        vec![HypothesisParam::bounded("h/q", 1.0, 0.0)],
        inverted.jacobian,
    );
    assert!(run(vec![inverted]).contains("range [1, 0]"));
    assert!(run(vec![hyp1("h", &p.a), hyp1("h", &p.b)]).contains("`h` appears twice"));
    let taken = Hypothesis::new(
        "h",
        vec![HypothesisParam::bounded("u", 0.0, 1.0)],
        Array2::ones((n, 1)),
    );
    assert!(run(vec![taken]).contains("`u` is already calibrated"));
    let none = Hypothesis::new("h", vec![], Array2::zeros((n, 0)));
    assert!(run(vec![none]).contains("has no parameter"));
    // Settings.
    let e = diagnose(&res, &[], &DiagnoseSettings::new().with_noise_sigma(-1.0)).unwrap_err();
    assert!(
        matches!(e, Error::InvalidSetting { ref name, .. } if name == "noise_sigma"),
        "{e}"
    );
    let e = diagnose(
        &res,
        &[],
        &DiagnoseSettings::new().with_min_independence(0.0),
    )
    .unwrap_err();
    assert!(msg(e).contains("min_independence"));
    let e = diagnose(&res, &[], &DiagnoseSettings::new().with_output_folds(1)).unwrap_err();
    assert!(msg(e).contains("output_folds"));
    // Noise that cannot be estimated: as many parameters as residuals, fitted exactly.
    let one = Residuals::new(rows(2, 1), vec![0.3, -0.1], Array2::eye(2), names()).unwrap();
    let e = diagnose(&one, &[], &DiagnoseSettings::new()).unwrap_err();
    let m = msg(e);
    assert!(
        m.contains("2 measured values for 2 calibrated parameters"),
        "{m}"
    );
    assert!(m.contains("DiagnoseSettings::noise_sigma"), "{m}");
    assert!(m.contains("kalibre diagnose --noise"), "{m}");
    // A single output in a single snapshot cannot be held out.
    let single = Residuals::new(rows(1, 1), vec![0.3], Array2::zeros((1, 0)), vec![]).unwrap();
    let e = diagnose(&single, &[], &DiagnoseSettings::new().with_noise_sigma(0.1)).unwrap_err();
    assert!(msg(e).contains("two snapshots or two outputs"));
}

#[test]
fn works_without_calibrated_parameters() {
    let p = Problem::new(101, 2, 30);
    let r: Vec<f64> = (0..p.n).map(|i| 0.4 * p.a[i] + p.noise[i]).collect();
    let res = Residuals::new(p.rows.clone(), r, Array2::zeros((p.n, 0)), vec![]).unwrap();
    let d = diagnose(&res, &p.hypotheses(), &DiagnoseSettings::new()).unwrap();
    let best = &d.hypotheses[0];
    assert_eq!(best.name, "a");
    assert!(best.significant && best.current_change.0.is_empty());
    assert!((best.fitted.get("a/q0").unwrap() + 0.4).abs() < 0.05);
    assert_eq!(d.significant().count(), 1);
}
