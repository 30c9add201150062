//! The simulator's library entry points refuse what no hall or run could be, naming it:
//! a hall built in code gets the hall file's checks, and a run's values their ranges.

#[path = "support/sim_halls.rs"]
mod sim_halls;

use kalibre_dc::sim::{RackRecirculation, SimConfig, SimMods, Simulator};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::Error;
use sim_halls::{demo_hall, uniform_state};

fn config() -> SimConfig {
    SimConfig::default().with_cell_m(0.4)
}

#[test]
fn a_hall_built_in_code_gets_the_files_checks() {
    let mut hall = demo_hall();
    hall.sensors[0].position_m = [1e6, 1e6, 1e6];
    match Simulator::new(&hall, config()) {
        Err(Error::Format { file, field, .. }) => {
            assert_eq!(file, format!("hall `{}`", hall.name));
            assert_eq!(field, "/sensors/0/position_m");
        }
        other => panic!("expected Error::Format, got {other:?}"),
    }
    let mut hall = demo_hall();
    hall.cracs[1].id = hall.cracs[0].id.clone();
    let e = Simulator::new(&hall, config()).unwrap_err().to_string();
    assert!(e.contains("/cracs/1/id"), "{e}");
}

#[test]
fn a_runs_values_out_of_range_are_named() {
    let hall = demo_hall();
    let sim = Simulator::new(&hall, config()).expect("simulator");
    let state = uniform_state(&hall, 18.0, 0.8, 300.0);
    let alpha = vec![0.15; hall.server_count()];
    let solve = |state: &OperatingState, alpha: &[f64], mods: &SimMods| {
        sim.solve_with_mods(state, alpha, mods)
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let plain = SimMods::new(hall.cracs.len());
    sim.solve_with_mods(&state, &alpha, &plain)
        .expect("the run itself is fine");

    let mut mods = plain.clone();
    mods.supply_offset_c[0] = f64::NAN;
    let e = solve(&state, &alpha, &mods);
    assert!(
        e.contains(&format!("CRAC `{}`: supply offset NaN", hall.cracs[0].id)),
        "{e}"
    );

    let mut mods = plain.clone();
    mods.rack_recirculation.push(RackRecirculation {
        rack: 0,
        fraction: 5.0,
        z_m: None,
    });
    let e = solve(&state, &alpha, &mods);
    assert!(e.contains("fraction 5 is outside [0, 1]"), "{e}");

    let mut cold = state.clone();
    cold.setpoint_c[0] = -300.0;
    let e = solve(&cold, &alpha, &plain);
    assert!(e.contains("setpoint -300 C is outside"), "{e}");

    let mut hot = state.clone();
    hot.power_w[3] = 1e300;
    let e = solve(&hot, &alpha, &plain);
    assert!(e.contains("power 1e300 W is outside"), "{e}");

    let mut big = alpha.clone();
    big[3] = 1e300;
    let e = solve(&state, &big, &plain);
    assert!(e.contains("alpha 1e300 cfm/W is outside"), "{e}");
}
