//! One OpenFOAM program of a solve, and how its end reads: success, a failure of the
//! solve itself (a divergence, a bad exit), a timeout, or a kill from outside (the
//! out-of-memory killer, an administrator, a scheduler's preemption), which says
//! nothing about the parameters and which a second attempt may outlive.

use std::path::{Path, PathBuf};
use std::time::Duration;

use kalibre_core::external::{log_tail, ProcessEnd};
use kalibre_core::ModelError;

use super::case::run_step;
use super::results::{file_tail, shows_fpe, FPE_VERDICT};

const SIGKILL: i32 = 9;
const SIGTERM: i32 = 15;
/// SIGFPE's number on Linux and the BSDs.
const SIGFPE: i32 = 8;

/// A failed attempt at a solve: the error, and the signal of a kill from outside when
/// that is what ended it.
#[derive(Debug)]
pub(super) struct StepFailure {
    pub error: ModelError,
    pub killed_by: Option<i32>,
}

impl From<ModelError> for StepFailure {
    fn from(error: ModelError) -> Self {
        StepFailure {
            error,
            killed_by: None,
        }
    }
}

/// The signal of a kill from outside in a program's end: SIGKILL or SIGTERM, received
/// directly, or passed on as the exit code 128 + n by `mpirun` or a shell; `None` for
/// every other end (SIGFPE and SIGSEGV are the solve's own failures). A kill during
/// kalibre's own stop is not from outside.
pub(super) fn killed_from_outside(end: &ProcessEnd) -> Option<i32> {
    let signal = match *end {
        ProcessEnd::Signalled(s) => s,
        ProcessEnd::Exited(c) if c > 128 => c - 128,
        _ => return None,
    };
    let outside = matches!(signal, SIGKILL | SIGTERM) && !kalibre_core::external::stopping();
    outside.then_some(signal)
}

/// Runs one program of a solve in `dir` (logs in `dir/logs/<step>`); a failed end
/// becomes a [`StepFailure`]. `limit` is the run's whole wall-clock limit, for the
/// message of a timeout.
pub(super) fn run_solve_step(
    dir: &Path,
    project_dir: &Path,
    step: &str,
    program: &str,
    args: &[String],
    timeout: Duration,
    limit: Duration,
) -> Result<PathBuf, StepFailure> {
    let (out, logs) = run_step(dir, project_dir, step, program, args, timeout)
        .map_err(|e| ModelError::failed(e.to_string()))?;
    let tail = || log_tail(&logs, 20);
    let mut killed_by = killed_from_outside(&out.end);
    let error = match out.end {
        ProcessEnd::Exited(0) => return Ok(logs),
        ProcessEnd::Exited(c) => {
            // OpenFOAM prints its trace on stderr, a shell's message on stdout.
            let fpe = ["stdout.log", "stderr.log"]
                .iter()
                .any(|f| file_tail(&logs.join(f), 16 * 1024).is_some_and(|t| shows_fpe(&t)));
            if fpe {
                // A divergence's exit is the solve's own, whatever its code.
                killed_by = None;
            }
            ModelError::Failed {
                reason: match (fpe, killed_by) {
                    (true, _) => FPE_VERDICT.into(),
                    (false, Some(s)) => format!(
                        "{program} ({step}) exited with code {c}: a process of it was killed \
                         by signal {s} from outside kalibre (the out-of-memory killer?)"
                    ),
                    (false, None) => format!("{program} ({step}) exited with code {c}"),
                },
                log_tail: tail(),
            }
        }
        ProcessEnd::Signalled(s) => ModelError::Failed {
            reason: match (s, killed_by) {
                (SIGFPE, _) => format!("{program} ({step}): floating-point exception (SIGFPE)"),
                (_, Some(_)) => format!(
                    "{program} ({step}) killed by signal {s} from outside kalibre (the \
                     out-of-memory killer?)"
                ),
                _ => format!("{program} ({step}) killed by signal {s}"),
            },
            log_tail: tail(),
        },
        ProcessEnd::TimedOut { .. } => ModelError::Timeout {
            seconds: limit.as_secs_f64(),
            log_tail: tail(),
        },
    };
    Err(StepFailure { error, killed_by })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kills_from_outside_are_told_from_the_solves_own_ends() {
        assert_eq!(killed_from_outside(&ProcessEnd::Signalled(9)), Some(9));
        assert_eq!(killed_from_outside(&ProcessEnd::Signalled(15)), Some(15));
        // mpirun and shells pass a child's kill on as 128 + n.
        assert_eq!(killed_from_outside(&ProcessEnd::Exited(137)), Some(9));
        assert_eq!(killed_from_outside(&ProcessEnd::Exited(143)), Some(15));
        // A divergence (SIGFPE), a crash (SIGSEGV) and a plain failure are the solve's.
        assert_eq!(killed_from_outside(&ProcessEnd::Signalled(8)), None);
        assert_eq!(killed_from_outside(&ProcessEnd::Signalled(11)), None);
        assert_eq!(killed_from_outside(&ProcessEnd::Exited(139)), None);
        assert_eq!(killed_from_outside(&ProcessEnd::Exited(1)), None);
        assert_eq!(killed_from_outside(&ProcessEnd::Exited(0)), None);
    }
}
