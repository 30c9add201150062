//! Warnings about inputs that read well but no hall produces: a reading colder than the
//! supply, a unit slip in a CRAC's air flow or in the servers' powers. They warn rather
//! than refuse, as the user may mean it (a test rig, an idle hall), and name the file and
//! snapshot to look at.

use std::path::Path;

use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{self, HallSnapshot, OperatingState};

/// ` (N more such WHAT)` after the first of `count` findings; empty for one.
fn more_such(count: usize, what: &str) -> String {
    match count {
        0 | 1 => String::new(),
        n => format!(" ({} more such {what})", n - 1),
    }
}

/// Warns of readings colder than every running CRAC's supply (a faulty sensor or a slip,
/// which least squares would fit as data), naming the file, snapshot and sensor; the
/// calibration goes on with them, as they are the user's measurements.
pub(crate) fn warn_cold_readings(path: &Path, hall: &Hall, snaps: &[HallSnapshot]) {
    let cold = snapshots::readings_below_supply(hall, snaps);
    let Some(first) = cold.first() else {
        return;
    };
    let more = more_such(cold.len(), "readings");
    eprintln!(
        "kalibre: warning: {}: snapshot `{}`, sensor `{}` reads {} C, more than {} C below \
         the coldest running CRAC's setpoint ({} C){more}; air in the hall is never colder \
         than its supply, so it is fitted as it is but is likely a faulty sensor or a slip \
         (leave its row out to calibrate without it)",
        path.display(),
        first.snapshot,
        first.sensor,
        snapshots::number(first.reading_c),
        snapshots::BELOW_SUPPLY_MARGIN_C,
        snapshots::number(first.coldest_supply_c),
    );
}

/// Warns of snapshots whose servers' heat and CRACs' air flow give a mean return-air
/// rise outside the plausible band (a flow in l/s or cfm typed as m3/s, powers in kW
/// typed as W), naming the two files and the first such snapshot.
pub(crate) fn warn_implausible_rises<'a>(
    hall_path: &Path,
    snapshots_path: &Path,
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) {
    let slips = snapshots::implausible_rises(hall, states);
    let Some(first) = slips.first() else {
        return;
    };
    let more = more_such(slips.len(), "snapshots");
    let hint = if first.mean_rise_k > snapshots::MAX_MEAN_RISE_K {
        format!(
            "no hall runs above {} K: is a CRAC's rated_flow_m3_s in another unit (l/s, \
             cfm), or a power in W meant as something smaller?",
            snapshots::MAX_MEAN_RISE_K
        )
    } else {
        format!(
            "below {} K the servers' heat hardly reaches the sensors and their air flow \
             cannot be told: are the powers in kW where W are meant?",
            snapshots::MIN_MEAN_RISE_K
        )
    };
    eprintln!(
        "kalibre: warning: {} and {}: snapshot `{}`: the servers' {} W over the CRACs' \
         {} m3/s of air make the return air {} K warmer than the supply on average; \
         {hint}{more}",
        hall_path.display(),
        snapshots_path.display(),
        first.snapshot,
        significant(first.power_w),
        significant(first.supply_m3_s),
        significant(first.mean_rise_k),
    );
}

/// Warns when a what-if (`what`) takes a snapshot's mean return-air rise past
/// [`snapshots::MAX_MEAN_RISE_K`]: the predictions and headroom are then the model's
/// arithmetic far outside any hall, not advice.
pub(crate) fn warn_what_if_beyond_halls<'a>(
    what: &str,
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) {
    let beyond: Vec<_> = snapshots::implausible_rises(hall, states)
        .into_iter()
        .filter(|r| r.mean_rise_k > snapshots::MAX_MEAN_RISE_K)
        .collect();
    if let Some(first) = beyond.first() {
        eprintln!(
            "kalibre: warning: what if {what}: snapshot `{}` would run its return air {} K \
             above its supply on average ({} snapshot(s) past {} K); no hall runs there, so \
             its predictions and headroom are far outside what the model was made for",
            first.snapshot,
            significant(first.mean_rise_k),
            beyond.len(),
            snapshots::MAX_MEAN_RISE_K
        );
    }
}

/// `v` to three significant figures, without an exponent (a flow of 0.00356 m3/s reads
/// as such, not as 0.0035550000000000004) unless it would take many digits.
fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return v.to_string();
    }
    if !(1e-4..1e6).contains(&v.abs()) {
        return format!("{v:.2e}");
    }
    let decimals = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.decimals$}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn three_significant_figures() {
        assert_eq!(super::significant(0.003555), "0.00356");
        assert_eq!(super::significant(51730.0), "51730");
        assert_eq!(super::significant(3.15), "3.15");
        assert_eq!(super::significant(12.34), "12.3");
    }
}
