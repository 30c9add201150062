//! The progress bar of `kalibre calibrate`: model runs done, iteration and best MAE.

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use kalibre_core::{Event, Observe};

/// Progress bars driven by calibration events; hidden when stderr is not a terminal.
pub(super) struct Progress {
    runs: ProgressBar,
    best_mae: Mutex<Option<f64>>,
}

impl Progress {
    pub(super) fn new(total_runs: u64, quiet: bool) -> Self {
        let target = if quiet || !std::io::stderr().is_terminal() {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
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
        }
    }
}

impl Observe for Progress {
    fn observe(&self, event: &Event<'_>) {
        match event {
            Event::RunFinished { .. } => self.runs.inc(1),
            Event::IterationDone { record } => {
                let mut best = self.best_mae.lock().unwrap_or_else(|p| p.into_inner());
                if let Some(m) = record.mae_c.filter(|m| m.is_finite()) {
                    *best = Some(best.map_or(m, |b: f64| b.min(m)));
                }
                self.runs.set_message(format!(
                    "iteration {} | best MAE {}",
                    record.iteration,
                    best.map_or("-".into(), |b| format!("{b:.3} C"))
                ));
            }
            Event::Stopped { .. } => self.runs.finish_and_clear(),
            _ => {}
        }
    }
}
