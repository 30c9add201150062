//! What the calibrated model says beyond the sensors: every server's intake against the
//! recommended limit, and (built-in model) which racks warm each sensor.

use std::path::Path;

use kalibre_core::calibrate::Report;
use kalibre_core::{Model, RunStore};
use kalibre_dc::calibration::HallCalibrationSettings;
use kalibre_dc::hall::Hall;
use kalibre_dc::openfoam::{server_air_from_intakes, OpenFoamModel, SERVER_INTAKE_KEY};
use kalibre_dc::sim::{inlet_check, server_air, InletCheck, RackHeat, RECOMMENDED_MAX_INLET_C};
use kalibre_dc::snapshots::HallSnapshot;
use kalibre_dc::HallModel;

use super::super::openfoam_args::of_err;
use super::super::{CliError, CliResult};
use super::{calibrated_hall, CalibrateArgs};

/// An OpenFOAM calibration's server intakes at the best parameters, per snapshot, and
/// how much its sensors' readings fluctuate there, from the runs it journaled (every
/// OpenFOAM run samples each intake and each probe's spread): no solve more. The intakes
/// are `None` when a run at the best parameters lacks them (journaled by an older
/// kalibre).
pub(super) fn openfoam_findings(
    args: &CalibrateArgs,
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &HallCalibrationSettings,
    report: &Report,
    journal: &Path,
) -> CliResult<OpenFoamFindings> {
    let hall = calibrated_hall(hall, settings);
    let model = OpenFoamModel::new(
        &hall,
        args.openfoam
            .settings(&args.out.join("openfoam"), args.grid_m)?,
    )
    .map_err(|e| of_err(e.in_hall_file(&args.hall_path().display().to_string())))?;
    let store = RunStore::open_with_aliases(
        journal,
        model.fingerprint(),
        &model.legacy_fingerprints(),
        false,
    )?;
    let names: Vec<String> = report
        .best
        .params
        .0
        .iter()
        .map(|(n, _)| n.clone())
        .collect();
    let params = report.best.params.values();
    let alpha = model.layout().alpha_per_server(&params);
    let mut checks = Vec::with_capacity(snaps.len());
    let mut fluctuation = Fluctuation::default();
    let mut complete = true;
    for snap in snaps {
        let inputs = model.scenario_key(&snap.state);
        let outputs = store
            .get_keyed(&snap.state.label, &inputs, &names, &params)
            .and_then(|(_, run)| run.result().ok());
        if let Some(spread) = outputs.as_ref().and_then(|o| o.spread.as_ref()) {
            fluctuation.add(&snap.state.label, spread, &hall);
        }
        let Some(intake_c) = outputs
            .as_ref()
            .and_then(|o| o.extras.get(SERVER_INTAKE_KEY))
        else {
            complete = false;
            continue;
        };
        let air = server_air_from_intakes(&hall, &snap.state, &alpha, intake_c, model.settings())?;
        checks.push((
            snap.state.label.clone(),
            inlet_check(&air, RECOMMENDED_MAX_INLET_C, 3)?,
        ));
    }
    Ok(OpenFoamFindings {
        intakes: complete.then_some(checks),
        fluctuation: (fluctuation.count > 0).then_some(fluctuation),
    })
}

/// What an OpenFOAM calibration's journal says at the best parameters.
pub(super) struct OpenFoamFindings {
    /// Every server's intake per snapshot; `None` when a run lacks them.
    pub intakes: Option<Vec<(String, InletCheck)>>,
    /// How much the sensors' readings fluctuate, when the runs journaled it.
    pub fluctuation: Option<Fluctuation>,
}

/// How much OpenFOAM's sensor readings fluctuate over the averaging window (each probe's
/// standard deviation, journaled as the run's `spread`) at the best parameters: an
/// unsteady solve limits how closely any calibration can match, and `ok` runs say
/// nothing of it otherwise.
#[derive(Default)]
pub(super) struct Fluctuation {
    sum_c: f64,
    count: usize,
    largest_c: f64,
    sensor: String,
    snapshot: String,
}

impl Fluctuation {
    /// Adds one snapshot's run: each sensor's spread, in the hall's sensor order.
    fn add(&mut self, snapshot: &str, spread: &[f64], hall: &Hall) {
        for (s, &c) in hall.sensors.iter().zip(spread) {
            self.sum_c += c;
            // The first reading, or a larger one.
            if self.count == 0 || c > self.largest_c {
                (self.largest_c, self.sensor, self.snapshot) =
                    (c, s.id.clone(), snapshot.to_string());
            }
            self.count += 1;
        }
    }

    /// The summary's line.
    pub(super) fn describe(&self) -> String {
        format!(
            "mean {:.2} C, largest {:.2} C ({}, {}), at the best parameters",
            self.sum_c / self.count as f64,
            self.largest_c,
            self.sensor,
            self.snapshot
        )
    }

    /// A warning when the largest exceeds the fit's MAE.
    pub(super) fn warn_if_unsteady(&self, best_mae_c: f64) {
        if self.largest_c > best_mae_c {
            eprintln!(
                "kalibre: warning: at the best parameters OpenFOAM's reading at {} ({}) \
                 fluctuates by {:.2} C (its standard deviation over the averaging window), \
                 more than the fit's MAE ({:.3} C): the solve is not steady there, so no \
                 parameter value can match that sensor closer; more --of-iterations or \
                 another --grid-m may settle it",
                self.sensor, self.snapshot, self.largest_c, best_mae_c
            );
        }
    }
}

/// What the calibrated built-in model says beyond the sensors.
pub(super) struct BuiltinFindings {
    /// Every server's intake per snapshot against the recommended limit.
    pub intakes: Vec<(String, InletCheck)>,
    /// Which racks warm each sensor in the busiest snapshot's air flow ([`busiest`];
    /// rows with no cut).
    pub warming: Vec<RackHeat>,
}

/// The snapshot whose servers draw the most power (the first of equals): where the
/// racks' part in each sensor's warming shows best. An idle one shows none.
pub(crate) fn busiest(snaps: &[HallSnapshot]) -> Option<&HallSnapshot> {
    let power = |s: &HallSnapshot| s.state.power_w.iter().sum::<f64>();
    snaps
        .iter()
        .reduce(|best, s| if power(s) > power(best) { s } else { best })
}

/// The calibrated built-in model's [`BuiltinFindings`] (one adjoint solve per sensor for
/// the warming).
pub(super) fn builtin_findings(
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &HallCalibrationSettings,
    report: &Report,
) -> CliResult<BuiltinFindings> {
    let hall = calibrated_hall(hall, settings);
    let model = HallModel::new(&hall, settings.sim.clone())?;
    let params = report.best.params.values();
    // The busiest snapshot's run comes with the adjoint solves, so it is solved once.
    let busiest = busiest(snaps).map(|s| s.state.label.as_str());
    let mut warming = Vec::new();
    let mut intakes = Vec::with_capacity(snaps.len());
    for snap in snaps {
        let label = &snap.state.label;
        let solution = if Some(label.as_str()) == busiest {
            let (solution, rows) = model
                .rack_heat(&snap.state, &params)
                .map_err(|e| CliError::Run(format!("snapshot `{label}`: {e}")))?;
            warming = rows;
            solution
        } else {
            model.solve(&snap.state, &params)?
        };
        let air = server_air(&hall, &snap.state, &solution)?;
        intakes.push((
            label.clone(),
            inlet_check(&air, RECOMMENDED_MAX_INLET_C, 3)?,
        ));
    }
    Ok(BuiltinFindings { intakes, warming })
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibre_dc::snapshots::OperatingState;

    /// An idle first snapshot warms no sensor: the racks' part shows in the busiest one.
    #[test]
    fn the_busiest_snapshot_is_the_one_drawing_most_power_first_of_equals() {
        let snap = |label: &str, power_w: Vec<f64>| HallSnapshot {
            state: OperatingState {
                label: label.into(),
                setpoint_c: vec![18.0],
                fan_speed: vec![0.8],
                power_w,
            },
            sensor_c: vec![Some(20.0)],
        };
        let snaps = [
            snap("idle", vec![1e-9, 0.0]),
            snap("busy", vec![500.0, 200.0]),
            snap("as-busy", vec![200.0, 500.0]),
        ];
        assert_eq!(
            busiest(&snaps).map(|s| s.state.label.as_str()),
            Some("busy")
        );
        assert!(busiest(&[]).is_none());
    }
}
