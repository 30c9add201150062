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

#[test]
fn sharper_edges_keep_the_same_servers_and_weigh_them_by_the_scaled_distance() {
    let h = hall(HALL_A, AlphaMode::PerServer);
    let base = AdjacencySettings::default();
    let adj = Adjacency::from_hall(&h, &base).unwrap();
    // Power 1 and height factor 1 are the default rule, bit for bit.
    let same = base
        .with_server_distance_power(1.0)
        .with_server_vertical_scale(1.0);
    assert_eq!(Adjacency::from_hall(&h, &same).unwrap(), adj);

    let (power, vertical) = (4.0, 0.5);
    let sharp = base.with_server_distance_power(power);
    let sharp_adj = Adjacency::from_hall(&h, &sharp).unwrap();
    // The cut compares reciprocal distances, so a power keeps the same servers.
    assert_eq!(sharp_adj.ss.col, adj.ss.col);
    assert_eq!(sharp_adj.ss.row_ptr, adj.ss.row_ptr);
    let exhausts: Vec<[f64; 3]> = h.servers().map(|s| s.exhaust_centre()).collect();
    let flat = Adjacency::from_hall(&h, &sharp.with_server_vertical_scale(vertical)).unwrap();
    for (k, sensor) in h.sensors.iter().enumerate() {
        let p = sensor.position_m;
        for (adj, scale) in [(&sharp_adj, 1.0), (&flat, vertical)] {
            let range = adj.ss.range(k);
            if range.is_empty() {
                continue;
            }
            // Each weight is (1 / d)^4 over the row's sum, d with the height difference
            // scaled.
            let recip = |j: usize| {
                let e = exhausts[j];
                let d2 =
                    (e[0] - p[0]).powi(2) + (e[1] - p[1]).powi(2) + (scale * (e[2] - p[2])).powi(2);
                1.0 / d2.sqrt().max(base.min_distance_m)
            };
            let cols = &adj.ss.col[range.clone()];
            let sum: f64 = cols.iter().map(|&j| recip(j as usize).powf(power)).sum();
            for (&j, &w) in cols.iter().zip(&adj.ss.val[range]) {
                let expected = recip(j as usize).powf(power) / sum;
                assert!((w - expected).abs() < 1e-12, "sensor {k}, server {j}");
            }
        }
    }
    // The nearest server of a row gets more of its weight at a higher power.
    let k = (0..h.sensors.len())
        .find(|&k| !adj.ss.range(k).is_empty())
        .unwrap();
    let top = |a: &Adjacency| a.ss.val[a.ss.range(k)].iter().copied().fold(0.0, f64::max);
    assert!(top(&sharp_adj) > top(&adj));
    // Bad values are refused by name.
    for bad in [
        base.with_server_distance_power(0.0),
        base.with_server_distance_power(f64::NAN),
        base.with_server_vertical_scale(-1.0),
    ] {
        let e = Adjacency::from_hall(&h, &bad).unwrap_err().to_string();
        assert!(e.contains("server_"), "{e}");
    }
}
