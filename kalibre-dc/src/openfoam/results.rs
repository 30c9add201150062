//! Reading a finished run: the solver log's verdict, the probes' window means and
//! spreads, and the energy balance over the openings.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// The end of a file (at most `max` bytes), lossily decoded.
pub fn file_tail(path: &Path, max: u64) -> Option<String> {
    let mut f = File::open(path).ok()?;
    let len = f.metadata().ok()?.len();
    f.seek(SeekFrom::Start(len.saturating_sub(max))).ok()?;
    let mut buf = Vec::new();
    f.read_to_end(&mut buf).ok()?;
    Some(String::from_utf8_lossy(&buf).into_owned())
}

/// The reason a run fails with when its solver hit a floating-point exception.
pub const FPE_VERDICT: &str = "floating-point exception in the solver (diverged)";

/// Why a solver log shows a failed run, if it does.
pub fn log_verdict(tail: &str) -> Option<String> {
    if let Some(i) = tail.find("FOAM FATAL") {
        let msg: String = tail[i..].lines().take(6).collect::<Vec<_>>().join(" | ");
        return Some(format!("OpenFOAM error: {msg}"));
    }
    if shows_fpe(tail) {
        return Some(FPE_VERDICT.into());
    }
    if !tail.lines().any(|l| l.trim() == "End") {
        return Some("the solver log has no `End` line (the run did not finish)".into());
    }
    None
}

/// A floating-point exception's trace (`Foam::sigFpe::sigHandler`) or the shell's
/// `Floating point exception (core dumped)`. Not the banner every solver prints at start
/// (`trapFpe: Floating point exception trapping enabled`, or `sigFpe : Enabling floating
/// point exception trapping` in older versions), which a short log keeps in its tail.
pub fn shows_fpe(log: &str) -> bool {
    log.lines().any(|l| {
        let l = l.trim_start();
        l.contains("sigFpe::sigHandler") || l.starts_with("Floating point exception")
    })
}

/// Window means and spreads (population standard deviation) of the probes.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeWindow {
    /// Mean per probe over the window (C).
    pub mean_c: Vec<f64>,
    /// Standard deviation per probe over the window (C).
    pub std_c: Vec<f64>,
    /// Samples in the window.
    pub samples: usize,
}

/// Averages the samples of a `probes` output file with time in `(from, to]`.
pub fn probe_window(
    text: &str,
    n_probes: usize,
    from: f64,
    to: f64,
) -> Result<ProbeWindow, String> {
    let mut sum = vec![0.0; n_probes];
    let mut sum2 = vec![0.0; n_probes];
    let mut samples = 0usize;
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (no, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split_whitespace();
        let t: f64 = it
            .next()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| format!("probes line {}: no time", no + 1))?;
        if !(t > from && t <= to + 1e-9) {
            continue;
        }
        let vals: Vec<f64> = it.map(|s| s.parse::<f64>().unwrap_or(f64::NAN)).collect();
        if vals.len() != n_probes {
            return Err(format!(
                "probes line {}: {} values, expected {n_probes} (a probe outside the mesh?)",
                no + 1,
                vals.len()
            ));
        }
        rows.push(vals);
    }
    // Two passes (mean, then deviations) keep the spread exact when it is tiny.
    for r in &rows {
        for (s, v) in sum.iter_mut().zip(r) {
            *s += v;
        }
        samples += 1;
    }
    if samples == 0 {
        return Err(format!(
            "no probe sample in the averaging window ({from}, {to}]"
        ));
    }
    let mean: Vec<f64> = sum.iter().map(|s| s / samples as f64).collect();
    for r in &rows {
        for ((s2, v), m) in sum2.iter_mut().zip(r).zip(&mean) {
            *s2 += (v - m) * (v - m);
        }
    }
    Ok(ProbeWindow {
        std_c: sum2.iter().map(|s| (s / samples as f64).sqrt()).collect(),
        mean_c: mean,
        samples,
    })
}

/// The last value of a `surfaceFieldValue.dat` file (second column of its last row).
pub fn last_field_value(text: &str) -> Result<f64, String> {
    let line = text
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .ok_or("no data row")?;
    line.split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("no value in row `{line}`"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_mean_and_spread() {
        let text = "# Probe 0 (1 1 1)\n# Probe 1 (2 2 2)\n#  Time\n5 10 20\n10 11 21\n15 13 23\n";
        let w = probe_window(text, 2, 5.0, 15.0).unwrap();
        assert_eq!(w.samples, 2);
        assert!((w.mean_c[0] - 12.0).abs() < 1e-12 && (w.mean_c[1] - 22.0).abs() < 1e-12);
        assert!((w.std_c[0] - 1.0).abs() < 1e-12);
        assert!(probe_window(text, 3, 0.0, 15.0).is_err());
        assert!(probe_window(text, 2, 15.0, 20.0).is_err());
    }

    #[test]
    fn log_verdicts() {
        assert_eq!(log_verdict("Time = 1000\n\nEnd\n\n"), None);
        assert!(log_verdict("Time = 3\n").unwrap().contains("End"));
        assert!(
            log_verdict("#0 Foam::sigFpe::sigHandler(int)\nFloating point exception")
                .unwrap()
                .contains("floating-point")
        );
        assert!(shows_fpe("Floating point exception (core dumped)\n"));
        // The start-up banners say trapping is on; a finished short run keeps them in
        // its tail and is no failure.
        for banner in [
            "trapFpe: Floating point exception trapping enabled (FOAM_SIGFPE).",
            "sigFpe : Enabling floating point exception trapping (FOAM_SIGFPE).",
        ] {
            let log = format!("nProcs : 1\n{banner}\nTime = 10\n\nEnd\n\n");
            assert_eq!(log_verdict(&log), None, "{banner}");
            assert!(!shows_fpe(&log));
        }
        // A fatal error is named as such, banner or not.
        let fatal = "trapFpe: Floating point exception trapping enabled\n--> FOAM FATAL ERROR: \
                     cannot find file \"0/T\"\n";
        assert!(log_verdict(fatal)
            .unwrap()
            .starts_with("OpenFOAM error: FOAM FATAL ERROR"));
    }

    #[test]
    fn last_value() {
        let t = "# Time weightedSum(T)\n1 -3.5\n2 -4.25\n";
        assert_eq!(last_field_value(t).unwrap(), -4.25);
    }
}
