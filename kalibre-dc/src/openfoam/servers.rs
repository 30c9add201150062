//! Every server's air in an OpenFOAM run: the intake OpenFOAM samples, the flow the case
//! prescribes, and the exhaust that flow and the server's power give.

use super::{OpenFoamSettings, M3_S_PER_CFM};
use crate::hall::Hall;
use crate::sim::ServerAir;
use crate::snapshots::OperatingState;
use crate::{Error, Result};

/// The servers' air of one run of `hall` at `state`, from the per-server `alpha` (cfm/W)
/// and the intakes OpenFOAM sampled (a run's `extras` under [`super::SERVER_INTAKE_KEY`]),
/// hall order. The exhaust is the intake plus the power over the flow's heat capacity, as the
/// case heats the air behind each exhaust; an idle server blows out what it draws.
///
/// ```
/// use kalibre_dc::openfoam::{server_air_from_intakes, OpenFoamSettings, M3_S_PER_CFM};
/// use kalibre_dc::synth::{generate, Preset, SynthOptions};
///
/// let truth = generate(&SynthOptions::new(Preset::Demo, 1)).unwrap();
/// let state = &truth.snapshots[0].state;
/// let n = state.power_w.len();
/// let (alpha, intake_c) = (vec![0.12; n], vec![20.0; n]);
/// let settings = OpenFoamSettings::default();
/// let air = server_air_from_intakes(&truth.hall, state, &alpha, &intake_c, &settings).unwrap();
/// let s = &air[0];
/// assert!((s.flow_m3_s - 0.12 * s.power_w * M3_S_PER_CFM).abs() < 1e-12);
/// let rise = s.power_w / (settings.rho_kg_m3 * settings.cp_j_kgk * s.flow_m3_s);
/// assert!((s.exhaust_c - 20.0 - rise).abs() < 1e-9);
/// ```
pub fn server_air_from_intakes(
    hall: &Hall,
    state: &OperatingState,
    alpha: &[f64],
    intake_c: &[f64],
    settings: &OpenFoamSettings,
) -> Result<Vec<ServerAir>> {
    let n = hall.servers().count();
    if [state.power_w.len(), alpha.len(), intake_c.len()] != [n; 3] {
        return Err(Error::Mismatch(format!(
            "server air of snapshot `{}`: the hall has {n} servers, but there are {} powers, \
             {} alphas and {} intakes",
            state.label,
            state.power_w.len(),
            alpha.len(),
            intake_c.len()
        )));
    }
    let heat_capacity = settings.rho_kg_m3 * settings.cp_j_kgk;
    Ok(hall
        .servers()
        .map(|s| {
            let i = s.index;
            let power_w = state.power_w[i];
            let flow_m3_s = alpha[i] * power_w * M3_S_PER_CFM;
            let rise_k = if flow_m3_s > 0.0 {
                power_w / (heat_capacity * flow_m3_s)
            } else {
                0.0
            };
            ServerAir {
                snapshot: state.label.clone(),
                server: s.server.id.clone(),
                rack: s.rack.id.clone(),
                server_type: s.server.server_type.clone(),
                power_w,
                flow_m3_s,
                intake_c: intake_c[i],
                exhaust_c: intake_c[i] + rise_k,
            }
        })
        .collect())
}
