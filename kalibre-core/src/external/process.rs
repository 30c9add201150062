//! Running one program: argument list, own process group, logs, wall-clock timeout.
//!
//! The program starts in a new process group (`process_group(0)`) with stdin closed and
//! stdout/stderr written to [`STDOUT_LOG`] and [`STDERR_LOG`] in its directory. A waiter
//! thread blocks in `waitid(WNOWAIT)`, which sees the exit without reaping: while the
//! leader is an unreaped zombie its pid, which is the group id, cannot be reused, so
//! signalling the group can only hit the run's own processes. On timeout the group gets
//! SIGTERM, then SIGKILL after a grace period. After the leader exits (normally or not)
//! the group gets SIGKILL so no stray child outlives its run, and only then is the leader
//! reaped.

use std::ffi::OsStr;
use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// File in the run directory that receives the program's stdout.
pub const STDOUT_LOG: &str = "stdout.log";
/// File in the run directory that receives the program's stderr.
pub const STDERR_LOG: &str = "stderr.log";

/// How long to wait for a SIGKILLed group leader before giving up on reaping it in line
/// (a process in uninterruptible sleep, e.g. on a hung network file system).
const KILL_WAIT: Duration = Duration::from_secs(30);

/// What to run.
#[derive(Debug, Clone, Copy)]
pub struct ProcessSpec<'a> {
    /// The program: a path, or a name looked up in `PATH`.
    pub program: &'a OsStr,
    /// Arguments, each passed as one `argv` element (no shell, no word splitting).
    pub args: &'a [String],
    /// Environment variables added to the inherited environment.
    pub env: &'a [(String, String)],
    /// Working directory; the logs go here.
    pub dir: &'a Path,
    /// Wall-clock limit.
    pub timeout: Duration,
    /// Time between SIGTERM and SIGKILL on timeout.
    pub kill_grace: Duration,
}

/// How the program ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProcessEnd {
    /// It exited with this code.
    Exited(i32),
    /// A signal it did not receive from us ended it (crash, out-of-memory killer).
    Signalled(i32),
    /// It ran past the limit and its process group was killed.
    TimedOut {
        /// True when SIGTERM was not enough and SIGKILL was sent.
        needed_sigkill: bool,
    },
}

/// The result of [`run_process`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessOutcome {
    /// How it ended.
    pub end: ProcessEnd,
    /// Wall time from spawn to reap.
    pub elapsed: Duration,
}

fn signal_group(pgid: libc::pid_t, signal: libc::c_int) {
    // SAFETY: killpg has no memory effects; an error (ESRCH: the group is gone) is fine.
    unsafe {
        libc::killpg(pgid, signal);
    }
}

/// Blocks until `pid` has exited, without reaping it.
fn wait_exit_no_reap(pid: libc::pid_t) -> io::Result<()> {
    loop {
        // SAFETY: siginfo_t is plain data; zeroed is a valid value for waitid to fill.
        let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
        // SAFETY: a valid pointer to a live siginfo_t.
        let r = unsafe {
            libc::waitid(
                libc::P_PID,
                pid as libc::id_t,
                &mut info,
                libc::WEXITED | libc::WNOWAIT,
            )
        };
        if r == 0 {
            return Ok(());
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

/// Runs a program to its end or its timeout. An error means it could not be started
/// (program not found, logs not writable) or not waited for.
pub fn run_process(spec: &ProcessSpec<'_>) -> io::Result<ProcessOutcome> {
    // kalibre's stop waits for the runs in progress to go; none starts meanwhile.
    if super::groups::stopping() {
        return Err(io::Error::other("kalibre is stopping"));
    }
    let stdout = File::create(spec.dir.join(STDOUT_LOG))?;
    let stderr = File::create(spec.dir.join(STDERR_LOG))?;
    let mut cmd = Command::new(spec.program);
    cmd.args(spec.args)
        .current_dir(spec.dir)
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(stderr)
        .process_group(0);
    for (k, v) in spec.env {
        cmd.env(k, v);
    }
    // The run has its own process group, so a Ctrl-C or a kill of kalibre does not reach
    // it: ask the kernel to send it SIGTERM when the thread that started it ends (this
    // thread waits for the run, so only kalibre's own end can trigger it). An orphaned
    // solver would otherwise hold its cores until its end, and its result is lost anyway.
    #[cfg(target_os = "linux")]
    {
        let parent = std::process::id() as libc::pid_t;
        // SAFETY: only async-signal-safe calls (prctl, getppid, _exit) between fork and exec.
        unsafe {
            cmd.pre_exec(move || {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(io::Error::last_os_error());
                }
                // kalibre may have ended before the prctl took effect.
                if libc::getppid() != parent {
                    libc::_exit(1);
                }
                Ok(())
            });
        }
    }
    let start = Instant::now();
    let mut child = cmd.spawn()?;
    let pid = child.id() as libc::pid_t;
    // Untracked (below) before the leader is reaped, while its id cannot be reused.
    let tracked = super::groups::track(pid, spec.kill_grace);
    let (tx, rx) = mpsc::channel();
    let waiter = std::thread::Builder::new()
        .name(format!("kalibre-wait-{pid}"))
        .spawn(move || {
            let _ = tx.send(wait_exit_no_reap(pid));
        });
    let waiter = match waiter {
        Ok(w) => w,
        Err(e) => {
            signal_group(pid, libc::SIGKILL);
            drop(tracked);
            let _ = child.wait();
            return Err(e);
        }
    };

    let mut timed_out = None;
    let exited = match rx.recv_timeout(spec.timeout) {
        Ok(r) => r,
        Err(_) => {
            signal_group(pid, libc::SIGTERM);
            match rx.recv_timeout(spec.kill_grace) {
                Ok(r) => {
                    timed_out = Some(false);
                    r
                }
                Err(_) => {
                    timed_out = Some(true);
                    signal_group(pid, libc::SIGKILL);
                    match rx.recv_timeout(KILL_WAIT) {
                        Ok(r) => r,
                        Err(_) => {
                            // Unkillable for now: reap it whenever it goes, off this thread.
                            drop(tracked);
                            std::thread::spawn(move || {
                                let _ = child.wait();
                            });
                            return Ok(ProcessOutcome {
                                end: ProcessEnd::TimedOut {
                                    needed_sigkill: true,
                                },
                                elapsed: start.elapsed(),
                            });
                        }
                    }
                }
            }
        }
    };
    // The leader is exited but unreaped (or waitid failed and we reap below anyway):
    // clear the rest of its group before the pid can be recycled.
    if exited.is_ok() {
        signal_group(pid, libc::SIGKILL);
    }
    drop(tracked);
    let status = child.wait()?;
    let _ = waiter.join();
    let elapsed = start.elapsed();
    let end = match (timed_out, status.code(), status.signal()) {
        (Some(needed_sigkill), _, _) => ProcessEnd::TimedOut { needed_sigkill },
        (None, Some(code), _) => ProcessEnd::Exited(code),
        (None, None, Some(sig)) => ProcessEnd::Signalled(sig),
        (None, None, None) => ProcessEnd::Exited(-1),
    };
    Ok(ProcessOutcome { end, elapsed })
}

/// The last `n` lines of a file, reading at most its last 64 KiB; empty if unreadable. A
/// carriage return ends a line too (a progress bar redraws one), and a line too long to
/// show keeps its end, where solvers print what went wrong.
fn tail_lines(path: &Path, n: usize) -> Vec<String> {
    const MAX_BYTES: u64 = 64 * 1024;
    const MAX_LINE: usize = 400;
    let Ok(mut f) = File::open(path) else {
        return Vec::new();
    };
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let skip = len.saturating_sub(MAX_BYTES);
    if f.seek(SeekFrom::Start(skip)).is_err() {
        return Vec::new();
    }
    let mut buf = Vec::new();
    if f.read_to_end(&mut buf).is_err() {
        return Vec::new();
    }
    let text = String::from_utf8_lossy(&buf);
    let mut lines: Vec<&str> = text.split(['\n', '\r']).collect();
    // The window cut its first line; when that is the only one, its end is all there is.
    if skip > 0 && lines.len() > 1 {
        lines.remove(0);
    }
    lines.retain(|l| !l.trim().is_empty());
    let from = lines.len().saturating_sub(n);
    lines[from..]
        .iter()
        .map(|l| {
            if l.len() > MAX_LINE {
                let cut = (l.len() - MAX_LINE..l.len())
                    .find(|&i| l.is_char_boundary(i))
                    .unwrap_or(l.len());
                format!("...{}", &l[cut..])
            } else {
                l.to_string()
            }
        })
        .collect()
}

/// The end of a run's logs: up to `max_lines` lines shared between stderr (at least half
/// when it has that many) and stdout, each under a `==> file <==` heading; `None` when
/// both are empty.
pub fn log_tail(dir: &Path, max_lines: usize) -> Option<String> {
    let err = tail_lines(&dir.join(STDERR_LOG), max_lines);
    let out = tail_lines(&dir.join(STDOUT_LOG), max_lines);
    let n_err = err
        .len()
        .min((max_lines / 2).max(max_lines.saturating_sub(out.len())));
    let n_out = out.len().min(max_lines - n_err);
    let mut s = String::new();
    for (name, lines, n) in [(STDOUT_LOG, &out, n_out), (STDERR_LOG, &err, n_err)] {
        if n > 0 {
            s.push_str(&format!("==> {name} <==\n"));
            for l in &lines[lines.len() - n..] {
                s.push_str(l);
                s.push('\n');
            }
        }
    }
    (!s.is_empty()).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A solver's error after a progress bar of carriage returns, or at the end of a line
    /// longer than the window read, is what the tail shows.
    #[test]
    fn the_tail_keeps_the_end_of_progress_bars_and_long_lines() {
        let dir = std::env::temp_dir().join(format!("kalibre-tail-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let progress: String = (0..20_000).map(|i| format!("\rstep {i}")).collect();
        std::fs::write(
            dir.join(STDERR_LOG),
            format!("{progress}\rERROR: solver diverged"),
        )
        .unwrap();
        std::fs::write(dir.join(STDOUT_LOG), "").unwrap();
        let tail = log_tail(&dir, 4).unwrap();
        assert!(
            tail.ends_with("step 19999\nERROR: solver diverged\n"),
            "{tail}"
        );
        let long = format!("{}ERROR: mesh not found", "Z".repeat(200_000));
        std::fs::write(dir.join(STDERR_LOG), long).unwrap();
        let tail = log_tail(&dir, 4).unwrap();
        assert!(tail.ends_with("ZZZERROR: mesh not found\n"), "{tail}");
        assert!(tail.len() < 500, "{} bytes", tail.len());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
