//! Bad training data, parameters and inputs: clear errors naming the culprit.

use kalibre_core::{Sample, Surrogate, TrainingSet};
use kalibre_dc::hall::AlphaMode;
use kalibre_dc::surrogate::*;
use kalibre_dc::ParamLayout;

use super::graph;
use crate::surrogate_fixture::{hall, state, SMALL};

#[test]
fn bad_training_data_is_a_clear_error() {
    let h = hall(SMALL, AlphaMode::PerType);
    let mut g = graph(&h, AlphaMode::PerType, ThermalGraphSettings::default());
    let scen = vec![state(&h, "t0", 1)];
    let p = g.layout().space().initial();
    let bad = vec![Sample {
        snapshot: 0,
        params: p.clone(),
        outputs: vec![20.0; 3],
        weight: 1.0,
    }];
    let err = g
        .fit(
            TrainingSet {
                scenarios: &scen,
                samples: &bad,
            },
            0,
        )
        .unwrap_err();
    assert!(err.to_string().contains("training sample 0"), "{err}");
    let bad = vec![Sample {
        snapshot: 4,
        params: p,
        outputs: vec![],
        weight: 1.0,
    }];
    assert!(g
        .fit(
            TrainingSet {
                scenarios: &scen,
                samples: &bad
            },
            0
        )
        .is_err());
    assert!(ThermalGraphSettings::default()
        .with_decay(0.0, 10)
        .check()
        .is_err());

    // Bad inputs to a prediction: the error names them, and `predict` gives NaN.
    let mut p = g.layout().space().initial();
    let last_alpha = g.layout().alpha_params().end - 1;
    assert_eq!(g.layout().alpha_params(), 0..p.len());
    p[last_alpha] = -0.1;
    let err = g.hidden(&scen[0], &p).unwrap_err().to_string();
    assert!(err.contains("alpha must be positive, got -0.1"), "{err}");
    assert!(g.predict(&scen[0], &p).iter().all(|t| t.is_nan()));
    p[last_alpha] = f64::NAN;
    let err = g.hidden(&scen[0], &p).unwrap_err().to_string();
    assert!(
        err.contains(&format!("parameter {last_alpha} is not finite")),
        "{err}"
    );
    let mut hot = scen[0].clone();
    hot.power_w[3] = f64::INFINITY;
    let err = g
        .hidden(&hot, &g.layout().space().initial())
        .unwrap_err()
        .to_string();
    assert!(err.contains("non-finite input value"), "{err}");
    // A fixed alpha is checked when the layout is built (predictions check only the
    // calibrated ones).
    let mut unchecked = h.clone();
    unchecked.server_types[0].alpha_cfm_per_w.initial = 0.0;
    let err = ParamLayout::with_mode(&unchecked, AlphaMode::Fixed, &[])
        .unwrap_err()
        .to_string();
    let id = &unchecked.server_types[0].id;
    assert!(
        err.contains(&format!(
            "server type `{id}`: alpha_cfm_per_w.initial must be positive"
        )),
        "{err}"
    );
}
