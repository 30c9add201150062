//! The adjacency of the thermal graph at Hall A's size: sparse, cut at the thresholds,
//! rows normalised.

use kalibre_dc::hall::AlphaMode;
use kalibre_dc::surrogate::*;

use crate::surrogate_fixture::{hall, HALL_A};

#[test]
fn adjacency_is_sparse_cut_and_normalised_at_hall_a_size() {
    let h = hall(HALL_A, AlphaMode::PerServer);
    assert_eq!(h.server_count(), 2240);
    let settings = AdjacencySettings::default();
    let adj = Adjacency::from_hall(&h, &settings).unwrap();
    let m = h.server_count();
    let mut hot_rows = 0;
    for (k, sensor) in h.sensors.iter().enumerate() {
        // Wcs: nearest CRAC has weight one, every kept entry is at or above the cut.
        let cs = adj.cs.range(k);
        let max = adj.cs.val[cs.clone()].iter().copied().fold(0.0, f64::max);
        assert!((max - 1.0).abs() < 1e-12);
        assert!(adj.cs.val[cs].iter().all(|&w| w >= settings.crac_threshold));
        let ss = adj.ss.range(k);
        if sensor.aisle == kalibre_dc::hall::Aisle::Cold {
            assert!(ss.is_empty(), "cold sensor {} has server edges", sensor.id);
            continue;
        }
        hot_rows += 1;
        let row = &adj.ss.val[ss.clone()];
        assert!(
            (row.iter().sum::<f64>() - 1.0).abs() < 1e-12,
            "row {k} not normalised"
        );
        // Relative weights: the kept ones reach the cut, the cut ones are zero.
        let recip: Vec<f64> = h
            .servers()
            .map(|s| {
                1.0 / kalibre_dc::hall::distance(s.exhaust_centre(), sensor.position_m)
                    .max(settings.min_distance_m)
            })
            .collect();
        let rmax = recip.iter().copied().fold(0.0, f64::max);
        for (j, r) in recip.iter().enumerate() {
            let kept = adj.ss.get(k, j) != 0.0;
            assert_eq!(
                kept,
                r / rmax >= settings.server_threshold,
                "sensor {k}, server {j}"
            );
        }
        assert!(
            row.len() < m / 4,
            "row {k} keeps {} of {m} servers",
            row.len()
        );
    }
    assert_eq!(hot_rows, 32);
    // A higher threshold keeps fewer edges.
    let tight = Adjacency::from_hall(&h, &settings.with_server_threshold(0.9)).unwrap();
    assert!(tight.ss.nnz() < adj.ss.nnz());
}
