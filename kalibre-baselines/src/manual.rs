//! The domain expert's calibration procedure, as the paper's baseline "manual expert".
//!
//! An expert looks at where the model disagrees with the sensors and turns the knobs of
//! the servers nearby: where the model reads hotter than a sensor, the servers near it
//! must move more air (raise alpha: a lower temperature rise), and where it reads cooler,
//! less. Each iteration:
//!
//! 1. residuals `r_k = model - measured` per sensor, averaged over the snapshots, at the
//!    best point so far;
//! 2. each server's suggestion `d_j` is the mean residual of the sensors it is near
//!    (the `k` nearest servers of each sensor, or those within a radius, measured from
//!    the sensor to the server's exhaust face for a hot-aisle sensor and to its intake
//!    face for a cold-aisle one);
//! 3. each alpha parameter (per server, or per type: the mean of its servers'
//!    suggestions) moves in the unit box (a log scale for alpha) by
//!    `step * d_i / max_i |d_i|`, clipped into the box;
//! 4. the model runs there (one run per snapshot); a lower MAE is kept, otherwise the
//!    step halves and the next proposal starts again from the best point.
//!
//! By default only hot-aisle sensors guide the expert: a server's flow sets its exhaust
//! temperature directly, while a cold-aisle reading responds to it with either sign
//! (more flow draws more recirculated air). Effect parameters are left at their initial
//! values: the expert tunes server flows. The procedure is deterministic.

use std::time::Instant;

use kalibre_core::{Model, Observations, RunStore};
use kalibre_dc::hall::{distance, Aisle, Hall};
use kalibre_dc::snapshots::OperatingState;
use kalibre_dc::ParamLayout;

use crate::error::require;
use crate::runner::{BaselineReport, HistoryPoint, ModelMae};
use crate::Result;

/// Which servers count as near a sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Neighbourhood {
    /// The `k` nearest servers.
    Nearest(usize),
    /// Every server within this distance (m).
    RadiusM(f64),
}

/// Settings of the [`ManualHeuristic`].
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `neighbourhood` | 4 nearest | servers a sensor's residual is attributed to | k >= 1, radius > 0 |
/// | `step` | 0.15 | largest move of one parameter in the first iteration, unit box | (0, 1] |
/// | `shrink` | 0.5 | step factor after an iteration that did not lower the MAE | (0, 1) |
/// | `min_step` | 1e-3 | stop when the step falls below this | (0, step] |
/// | `max_iterations` | 30 | iterations (each one model run per snapshot) | >= 1 |
/// | `use_cold_aisle` | false | let cold-aisle sensors guide the flows too | bool |
/// | `target_mae_c` | none | stop once the best MAE is at most this | >= 0 |
#[derive(Debug, Clone, PartialEq)]
pub struct ManualSettings {
    /// Servers near a sensor.
    pub neighbourhood: Neighbourhood,
    /// Initial step (unit box).
    pub step: f64,
    /// Step factor after a failed iteration.
    pub shrink: f64,
    /// Smallest step.
    pub min_step: f64,
    /// Iterations.
    pub max_iterations: usize,
    /// Use cold-aisle sensors too.
    pub use_cold_aisle: bool,
    /// Stop at this MAE.
    pub target_mae_c: Option<f64>,
}

impl Default for ManualSettings {
    fn default() -> Self {
        ManualSettings {
            neighbourhood: Neighbourhood::Nearest(4),
            step: 0.15,
            shrink: 0.5,
            min_step: 1e-3,
            max_iterations: 30,
            use_cold_aisle: false,
            target_mae_c: None,
        }
    }
}

impl ManualSettings {
    /// Number of iterations.
    pub fn with_max_iterations(mut self, n: usize) -> Self {
        self.max_iterations = n;
        self
    }
    /// Servers near a sensor.
    pub fn with_neighbourhood(mut self, n: Neighbourhood) -> Self {
        self.neighbourhood = n;
        self
    }
    /// Initial step.
    pub fn with_step(mut self, step: f64) -> Self {
        self.step = step;
        self
    }
    /// Use cold-aisle sensors too.
    pub fn with_cold_aisle(mut self, on: bool) -> Self {
        self.use_cold_aisle = on;
        self
    }
    /// Stop at this MAE.
    pub fn with_target_mae_c(mut self, target: f64) -> Self {
        self.target_mae_c = Some(target);
        self
    }

    /// Checks every setting, naming the first one out of range.
    pub fn check(&self) -> Result<()> {
        match self.neighbourhood {
            Neighbourhood::Nearest(k) => require(k >= 1, "neighbourhood", || {
                "needs at least 1 nearest server".into()
            })?,
            Neighbourhood::RadiusM(r) => {
                require(r.is_finite() && r > 0.0, "neighbourhood", || {
                    format!("radius must be finite and > 0 m, got {r}")
                })?
            }
        }
        require(self.step > 0.0 && self.step <= 1.0, "step", || {
            format!("must be in (0, 1], got {}", self.step)
        })?;
        require(self.shrink > 0.0 && self.shrink < 1.0, "shrink", || {
            format!("must be in (0, 1), got {}", self.shrink)
        })?;
        require(
            self.min_step > 0.0 && self.min_step <= self.step,
            "min_step",
            || format!("must be in (0, step], got {}", self.min_step),
        )?;
        require(self.max_iterations >= 1, "max_iterations", || {
            "must be at least 1".into()
        })?;
        if let Some(t) = self.target_mae_c {
            require(t.is_finite() && t >= 0.0, "target_mae_c", || {
                format!("must be finite and >= 0, got {t}")
            })?;
        }
        Ok(())
    }
}

/// The expert's procedure for one hall and parameter layout.
#[derive(Debug, Clone)]
pub struct ManualHeuristic {
    settings: ManualSettings,
    layout: ParamLayout,
    /// Per sensor: the servers near it (empty for a sensor that does not guide).
    near: Vec<Vec<usize>>,
    /// Per server: the index of its type.
    server_type: Vec<usize>,
    n_types: usize,
}

impl ManualHeuristic {
    /// Precomputes which servers are near each guiding sensor.
    pub fn new(hall: &Hall, layout: ParamLayout, settings: ManualSettings) -> Result<Self> {
        settings.check()?;
        if layout.alpha_index().len() != hall.server_count() {
            return Err(crate::Error::Mismatch(format!(
                "parameter layout has {} servers, hall `{}` has {}",
                layout.alpha_index().len(),
                hall.name,
                hall.server_count()
            )));
        }
        let servers: Vec<_> = hall.servers().collect();
        let near: Vec<Vec<usize>> = hall
            .sensors
            .iter()
            .map(|sensor| {
                if sensor.aisle == Aisle::Cold && !settings.use_cold_aisle {
                    return Vec::new();
                }
                let mut d: Vec<(f64, usize)> = servers
                    .iter()
                    .map(|s| {
                        let face = match sensor.aisle {
                            Aisle::Hot => s.exhaust_centre(),
                            Aisle::Cold => s.intake_centre(),
                        };
                        (distance(sensor.position_m, face), s.index)
                    })
                    .collect();
                d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                match settings.neighbourhood {
                    Neighbourhood::Nearest(k) => d.iter().take(k).map(|x| x.1).collect(),
                    Neighbourhood::RadiusM(r) => {
                        d.iter().take_while(|x| x.0 <= r).map(|x| x.1).collect()
                    }
                }
            })
            .collect();
        let server_type = hall
            .server_type_indices()
            .into_iter()
            .zip(hall.servers())
            .map(|(t, s)| {
                t.ok_or_else(|| {
                    crate::Error::Mismatch(format!(
                        "server `{}` has unknown type `{}`",
                        s.server.id, s.server.server_type
                    ))
                })
            })
            .collect::<Result<Vec<_>>>()?;
        if near.iter().all(Vec::is_empty) {
            // The procedure would stop after its first run without a word.
            return Err(crate::Error::InvalidSetting {
                name: "neighbourhood".into(),
                reason: format!(
                    "no guiding sensor of hall `{}` has a server in it ({:?}{})",
                    hall.name,
                    settings.neighbourhood,
                    match settings.use_cold_aisle {
                        true => "",
                        false => ", hot-aisle sensors only",
                    }
                ),
            });
        }
        Ok(ManualHeuristic {
            settings,
            layout,
            near,
            server_type,
            n_types: hall.server_types.len(),
        })
    }

    /// The servers near each sensor (hall order; empty for sensors that do not guide).
    pub fn neighbours(&self) -> &[Vec<usize>] {
        &self.near
    }

    /// The expert's move direction in the unit box from the model's outputs per snapshot:
    /// per parameter, the mean suggestion (C) of its servers; zero where no guiding
    /// sensor is near. The observations and each snapshot's outputs are the hall's
    /// sensors, in hall order.
    pub fn suggestion(
        &self,
        observations: &Observations<OperatingState>,
        outputs: &[Vec<f64>],
    ) -> Result<Vec<f64>> {
        let n_sensors = self.near.len();
        let snaps = observations.snapshots().len();
        if observations.outputs().len() != n_sensors || outputs.len() != snaps {
            return Err(crate::Error::Mismatch(format!(
                "the observations have {} outputs in {snaps} snapshots, the model's outputs \
                 {} snapshots; the expert reads the hall's {n_sensors} sensors per snapshot",
                observations.outputs().len(),
                outputs.len()
            )));
        }
        if let Some((i, o)) = outputs
            .iter()
            .enumerate()
            .find(|(_, o)| o.len() != n_sensors)
        {
            return Err(crate::Error::Mismatch(format!(
                "snapshot {i}: {} model outputs for the hall's {n_sensors} sensors",
                o.len()
            )));
        }
        // Mean residual per sensor over the snapshots where it was measured.
        let mut r = vec![0.0; n_sensors];
        let mut cnt = vec![0usize; n_sensors];
        for (snap, out) in observations.snapshots().iter().zip(outputs) {
            for (k, (m, p)) in snap.measured.iter().zip(out).enumerate() {
                if let Some(m) = m {
                    r[k] += p - m;
                    cnt[k] += 1;
                }
            }
        }
        let n_servers = self.layout.alpha_index().len();
        let (mut d, mut dn) = (vec![0.0; n_servers], vec![0usize; n_servers]);
        for k in 0..n_sensors {
            if cnt[k] == 0 {
                continue;
            }
            for &j in &self.near[k] {
                d[j] += r[k] / cnt[k] as f64;
                dn[j] += 1;
            }
        }
        // A server no guiding sensor is near takes the mean suggestion of the servers of
        // its type that have one: the expert assumes servers of a kind behave alike.
        let mut per_server: Vec<Option<f64>> = d
            .iter()
            .zip(&dn)
            .map(|(v, &n)| (n > 0).then(|| v / n as f64))
            .collect();
        let (mut t_sum, mut t_n) = (vec![0.0; self.n_types], vec![0usize; self.n_types]);
        for (v, &t) in per_server.iter().zip(&self.server_type) {
            if let Some(v) = v {
                t_sum[t] += v;
                t_n[t] += 1;
            }
        }
        for (v, &t) in per_server.iter_mut().zip(&self.server_type) {
            if v.is_none() && t_n[t] > 0 {
                *v = Some(t_sum[t] / t_n[t] as f64);
            }
        }
        let dim = self.layout.space().dim();
        let (mut s, mut sn) = (vec![0.0; dim], vec![0usize; dim]);
        for (idx, v) in self.layout.alpha_index().iter().zip(&per_server) {
            if let (Some(i), Some(v)) = (idx, v) {
                s[*i] += v;
                sn[*i] += 1;
            }
        }
        Ok(s.iter()
            .zip(&sn)
            .map(|(v, &n)| if n > 0 { v / n as f64 } else { 0.0 })
            .collect())
    }

    /// Runs the procedure from the layout's initial values, journaling runs in `store`
    /// when given.
    pub fn run<M: Model<Scenario = OperatingState>>(
        &self,
        model: &M,
        observations: &Observations<OperatingState>,
        store: Option<&RunStore>,
    ) -> Result<BaselineReport> {
        let t0 = Instant::now();
        let space = self.layout.space();
        let mae = ModelMae::new(model, observations, space, store)?;
        let per_point = mae.runs_per_point();
        let st = &self.settings;
        let mut best_u = space.to_unit(&space.initial())?;
        let mut best_x = space.initial();
        let first = mae.run(&best_x)?;
        let initial_mae = first.mae_c;
        let mut best = first;
        let mut history = vec![HistoryPoint {
            iteration: 0,
            model_runs: per_point,
            mae_c: best.mae_c,
            best_mae_c: best.mae_c,
        }];
        let mut step = st.step;
        for it in 1..=st.max_iterations {
            if st.target_mae_c.is_some_and(|t| best.mae_c <= t) || step < st.min_step {
                break;
            }
            let Some(outputs) = &best.outputs else {
                return Err(crate::Error::Mismatch(
                    "the model failed at the initial parameters; the expert has no residuals to read"
                        .into(),
                ));
            };
            let dir = self.suggestion(observations, outputs)?;
            let scale = dir.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if scale == 0.0 {
                break; // No guiding sensor disagrees: nothing left to turn.
            }
            let u: Vec<f64> = best_u
                .iter()
                .zip(&dir)
                .map(|(b, d)| (b + step * d / scale).clamp(0.0, 1.0))
                .collect();
            let x = space.from_unit(&u)?;
            let res = mae.run(&x)?;
            let improved = res.mae_c < best.mae_c;
            history.push(HistoryPoint {
                iteration: it,
                model_runs: (it + 1) * per_point,
                mae_c: res.mae_c,
                best_mae_c: res.mae_c.min(best.mae_c),
            });
            if improved {
                best = res;
                best_u = u;
                best_x = x;
            } else {
                step *= st.shrink;
            }
        }
        Ok(BaselineReport {
            method: "manual_heuristic".into(),
            param_names: space.names(),
            best_params: best_x,
            best_mae_c: best.mae_c,
            initial_mae_c: initial_mae,
            model_runs: history.last().map_or(0, |h| h.model_runs),
            history,
            wall_s: t0.elapsed().as_secs_f64(),
        })
    }
}
