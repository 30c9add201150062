//! The process groups of the model runs in progress, so that kalibre's own end (Ctrl-C,
//! `kill`, a closed terminal) ends them with it. Each run has its own process group
//! ([`super::run_process`]), which a terminal's Ctrl-C does not reach; the kernel's
//! parent-death signal reaches only a run's first process, not the solver a script
//! starts. [`end_runs_with_kalibre`] installs handlers that signal every group here.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU64, Ordering};
use std::sync::OnceLock;

/// Runs tracked at once; beyond this a run is not tracked (its first process still gets
/// the parent-death signal).
const SLOTS: usize = 256;

static GROUPS: [AtomicI32; SLOTS] = [const { AtomicI32::new(0) }; SLOTS];

/// The longest grace (ms) any tracked run was given between SIGTERM and SIGKILL
/// (`kill_grace_s`): how long kalibre's own end waits for its runs to go.
static STOP_GRACE_MS: AtomicU64 = AtomicU64::new(0);

/// The most kalibre's end waits for runs that ignore SIGTERM before it kills them (ms),
/// whatever their grace: an interrupted program should end soon.
const MAX_STOP_WAIT_MS: u64 = 30_000;

/// A tracked group; dropping it stops the tracking. Dropped before the group's leader
/// is reaped, while its id cannot yet be reused.
pub(crate) struct Tracked(Option<usize>);

/// Tracks the process group `pgid` until the returned guard is dropped; `kill_grace` is
/// how long the run may take to go after SIGTERM before it gets SIGKILL.
pub(crate) fn track(pgid: libc::pid_t, kill_grace: std::time::Duration) -> Tracked {
    let grace_ms = u64::try_from(kill_grace.as_millis()).unwrap_or(u64::MAX);
    STOP_GRACE_MS.fetch_max(grace_ms, Ordering::AcqRel);
    Tracked(GROUPS.iter().position(|g| {
        g.compare_exchange(0, pgid, Ordering::AcqRel, Ordering::Relaxed)
            .is_ok()
    }))
}

impl Drop for Tracked {
    fn drop(&mut self) {
        if let Some(i) = self.0 {
            GROUPS[i].store(0, Ordering::Release);
        }
    }
}

/// Sends `signal` to every tracked run's process group; returns how many there were.
/// Async-signal-safe (atomic loads and `kill(2)` only), so a signal handler may call it.
pub fn signal_runs(signal: libc::c_int) -> usize {
    let mut n = 0;
    for g in &GROUPS {
        let pgid = g.load(Ordering::Acquire);
        if pgid > 0 {
            // SAFETY: kill has no memory effects; a group already gone gives ESRCH.
            unsafe {
                libc::kill(-pgid, signal);
            }
            n += 1;
        }
    }
    n
}

/// Whether any tracked run's process group still has a process (a zombie leader counts
/// until its thread reaps it). Async-signal-safe.
fn any_run_alive() -> bool {
    GROUPS.iter().any(|g| {
        let pgid = g.load(Ordering::Acquire);
        // SAFETY: signal 0 only checks that the group exists.
        pgid > 0 && unsafe { libc::kill(-pgid, 0) } == 0
    })
}

/// After SIGTERM: waits for the runs to go, up to their grace, and sends SIGKILL to
/// every group still there, so that a run ignoring SIGTERM does not outlive kalibre,
/// hold its cores, and be taken for an abandoned run by the next command.
/// Async-signal-safe (atomics, `kill(2)`, `nanosleep(2)`).
fn kill_lingering_runs() {
    const STEP_MS: u64 = 20;
    let wait_ms = STOP_GRACE_MS.load(Ordering::Acquire).min(MAX_STOP_WAIT_MS);
    let mut waited_ms = 0;
    while waited_ms < wait_ms && any_run_alive() {
        let step = libc::timespec {
            tv_sec: 0,
            tv_nsec: (STEP_MS * 1_000_000) as libc::c_long,
        };
        // SAFETY: nanosleep only reads `step`; an interruption just shortens the wait.
        unsafe {
            libc::nanosleep(&step, std::ptr::null_mut());
        }
        waited_ms += STEP_MS;
    }
    signal_runs(libc::SIGKILL);
}

/// What [`end_runs_with_kalibre`]'s handler says, unless the program set its own
/// ([`set_stop_message`]).
const DEFAULT_STOP_MESSAGE: StopMessage = StopMessage {
    runs_ended: "kalibre: stopped; the model runs in progress were ended with it (finished \
                 runs are kept: the same command resumes where a journal is kept)\n",
    no_runs: "kalibre: stopped\n",
};

/// What the handler of [`end_runs_with_kalibre`] writes on stderr, one line each, ending
/// in a newline.
#[derive(Debug, Clone, Copy)]
pub struct StopMessage {
    /// When it ended external model runs in progress.
    pub runs_ended: &'static str,
    /// When none was in progress (in-process models, or between runs).
    pub no_runs: &'static str,
}

static STOP_MESSAGE: OnceLock<StopMessage> = OnceLock::new();

/// Sets what the handler of [`end_runs_with_kalibre`] writes on stderr: a command that
/// keeps a journal says where the finished runs are, one that keeps none says so rather
/// than promise a resume. The first call wins.
pub fn set_stop_message(message: StopMessage) {
    let _ = STOP_MESSAGE.set(message);
}

/// Set by the handler of [`end_runs_with_kalibre`] before it ends the runs in progress.
static STOPPING: AtomicBool = AtomicBool::new(false);

/// Whether kalibre is ending (the handler of [`end_runs_with_kalibre`] ran): a run that
/// ends killed now was ended by kalibre's own stop, not from outside, and is neither
/// retried nor journaled (the calibration loop waits for the end instead).
pub fn stopping() -> bool {
    STOPPING.load(Ordering::Acquire)
}

/// Once kalibre's stop has begun ([`stopping`]), waits for its handler to end the
/// process, so that a command which returns in the meantime (its runs just ended by the
/// stop) does not exit first with an error of its own. Returns at once otherwise. For the
/// end of a program's `main`.
pub fn await_stop() {
    while stopping() {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

extern "C" fn on_end_signal(signal: libc::c_int) {
    // An atomic store: async-signal-safe. Before the runs are signalled, so that no
    // worker takes their end for an outside kill.
    STOPPING.store(true, Ordering::Release);
    let ended = signal_runs(libc::SIGTERM) > 0;
    if ended {
        kill_lingering_runs();
    }
    // An atomic load once set: async-signal-safe.
    let message = STOP_MESSAGE.get().copied().unwrap_or(DEFAULT_STOP_MESSAGE);
    let said = if ended {
        message.runs_ended
    } else {
        message.no_runs
    };
    // SAFETY: write(2) is async-signal-safe; the text is static.
    unsafe {
        libc::write(2, said.as_ptr().cast(), said.len());
    }
    // End as the signal would have, with its exit status.
    // SAFETY: signal(2) and raise(3) are async-signal-safe.
    unsafe {
        libc::signal(signal, libc::SIG_DFL);
        libc::raise(signal);
    }
}

/// Installs handlers for SIGINT, SIGTERM and SIGHUP that send SIGTERM to every model
/// run in progress, SIGKILL to those still there after their grace (`kill_grace_s`, at
/// most 30 s), then end the process as the signal would have. For programs (the
/// `kalibre` CLI) that start model runs; a library leaves signals to its program.
pub fn end_runs_with_kalibre() {
    for signal in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        // SAFETY: the handler makes only async-signal-safe calls; installed before any
        // run starts.
        unsafe {
            libc::signal(signal, on_end_signal as *const () as libc::sighandler_t);
        }
    }
}
