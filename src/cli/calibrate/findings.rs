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

/// An OpenFOAM calibration's server intakes at the best parameters, per snapshot, from
/// the runs it journaled (every OpenFOAM run samples each intake): no solve more. `None`
/// when a run at the best parameters lacks them (journaled by an older kalibre).
pub(super) fn openfoam_intakes(
    args: &CalibrateArgs,
    hall: &Hall,
    snaps: &[HallSnapshot],
    settings: &HallCalibrationSettings,
    report: &Report,
    journal: &Path,
) -> CliResult<Option<Vec<(String, InletCheck)>>> {
    let hall = calibrated_hall(hall, settings);
    let model = OpenFoamModel::new(
        &hall,
        args.openfoam
            .settings(&args.out.join("openfoam"), args.grid_m)?,
    )
    .map_err(|e| of_err(e.in_hall_file(&args.hall.display().to_string())))?;
    let store = RunStore::open(journal, model.fingerprint())?;
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
    for snap in snaps {
        let inputs = model.scenario_key(&snap.state);
        let outputs = store
            .get_keyed(&snap.state.label, &inputs, &names, &params)
            .and_then(|(_, run)| run.result().ok());
        let Some(intake_c) = outputs
            .as_ref()
            .and_then(|o| o.extras.get(SERVER_INTAKE_KEY))
        else {
            return Ok(None);
        };
        let air = server_air_from_intakes(&hall, &snap.state, &alpha, intake_c, model.settings())?;
        checks.push((
            snap.state.label.clone(),
            inlet_check(&air, RECOMMENDED_MAX_INLET_C, 3)?,
        ));
    }
    Ok(Some(checks))
}

/// What the calibrated built-in model says beyond the sensors.
pub(super) struct BuiltinFindings {
    /// Every server's intake per snapshot against the recommended limit.
    pub intakes: Vec<(String, InletCheck)>,
    /// Which racks warm each sensor in the first snapshot's air flow (rows with no cut).
    pub warming: Vec<RackHeat>,
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
    // The first snapshot's run comes with the adjoint solves, so it is solved once.
    let mut warming = Vec::new();
    let mut intakes = Vec::with_capacity(snaps.len());
    for (k, snap) in snaps.iter().enumerate() {
        let label = &snap.state.label;
        let solution = if k == 0 {
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
