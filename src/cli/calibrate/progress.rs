//! The progress of `kalibre calibrate`: model runs done, iteration and best MAE. On a
//! terminal, a bar; otherwise (a log file, a batch job) a line on stderr at most every
//! [`LOG_EVERY`], so a calibration whose runs take minutes is not silent for an hour,
//! while one that ends within it prints nothing.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::summary::Style;
use indicatif::{FormattedDuration, ProgressBar, ProgressDrawTarget, ProgressStyle};
use kalibre_core::{Event, Observe};

/// The least time between two progress lines when stderr is not a terminal.
const LOG_EVERY: Duration = Duration::from_secs(30);

/// Progress lines for a log: where, how often, and when the last was written.
struct Log {
    out: Box<dyn Write + Send>,
    every: Duration,
    last: Instant,
}

/// What a calibration may run, for the bar's length: the most model runs it can take.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plan {
    /// Snapshots (each point runs once per snapshot).
    pub(super) snapshots: usize,
    /// The loop's iterations after the design.
    pub(super) iterations: usize,
    /// Levenberg-Marquardt steps after the loop.
    pub(super) polish_iterations: usize,
    /// Most parameters for which the polish runs.
    pub(super) polish_max_params: usize,
    /// What is calibrated, for the unit of the best MAE.
    pub(super) style: Style,
}

impl Plan {
    /// The most model runs: a design of at most 4 points, one point per iteration, and
    /// per polish step a Jacobian (one point per parameter) and the step, all at every
    /// snapshot. The parameters are counted once the first run shows them (`dim`).
    fn most_runs(&self, dim: Option<usize>) -> u64 {
        let polish_points = match dim {
            Some(d) if d <= self.polish_max_params => self.polish_iterations * (d + 1),
            _ => 0,
        };
        ((4 + self.iterations + polish_points) * self.snapshots) as u64
    }
}

/// Where the calibration is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Design,
    Iteration(usize),
    /// The n-th polish step done.
    Polish(usize),
}

impl std::fmt::Display for Phase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Phase::Design => write!(f, "initial design"),
            Phase::Iteration(i) => write!(f, "iteration {i}"),
            Phase::Polish(k) => write!(f, "polish step {k}"),
        }
    }
}

/// Progress driven by calibration events.
pub(super) struct Progress {
    runs: ProgressBar,
    plan: Plan,
    /// Whether the bar's length counts the polish yet (it needs the parameter count).
    sized: std::sync::atomic::AtomicBool,
    best_mae: Mutex<Option<f64>>,
    phase: Mutex<Phase>,
    log: Option<Mutex<Log>>,
}

impl Progress {
    pub(super) fn new(plan: Plan, quiet: bool) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let log = (!quiet && !terminal).then(|| {
            let out: Box<dyn Write + Send> = Box::new(std::io::stderr());
            (out, LOG_EVERY)
        });
        Self::with(plan, !quiet && terminal, log)
    }

    /// A bar on stderr when `bar`, and lines to `log`'s writer at most every its
    /// duration.
    fn with(plan: Plan, bar: bool, log: Option<(Box<dyn Write + Send>, Duration)>) -> Self {
        let total_runs = plan.most_runs(None);
        let target = if bar {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let runs = ProgressBar::with_draw_target(Some(total_runs), target);
        runs.set_style(
            ProgressStyle::with_template(
                "{spinner} model runs {pos}/{len} [{bar:30}] {elapsed_precise} {msg}",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        Progress {
            runs,
            plan,
            sized: std::sync::atomic::AtomicBool::new(false),
            best_mae: Mutex::new(None),
            phase: Mutex::new(Phase::Design),
            log: log.map(|(out, every)| {
                Mutex::new(Log {
                    out,
                    every,
                    last: Instant::now(),
                })
            }),
        }
    }

    /// Writes a progress line when the last is old enough.
    fn log_line(&self) {
        let Some(log) = &self.log else {
            return;
        };
        let mut log = log.lock().unwrap_or_else(|p| p.into_inner());
        let now = Instant::now();
        if now.duration_since(log.last) < log.every {
            return;
        }
        log.last = now;
        let phase = *self.phase.lock().unwrap_or_else(|p| p.into_inner());
        let best = *self.best_mae.lock().unwrap_or_else(|p| p.into_inner());
        let line = format!(
            "kalibre: {} model runs done (of at most {} planned), {phase}, best MAE {}, {} \
             elapsed\n",
            self.runs.position(),
            self.runs.length().unwrap_or(0),
            self.plan.style.error(best),
            // As the bar's `elapsed_precise`.
            FormattedDuration(self.runs.elapsed())
        );
        // A log that cannot be written must not stop the calibration.
        let _ = log.out.write_all(line.as_bytes());
        let _ = log.out.flush();
    }
}

impl Observe for Progress {
    fn observe(&self, event: &Event<'_>) {
        match event {
            Event::RunFinished { params, .. } => {
                if !self.sized.swap(true, std::sync::atomic::Ordering::Relaxed) {
                    self.runs
                        .set_length(self.plan.most_runs(Some(params.len())));
                }
                self.runs.inc(1);
                self.log_line();
            }
            Event::IterationDone { record } => {
                let mut best = self.best_mae.lock().unwrap_or_else(|p| p.into_inner());
                if let Some(m) = record.mae_c.filter(|m| m.is_finite()) {
                    *best = Some(best.map_or(m, |b: f64| b.min(m)));
                }
                let mut phase = self.phase.lock().unwrap_or_else(|p| p.into_inner());
                // Polish steps fit no surrogate (no training samples); their record
                // numbers count on past the loop's, two per step with a new Jacobian.
                // A Jacobian's runs have a record (with no search loss) only when one
                // of them became the best point: no step of its own.
                let differences = record.training_samples == 0 && record.search_loss.is_nan();
                *phase = match (*phase, record.training_samples) {
                    _ if differences => *phase,
                    (Phase::Polish(k), 0) => Phase::Polish(k + 1),
                    (_, 0) => Phase::Polish(1),
                    _ => Phase::Iteration(record.iteration),
                };
                self.runs.set_message(format!(
                    "{phase} | best MAE {}",
                    self.plan.style.error(*best)
                ));
                drop(phase);
                drop(best);
                self.log_line();
            }
            Event::Stopped { .. } => self.runs.finish_and_clear(),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibre_core::calibrate::IterationRecord;
    use std::sync::Arc;

    /// A writer the test reads back.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn run_event(p: &Progress) {
        p.observe(&Event::RunFinished {
            iteration: 0,
            snapshot: "t0",
            params: &[0.1],
            cached: false,
            error: None,
            wall_s: 40.0,
        });
    }

    /// Three snapshots, no iterations, no polish: the design's 12 runs at most.
    const DESIGN_ONLY: Plan = Plan {
        snapshots: 3,
        iterations: 0,
        polish_iterations: 0,
        polish_max_params: 64,
        style: Style::Hall,
    };

    fn record(iteration: usize, training_samples: usize, mae_c: f64) -> IterationRecord {
        IterationRecord {
            iteration,
            model_runs: 0,
            mae_c: Some(mae_c),
            rmse_c: None,
            max_abs_c: None,
            score: None,
            best_mae_c: None,
            per_snapshot: Vec::new(),
            per_group: Default::default(),
            fit_mse: f64::NAN,
            training_samples,
            // A step predicts its loss; a Jacobian's own record has none.
            search_loss: 0.1,
            search_data_mse: f64::NAN,
            search_evaluations: 0,
            failed_runs: 0,
            perturbed: false,
            params: Default::default(),
            wall_s: Default::default(),
        }
    }

    fn text_of(out: &Shared) -> String {
        String::from_utf8(out.0.lock().unwrap().clone()).unwrap()
    }

    #[test]
    fn a_log_gets_a_line_per_interval_and_none_sooner() {
        let out = Shared::default();
        let every_time = Progress::with(
            DESIGN_ONLY,
            false,
            Some((Box::new(out.clone()), Duration::ZERO)),
        );
        run_event(&every_time);
        run_event(&every_time);
        let text = text_of(&out);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[1].starts_with(
                "kalibre: 2 model runs done (of at most 12 planned), initial design, best MAE \
                 -, 00:00:00 elapsed"
            ),
            "{text}"
        );

        let out = Shared::default();
        let hourly = Progress::with(
            DESIGN_ONLY,
            false,
            Some((Box::new(out.clone()), Duration::from_secs(3600))),
        );
        run_event(&hourly);
        assert!(out.0.lock().unwrap().is_empty());
    }

    /// The plan counts the polish's Jacobians once a run shows the parameters, and the
    /// polish's steps are named as such, not as iterations past `--iterations`.
    #[test]
    fn the_plan_counts_the_polish_and_its_steps_are_named() {
        let plan = Plan {
            snapshots: 16,
            iterations: 10,
            polish_iterations: 8,
            polish_max_params: 64,
            style: Style::Hall,
        };
        let out = Shared::default();
        let p = Progress::with(plan, false, Some((Box::new(out.clone()), Duration::ZERO)));
        assert_eq!(p.runs.length(), Some(224));
        let five_params = Event::RunFinished {
            iteration: 0,
            snapshot: "t0",
            params: &[0.1; 5],
            cached: false,
            error: None,
            wall_s: 1.0,
        };
        // Five parameters: 8 steps of 6 points at 16 snapshots more.
        p.observe(&five_params);
        assert_eq!(p.runs.length(), Some(224 + 8 * 6 * 16));
        p.observe(&Event::IterationDone {
            record: &record(10, 48, 0.5),
        });
        p.observe(&Event::IterationDone {
            record: &record(12, 0, 0.4),
        });
        // A finite difference of step 2's Jacobian became the best point: its record
        // is no step.
        p.observe(&Event::IterationDone {
            record: &IterationRecord {
                search_loss: f64::NAN,
                ..record(13, 0, 0.35)
            },
        });
        p.observe(&Event::IterationDone {
            record: &record(14, 0, 0.3),
        });
        let text = text_of(&out);
        let lines: Vec<&str> = text.lines().collect();
        assert!(
            lines[1].contains(", iteration 10, best MAE 0.500 C"),
            "{text}"
        );
        assert!(
            lines[2].contains(", polish step 1, best MAE 0.400 C"),
            "{text}"
        );
        assert!(
            lines[3].contains(", polish step 1, best MAE 0.350 C"),
            "{text}"
        );
        assert!(
            lines[4].contains(", polish step 2, best MAE 0.300 C"),
            "{text}"
        );
        // More parameters than the polish takes: no polish in the plan.
        let p = Progress::with(
            Plan {
                polish_max_params: 4,
                ..plan
            },
            false,
            None,
        );
        p.observe(&five_params);
        assert_eq!(p.runs.length(), Some(224));
    }
}
