//! The progress of `kalibre calibrate`: model runs done, iteration and best MAE. On a
//! terminal, a bar; otherwise (a log file, a batch job) a line on stderr at most every
//! [`LOG_EVERY`], so a calibration whose runs take minutes is not silent for an hour,
//! while one that ends within it prints nothing.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

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

/// Progress driven by calibration events.
pub(super) struct Progress {
    runs: ProgressBar,
    best_mae: Mutex<Option<f64>>,
    iteration: Mutex<usize>,
    log: Option<Mutex<Log>>,
}

impl Progress {
    pub(super) fn new(total_runs: u64, quiet: bool) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let log = (!quiet && !terminal).then(|| {
            let out: Box<dyn Write + Send> = Box::new(std::io::stderr());
            (out, LOG_EVERY)
        });
        Self::with(total_runs, !quiet && terminal, log)
    }

    /// A bar on stderr when `bar`, and lines to `log`'s writer at most every its
    /// duration.
    fn with(total_runs: u64, bar: bool, log: Option<(Box<dyn Write + Send>, Duration)>) -> Self {
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
            best_mae: Mutex::new(None),
            iteration: Mutex::new(0),
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
        let iteration = *self.iteration.lock().unwrap_or_else(|p| p.into_inner());
        let best = *self.best_mae.lock().unwrap_or_else(|p| p.into_inner());
        let line = format!(
            "kalibre: {} model runs done (of about {} planned), {}, best MAE {}, {} elapsed\n",
            self.runs.position(),
            self.runs.length().unwrap_or(0),
            match iteration {
                0 => "initial design".to_string(),
                i => format!("iteration {i}"),
            },
            best.map_or("-".into(), |b| format!("{b:.3} C")),
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
            Event::RunFinished { .. } => {
                self.runs.inc(1);
                self.log_line();
            }
            Event::IterationDone { record } => {
                let mut best = self.best_mae.lock().unwrap_or_else(|p| p.into_inner());
                if let Some(m) = record.mae_c.filter(|m| m.is_finite()) {
                    *best = Some(best.map_or(m, |b: f64| b.min(m)));
                }
                *self.iteration.lock().unwrap_or_else(|p| p.into_inner()) = record.iteration;
                self.runs.set_message(format!(
                    "iteration {} | best MAE {}",
                    record.iteration,
                    best.map_or("-".into(), |b| format!("{b:.3} C"))
                ));
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

    #[test]
    fn a_log_gets_a_line_per_interval_and_none_sooner() {
        let out = Shared::default();
        let every_time = Progress::with(12, false, Some((Box::new(out.clone()), Duration::ZERO)));
        run_event(&every_time);
        run_event(&every_time);
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[1].starts_with(
                "kalibre: 2 model runs done (of about 12 planned), initial design, best MAE -, \
                 00:00:00 elapsed"
            ),
            "{text}"
        );

        let out = Shared::default();
        let hourly = Progress::with(
            12,
            false,
            Some((Box::new(out.clone()), Duration::from_secs(3600))),
        );
        run_event(&hourly);
        assert!(out.0.lock().unwrap().is_empty());
    }
}
