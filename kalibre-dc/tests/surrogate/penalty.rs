//! The temperature-rise penalty: where it binds, and what its report says.

use kalibre_core::Regularizer;
use kalibre_dc::hall::AlphaMode;
use kalibre_dc::surrogate::*;
use kalibre_dc::ParamLayout;

use crate::surrogate_fixture::{hall, state, SMALL};

#[test]
fn penalty_reports_where_it_binds() {
    let mode = AlphaMode::PerType;
    let h = hall(SMALL, mode);
    let layout = ParamLayout::with_mode(&h, mode, &[]).unwrap();
    let scen = vec![state(&h, "t0", 1)];
    let pen = TemperatureRisePenalty::new(&h, &layout, &scen, PenaltySettings::default()).unwrap();
    // K = 1 / (4.71947e-4 * 1.2 * 1005) = 1.757 K cfm/W.
    assert!((pen.rise_c(1.0) - 1.7570).abs() < 1e-3);
    // Rises 8.8 K (alpha 0.2) are inside [5, 20]: no penalty.
    let inside = vec![0.2; layout.space().dim()];
    let rep = pen.report(&inside);
    assert!(!rep.binds && rep.value == 0.0 && rep.violations.is_empty());
    // Type 1 at alpha 0.08 (rise 22 K) binds from above; type 2 at 0.5 (3.5 K) from below.
    let mut p = inside.clone();
    p[1] = 0.08;
    p[2] = 0.5;
    let rep = pen.report(&p);
    assert!(rep.binds);
    assert_eq!(rep.violations.len(), 2);
    assert_eq!(rep.violations[0].source, "alpha/type-1");
    assert_eq!(rep.violations[0].bound, RiseBound::Above);
    assert_eq!(rep.violations[1].bound, RiseBound::Below);
    assert!(rep.servers_above > 0 && rep.servers_below > 0);
    assert!(rep.weight_fraction_outside > 0.0 && rep.weight_fraction_outside < 1.0);
    // The value is the power-weighted mean violation: below the largest violation (K).
    let (v, _) = pen.value_and_gradient(&p);
    assert!((v - rep.value).abs() < 1e-12);
    assert!(v > 0.0 && v < pen.rise_c(0.08) - pen.settings().upper_c);
    assert!(PenaltySettings::default()
        .with_range_c(10.0, 5.0)
        .check()
        .is_err());
}

/// Servers that draw no power in any snapshot have no rise: an alpha that would give them
/// one outside the range is not reported as binding (it said "gives 1 server(s) a rise of
/// 175.7 K" of a server at 0 W, with the penalty at 0).
#[test]
fn servers_at_zero_power_are_not_reported_as_binding() {
    let mode = AlphaMode::PerType;
    let h = hall(SMALL, mode);
    let layout = ParamLayout::with_mode(&h, mode, &[]).unwrap();
    let mut scen = vec![state(&h, "t0", 1)];
    let type1: Vec<usize> = (h.servers().enumerate())
        .filter(|(_, s)| s.server.server_type == h.server_types[1].id)
        .map(|(j, _)| j)
        .collect();
    assert!(!type1.is_empty());
    for &j in &type1 {
        scen[0].power_w[j] = 0.0;
    }
    let pen = TemperatureRisePenalty::new(&h, &layout, &scen, PenaltySettings::default()).unwrap();
    let mut p = vec![0.2; layout.space().dim()];
    p[1] = 0.01;
    let rep = pen.report(&p);
    assert!(
        !rep.binds && rep.value == 0.0 && rep.violations.is_empty(),
        "{rep:?}"
    );
}
