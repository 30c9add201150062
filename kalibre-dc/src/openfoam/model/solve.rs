//! One solve of [`OpenFoamModel`] in its run directory: link the meshed case, write
//! the parameters, run the solver (in parallel when `np > 1`), then read the probes,
//! check the energy balance and read every server's intake.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use kalibre_core::external::log_tail;
use kalibre_core::{check_outputs, ModelError, Outputs};

use super::super::params::RunInputs;
use super::super::results::{file_tail, last_field_value, log_verdict, probe_window};
use super::super::step::{run_solve_step, StepFailure};
use super::{OpenFoamModel, RunTimings, SERVER_INTAKE_KEY};

impl OpenFoamModel {
    pub(super) fn run_in(
        &self,
        dir: &Path,
        inputs: &RunInputs,
        t0: Instant,
    ) -> Result<(Outputs, RunTimings), StepFailure> {
        let io = |what: &str, e: std::io::Error| ModelError::failed(format!("{what}: {e}"));
        let case = self.case.path();
        for sub in ["constant", "system"] {
            std::os::unix::fs::symlink(case.join(sub), dir.join(sub))
                .map_err(|e| io("linking the meshed case", e))?;
        }
        let params = inputs.render();
        for zero in ["0.orig", "0"] {
            let d = dir.join(zero).join("include");
            std::fs::create_dir_all(&d).map_err(|e| io("writing the run", e))?;
            std::fs::write(d.join("params"), &params).map_err(|e| io("writing params", e))?;
            for entry in std::fs::read_dir(case.join("0.orig")).map_err(|e| io("0.orig", e))? {
                let entry = entry.map_err(|e| io("0.orig", e))?;
                if entry.path().is_file() {
                    std::fs::copy(entry.path(), dir.join(zero).join(entry.file_name()))
                        .map_err(|e| io("copying 0.orig", e))?;
                }
            }
        }
        let prepare_s = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let deadline = t1 + self.settings.timeout;
        let remaining = || {
            deadline
                .saturating_duration_since(Instant::now())
                .max(Duration::from_millis(1))
        };
        let case_args = vec!["-case".to_string(), dir.display().to_string()];
        let solver = "buoyantBoussinesqSimpleFoam";
        let np = self.settings.np;
        if np > 1 {
            let mut args = vec!["-force".to_string()];
            args.extend(case_args.clone());
            self.step(dir, "decomposePar", "decomposePar", &args, remaining())?;
        }
        let (program, args) = if np > 1 {
            let mut a: Vec<String> = ["--allow-run-as-root", "--oversubscribe", "-np"]
                .iter()
                .map(|s| s.to_string())
                .collect();
            a.push(np.to_string());
            a.push(solver.into());
            a.push("-parallel".into());
            a.extend(case_args);
            ("mpirun", a)
        } else {
            (solver, case_args)
        };
        let logs = self.step(dir, "solve", program, &args, remaining())?;
        let solve_s = t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        let tail = file_tail(&logs.join("stdout.log"), 16 * 1024).unwrap_or_default();
        if let Some(reason) = log_verdict(&tail) {
            return Err(ModelError::Failed {
                reason,
                log_tail: log_tail(&logs, 20),
            }
            .into());
        }
        let st = &self.settings;
        let k = st.iterations as f64;
        let probes = dir.join("postProcessing/probes/0/T");
        let text = std::fs::read_to_string(&probes)
            .map_err(|e| ModelError::failed(format!("{}: {e}", probes.display())))?;
        let window = probe_window(&text, self.geometry.probes.len(), k * st.average_from, k)
            .map_err(ModelError::failed)?;
        let mut flux_sum = 0.0;
        for p in self.geometry.room_openings() {
            let f = dir.join(format!(
                "postProcessing/flux_{}/0/surfaceFieldValue.dat",
                p.name
            ));
            let text = std::fs::read_to_string(&f)
                .map_err(|e| ModelError::failed(format!("{}: {e}", f.display())))?;
            flux_sum += last_field_value(&text)
                .map_err(|e| ModelError::failed(format!("{}: {e}", f.display())))?;
        }
        let rise_w = st.rho_kg_m3 * st.cp_j_kgk * flux_sum;
        let balance = (rise_w - inputs.heat_w) / inputs.heat_w.max(f64::MIN_POSITIVE);
        if !balance.is_finite() || balance.abs() > st.energy_tolerance {
            return Err(ModelError::Failed {
                reason: format!(
                    "energy balance off by {:.2} % (air carries {rise_w:.0} W out, servers put in {:.0} W; tolerance {:.1} %)",
                    100.0 * balance,
                    inputs.heat_w,
                    100.0 * st.energy_tolerance
                ),
                log_tail: log_tail(&logs, 20),
            }
            .into());
        }
        let server_intake_c = self
            .geometry
            .servers
            .iter()
            .map(|srv| {
                let f = dir.join(format!(
                    "postProcessing/intake_{}/0/surfaceFieldValue.dat",
                    srv.intake.name
                ));
                let text = std::fs::read_to_string(&f)
                    .map_err(|e| ModelError::failed(format!("{}: {e}", f.display())))?;
                let w = probe_window(&text, 1, k * st.average_from, k)
                    .map_err(|e| ModelError::failed(format!("{}: {e}", f.display())))?;
                match w.mean_c[0] {
                    t if t.is_finite() => Ok(t),
                    t => Err(ModelError::failed(format!(
                        "{}: intake at {t} C",
                        f.display()
                    ))),
                }
            })
            .collect::<Result<Vec<f64>, ModelError>>()?;
        let outputs = check_outputs(
            Outputs {
                values: window.mean_c,
                spread: Some(window.std_c),
                extras: [(SERVER_INTAKE_KEY.to_string(), server_intake_c)].into(),
            },
            &self.sensor_names,
        )?;
        Ok((
            outputs,
            RunTimings {
                prepare_s,
                solve_s,
                parse_s: t2.elapsed().as_secs_f64(),
                cleanup_s: 0.0,
                energy_balance: balance,
                killed_attempts: Vec::new(),
            },
        ))
    }

    /// Runs one program of a solve ([`run_solve_step`]).
    fn step(
        &self,
        dir: &Path,
        step: &str,
        program: &str,
        args: &[String],
        timeout: Duration,
    ) -> Result<PathBuf, StepFailure> {
        let project = &self.settings.project_dir;
        run_solve_step(
            dir,
            project,
            step,
            program,
            args,
            timeout,
            self.settings.timeout,
        )
    }
}
