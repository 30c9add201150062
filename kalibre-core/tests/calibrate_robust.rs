//! The calibration under a Student-t likelihood (`Settings::robust_nu`): an output the
//! model cannot match (an outlier) bends the least-squares calibration but not the
//! robust one, whose polish reweighs it.

mod common;

use common::*;
use kalibre_core::{Calibrator, Error, Observations, Settings};

/// Five snapshots of the analytic model at the truth, with a small deterministic noise,
/// and output `s1` of the first snapshot off by `outlier`.
fn observations_with_outlier(outlier: f64) -> Observations<Scen> {
    observations_with(&[1.0, 1.5, 2.0, 2.5, 3.0], |id, k, y| {
        let noise = 0.03 * ((7 * id + 3 * k) as f64).sin();
        let off = if id == 0 && k == 1 { outlier } else { 0.0 };
        Some(y + noise + off)
    })
}

/// Calibrates the analytic model against the observations with an outlier; returns the
/// distance of the best parameters from the truth.
fn calibration_error(robust_nu: Option<f64>) -> f64 {
    let (model, obs, space) = (Poly::new(), observations_with_outlier(3.0), space());
    let settings = Settings {
        seed: 3,
        max_iterations: 4,
        polish_iterations: 10,
        robust_nu,
        ..Settings::default()
    };
    let report = Calibrator::new(&model, QuadSurface::default(), &obs, &space)
        .with_settings(settings)
        .run()
        .unwrap();
    let p = report.best.params.values();
    ((p[0] - TRUTH[0]).powi(2) + (p[1] - TRUTH[1]).powi(2)).sqrt()
}

#[test]
fn an_outlier_bends_least_squares_but_not_the_student_t_calibration() {
    let least_squares = calibration_error(None);
    let student_t = calibration_error(Some(4.0));
    assert!(
        student_t < 0.02,
        "student-t lands {student_t} from the truth"
    );
    assert!(
        least_squares > 5.0 * student_t && least_squares > 0.05,
        "least squares {least_squares} against student-t {student_t}"
    );
}

#[test]
fn a_bad_nu_is_refused_by_name() {
    for nu in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let s = Settings {
            robust_nu: Some(nu),
            ..Settings::default()
        };
        match s.check() {
            Err(Error::InvalidSetting { name, .. }) => assert_eq!(name, "robust_nu"),
            other => panic!("nu {nu}: {other:?}"),
        }
    }
}
