//! The mass-balance surrogate terms: hand-written vector-Jacobian products against
//! central finite differences, per type and per server, across the recirculation kink.

use kalibre_dc::hall::Aisle;
use kalibre_dc::hall::{AlphaMode, Hall};
use kalibre_dc::snapshots::{load_snapshots, HallSnapshot};
use kalibre_dc::surrogate::{
    FlowBalance, FlowBalanceTerm, LocalRecirculationSettings, LocalRecirculationTerm,
    SurrogateTerm, LOCAL_RADIUS_M,
};
use kalibre_dc::ParamLayout;

fn dev_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/openfoam/of-dev-clean")
}

fn hall() -> Hall {
    Hall::load(&dev_dir().join("hall.json")).unwrap()
}

fn snapshots(hall: &Hall) -> Vec<HallSnapshot> {
    load_snapshots(hall, &dev_dir().join("snapshots.csv")).unwrap()
}

/// A term's features at `snap` with every alpha at `alpha`.
fn uniform_features(
    term: &dyn SurrogateTerm,
    hall: &Hall,
    layout: &ParamLayout,
    snap: &HallSnapshot,
    alpha: f64,
) -> Vec<f64> {
    let mut out = vec![0.0; hall.sensors.len()];
    term.features(&snap.state, &vec![alpha; layout.space().dim()], &mut out);
    out
}

fn check(term: &dyn SurrogateTerm, hall: &Hall, params: &[f64]) {
    let snaps = snapshots(hall);
    let n = hall.sensors.len();
    let cot: Vec<f64> = (0..n)
        .map(|k| ((k * 7 % 5) as f64 - 2.0) * 0.3 + 0.1)
        .collect();
    for snap in &snaps {
        let s = &snap.state;
        let mut grad = vec![0.0; params.len()];
        term.features_vjp(s, params, &cot, &mut grad);
        let f = |p: &[f64]| {
            let mut out = vec![0.0; n];
            term.features(s, p, &mut out);
            out.iter().zip(&cot).map(|(a, b)| a * b).sum::<f64>()
        };
        for i in 0..params.len() {
            let h = 1e-6 * params[i];
            let (mut p, mut m) = (params.to_vec(), params.to_vec());
            p[i] += h;
            m[i] -= h;
            let fd = (f(&p) - f(&m)) / (2.0 * h);
            let tol = 1e-5 * fd.abs().max(1e-3);
            assert!(
                (fd - grad[i]).abs() <= tol,
                "{} param {i} snapshot {}: fd {fd} vs {}",
                term.name(),
                s.label,
                grad[i]
            );
        }
    }
}

#[test]
fn mass_balance_terms_match_finite_differences() {
    let mut hall = hall();
    for mode in [AlphaMode::PerType, AlphaMode::PerServer] {
        hall.calibrate.alpha = mode;
        let layout = ParamLayout::new(&hall, &[]).unwrap();
        let dim = layout.space().dim();
        let terms: Vec<Box<dyn SurrogateTerm>> = vec![
            Box::new(FlowBalanceTerm::new(
                &hall,
                &layout,
                FlowBalance::Recirculation,
            )),
            Box::new(FlowBalanceTerm::new(&hall, &layout, FlowBalance::Bypass)),
            Box::new(LocalRecirculationTerm::new(&hall, &layout)),
            Box::new(
                LocalRecirculationTerm::with_settings(
                    &hall,
                    &layout,
                    LocalRecirculationSettings::within(LOCAL_RADIUS_M),
                )
                .unwrap(),
            ),
        ];
        // Below, near and above the point where the servers draw the supply (about 0.14 cfm/W).
        for base in [0.09, 0.13, 0.14, 0.16, 0.25] {
            let params: Vec<f64> = (0..dim)
                .map(|i| base * (1.0 + 0.03 * (i % 4) as f64))
                .collect();
            for t in &terms {
                check(t.as_ref(), &hall, &params);
            }
        }
    }
}

#[test]
fn local_recirculation_is_zero_when_supply_is_ample_and_grows_with_draw() {
    let hall = hall();
    let layout = ParamLayout::new(&hall, &[]).unwrap();
    let snaps = snapshots(&hall);
    let term = LocalRecirculationTerm::new(&hall, &layout);
    let feature = |alpha: f64| uniform_features(&term, &hall, &layout, &snaps[0], alpha);
    let (low, high) = (feature(0.05), feature(0.4));
    assert!(low.iter().all(|v| *v < 0.05), "{low:?}");
    assert!(high.iter().zip(&low).all(|(h, l)| h >= l));
    // By default only cold-aisle sensors take the term, and each of them sees
    // recirculation at 0.4 cfm/W, where the servers draw nearly three times the supply.
    for (s, v) in hall.sensors.iter().zip(&high) {
        match s.aisle {
            Aisle::Cold => assert!(*v > 1.0, "{}: {v}", s.id),
            Aisle::Hot => assert_eq!(*v, 0.0, "{}", s.id),
        }
    }
}

#[test]
fn local_recirculation_reach_sets_which_sensors_and_servers_count() {
    let hall = hall();
    let layout = ParamLayout::new(&hall, &[]).unwrap();
    let snaps = snapshots(&hall);
    let whole = LocalRecirculationTerm::new(&hall, &layout);
    let near = LocalRecirculationTerm::with_settings(
        &hall,
        &layout,
        LocalRecirculationSettings::within(LOCAL_RADIUS_M),
    )
    .unwrap();
    // The whole hall moves with every alpha, like the hall-wide terms, and takes their
    // ridge; the 3 m form is local.
    assert!(whole.hall_wide() && !near.hall_wide());
    let feature = |t: &LocalRecirculationTerm, alpha: f64| {
        uniform_features(t, &hall, &layout, &snaps[0], alpha)
    };
    // The 3 m form gives hot-aisle sensors the term too.
    let hot_near: Vec<f64> = hall
        .sensors
        .iter()
        .zip(feature(&near, 0.4))
        .filter(|(s, _)| s.aisle == Aisle::Hot)
        .map(|(_, v)| v)
        .collect();
    assert!(hot_near.iter().any(|v| *v > 1.0), "{hot_near:?}");
    // Against a direct computation on the demo hall (12 m long, so the 3 m reach leaves
    // servers out): every server intake and tile, weighed by 1 / max(d, 0.5 m), gives
    // each cold-aisle sensor rho_k, and the feature is (1 - 1 / rho_k) times the mean
    // exhaust rise (rho_k is far above 1 here, where the softplus is the plain hinge).
    let demo = kalibre_dc::synth::generate_hall(&kalibre_dc::synth::SynthOptions::new(
        kalibre_dc::synth::Preset::Demo,
        1,
    ))
    .unwrap();
    let layout = ParamLayout::new(&demo, &[]).unwrap();
    let state = kalibre_dc::snapshots::OperatingState {
        label: "uniform".into(),
        setpoint_c: vec![20.0; demo.cracs.len()],
        fan_speed: vec![0.8; demo.cracs.len()],
        power_w: (0..demo.server_count())
            .map(|i| 200.0 + 10.0 * (i % 7) as f64)
            .collect(),
    };
    let alpha = 1.5;
    let params = vec![alpha; layout.space().dim()];
    let mut got = vec![0.0; demo.sensors.len()];
    LocalRecirculationTerm::new(&demo, &layout).features(&state, &params, &mut got);
    let mut near_got = vec![0.0; demo.sensors.len()];
    LocalRecirculationTerm::with_settings(
        &demo,
        &layout,
        LocalRecirculationSettings::within(LOCAL_RADIUS_M),
    )
    .unwrap()
    .features(&state, &params, &mut near_got);
    let flow: Vec<f64> = state
        .power_w
        .iter()
        .map(|p| alpha * p * 4.71947e-4)
        .collect();
    let q_srv: f64 = flow.iter().sum();
    let q_sup: f64 = demo
        .cracs
        .iter()
        .zip(&state.fan_speed)
        .map(|(c, v)| v * c.rated_flow_m3_s)
        .sum();
    let rise = state.power_w.iter().sum::<f64>() / (1.2 * 1005.0 * q_srv);
    let open: Vec<f64> = demo
        .tiles
        .iter()
        .map(|t| t.size_m[0] * t.size_m[1] * t.open_fraction)
        .collect();
    let open_total: f64 = open.iter().sum();
    let mut differs = false;
    for (k, sensor) in demo.sensors.iter().enumerate() {
        if sensor.aisle != Aisle::Cold {
            assert_eq!(got[k], 0.0, "{}", sensor.id);
            continue;
        }
        let w = |p: [f64; 3]| 1.0 / kalibre_dc::hall::distance(p, sensor.position_m).max(0.5);
        let (mut draw, mut w_sum) = (0.0, 0.0);
        for (srv, q) in demo.servers().zip(&flow) {
            let wj = w(srv.intake_centre());
            draw += wj * q;
            w_sum += wj;
        }
        let (mut share, mut v_sum) = (0.0, 0.0);
        for (t, o) in demo.tiles.iter().zip(&open) {
            let centre = [
                t.position_m[0] + 0.5 * t.size_m[0],
                t.position_m[1] + 0.5 * t.size_m[1],
                0.0,
            ];
            let vt = w(centre);
            share += vt * o / open_total;
            v_sum += vt;
        }
        let rho =
            (draw / w_sum * flow.len() as f64) / (share / v_sum * demo.tiles.len() as f64 * q_sup);
        assert!(rho > 2.6, "{}: rho {rho}", sensor.id);
        let want = (1.0 - 1.0 / rho) * rise;
        assert!(
            (got[k] - want).abs() <= 1e-9 * want,
            "{}: {} vs {want}",
            sensor.id,
            got[k]
        );
        differs |= (near_got[k] - got[k]).abs() > 1e-3;
    }
    assert!(differs, "the 3 m reach changes some cold-aisle sensor");
    for bad in [0.0, -1.0, f64::NAN] {
        let e = LocalRecirculationTerm::with_settings(
            &hall,
            &layout,
            LocalRecirculationSettings {
                radius_m: bad,
                cold_aisle_only: true,
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("local_recirculation.radius_m"), "{e}");
    }
}

/// Recirculation that no training run had, at a prediction that has it: the fitted graph
/// must not multiply a training spread of 1e-5 K by a slope fitted to noise (Fig. 7's
/// log-uniform draws once predicted millions of degrees this way).
#[test]
fn a_term_that_never_moved_in_training_does_not_blow_up_the_prediction() {
    use kalibre_core::{Sample, Surrogate, TrainingSet};
    use kalibre_dc::surrogate::{ThermalGraph, ThermalGraphSettings};
    let mut hall = hall();
    hall.calibrate.alpha = AlphaMode::PerType;
    let snaps = snapshots(&hall);
    let state = snaps[0].state.clone();
    let layout = ParamLayout::new(&hall, &[]).unwrap();
    let dim = layout.space().dim();
    let n = hall.sensors.len();
    // Training alphas 0.10-0.12 cfm/W, below the supply-matching 0.14: no recirculation,
    // so its feature is a softplus tail of 1e-7 to 5e-5 K. Outputs: 22 C plus half the
    // bypass feature plus a 0.05 C wiggle (noise for the idle feature to fit).
    let bypass = FlowBalanceTerm::new(&hall, &layout, FlowBalance::Bypass);
    let truth = |params: &[f64]| {
        let mut f = vec![0.0; n];
        bypass.features(&state, params, &mut f);
        f.iter().map(|b| 22.0 + 0.5 * b).collect::<Vec<f64>>()
    };
    let samples: Vec<Sample> = (0..12)
        .map(|i| {
            let params: Vec<f64> = (0..dim)
                .map(|p| 0.1 + 0.002 * ((i * 3 + p * 5) % 11) as f64)
                .collect();
            let outputs = truth(&params)
                .iter()
                .enumerate()
                .map(|(k, y)| y + 0.05 * ((i * 7 + k * 3) as f64).sin())
                .collect();
            Sample {
                snapshot: 0,
                params,
                outputs,
                weight: 1.0,
            }
        })
        .collect();
    let recirculating = vec![0.3; dim];
    let mut feature = vec![0.0; n];
    FlowBalanceTerm::new(&hall, &layout, FlowBalance::Recirculation).features(
        &state,
        &recirculating,
        &mut feature,
    );
    assert!(feature[0] > 1.0, "recirculation feature {}", feature[0]);
    let expected = truth(&recirculating);
    let worst = |settings: ThermalGraphSettings| {
        let mut g = ThermalGraph::new(&hall, layout.clone(), settings).unwrap();
        for kind in [FlowBalance::Recirculation, FlowBalance::Bypass] {
            g = g.with_term(Box::new(FlowBalanceTerm::new(&hall, &layout, kind)));
        }
        let data = TrainingSet {
            scenarios: std::slice::from_ref(&state),
            samples: &samples,
        };
        g.fit(data, 1).unwrap();
        g.predict(&state, &recirculating)
            .iter()
            .zip(&expected)
            .map(|(y, e)| (y - e).abs())
            .fold(0.0, f64::max)
    };
    // Without the ridge in Adam's loss (and the hall-wide terms ridged like the rest): the
    // term's scale is floored at 0.1 K, so the idle slope is bounded (without the floor:
    // 9e4 C off); Adam's normalised steps still fit the noise with it.
    let plain = ThermalGraphSettings::default()
        .with_adam_ridge(false)
        .with_hall_wide_ridge(1e-3);
    let unridged = worst(plain);
    assert!(unridged < 200.0, "no ridge in Adam: {unridged} C off");
    // With the ridge kept in Adam's loss the idle slope stays near zero.
    let ridged = worst(plain.with_adam_ridge(true));
    assert!(ridged < 1.0, "ridge in Adam: {ridged} C off");
    // The default also ridges the hall-wide terms' weights harder, so part of this
    // (purely hall-wide) truth's slope goes to the local heating block, which extrapolates
    // to the recirculating point: measured 1.47 C off, still no blow-up.
    let default = worst(ThermalGraphSettings::default());
    assert!(default < 2.0, "default: {default} C off");
}
