//! Warnings about inputs that read well but no hall produces: a reading colder than the
//! supply, a unit slip in a CRAC's air flow or in the servers' powers. They warn rather
//! than refuse, as the user may mean it (a test rig, an idle hall), and name the file and
//! snapshot to look at. Only a rise no model run could give is refused.

use std::path::Path;

use kalibre_dc::hall::Hall;
use kalibre_dc::snapshots::{self, HallSnapshot, OperatingState};

use super::CliError;

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
fn warn_cold_readings(path: &Path, hall: &Hall, snaps: &[HallSnapshot]) {
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

/// The reading `f` in degrees Fahrenheit, as Celsius.
fn fahrenheit_as_c(f: f64) -> String {
    snapshots::number(((f - 32.0) / 1.8 * 10.0).round() / 10.0)
}

/// How many distinct names `names` holds, and them quoted for a message, in order
/// ([`kalibre_core::some_names`]: the first few of a long list and its count).
fn distinct(names: impl IntoIterator<Item = String>) -> (usize, String) {
    let mut seen: Vec<String> = Vec::new();
    for n in names {
        let quoted = format!("`{n}`");
        if !seen.contains(&quoted) {
            seen.push(quoted);
        }
    }
    (seen.len(), kalibre_core::some_names(&seen))
}

/// The warnings about a snapshot file's readings that `calibrate` and `diagnose` give
/// alike: colder than the supply, far warmer than any hall's air, stuck.
pub(crate) fn warn_readings(path: &Path, hall: &Hall, snaps: &[HallSnapshot]) {
    warn_cold_readings(path, hall, snaps);
    warn_hot_readings(path, hall, snaps);
    warn_stuck_sensors(path, hall, snaps);
}

/// Warns of readings far warmer than any hall's air (more than
/// [`snapshots::ABOVE_SUPPLY_MARGIN_C`] above the warmest running setpoint), as readings
/// in degrees Fahrenheit are, naming the file, the first and the sensors; fitted as they
/// are, they would set the alphas (a sensor in Fahrenheit pinned one at its bound).
fn warn_hot_readings(path: &Path, hall: &Hall, snaps: &[HallSnapshot]) {
    let hot = snapshots::readings_above_supply(hall, snaps);
    let Some(first) = hot.first() else {
        return;
    };
    let (sensors, named) = distinct(hot.iter().map(|h| h.sensor.clone()));
    let sensors = if sensors == 1 {
        format!("sensor {named}")
    } else {
        format!("{sensors} sensors ({named})")
    };
    eprintln!(
        "kalibre: warning: {}: {} reading(s) of {sensors} lie more than {} C (hot aisle: \
         {} C) above the warmest running CRAC's setpoint, which no hall's air does; the \
         first, snapshot `{}` sensor `{}`, reads {} C ({} C above {} C). Read as Fahrenheit \
         it is {} C: are these readings in F? They are fitted as they are: convert them, or \
         leave their rows out",
        path.display(),
        hot.len(),
        snapshots::ABOVE_SUPPLY_MARGIN_C,
        snapshots::HOT_AISLE_ABOVE_SUPPLY_MARGIN_C,
        first.snapshot,
        first.sensor,
        snapshots::number(first.reading_c),
        snapshots::number(((first.reading_c - first.warmest_supply_c) * 10.0).round() / 10.0),
        snapshots::number(first.warmest_supply_c),
        fahrenheit_as_c(first.reading_c),
    );
}

/// Warns of sensors that read the same in every snapshot while the conditions change
/// (stuck, or a default an export filled in), naming the file and the sensors.
fn warn_stuck_sensors(path: &Path, hall: &Hall, snaps: &[HallSnapshot]) {
    let stuck = snapshots::stuck_sensors(hall, snaps);
    let Some(first) = stuck.first() else {
        return;
    };
    let (n, named) = distinct(stuck.iter().map(|s| s.sensor.clone()));
    let which = if n == 1 {
        format!(
            "sensor {named} reads {} C in each of its {} readings",
            snapshots::number(first.reading_c),
            first.snapshots
        )
    } else {
        format!(
            "{n} sensors ({named}) each read one value in every snapshot (`{}`: {} C in each \
             of its {} readings)",
            first.sensor,
            snapshots::number(first.reading_c),
            first.snapshots
        )
    };
    eprintln!(
        "kalibre: warning: {}: {which} while the setpoints, fans or powers change, and a \
         real sensor's noise alone would make its readings differ: stuck, or a value the \
         export filled in? It is fitted as it is: leave its rows out if it is stuck",
        path.display(),
    );
}

/// Notes the sensors missing from some snapshots (dead, or left out by the export): the
/// calibration fits the readings there are, which a user should know rather than find.
/// Sensors missing from every snapshot are named too: nothing calibrates against them.
pub(crate) fn note_missing_readings(path: &Path, hall: &Hall, snaps: &[HallSnapshot]) {
    let missing: Vec<(String, usize)> = hall
        .sensors
        .iter()
        .enumerate()
        .map(|(k, sensor)| {
            let absent = snaps
                .iter()
                .filter(|s| s.sensor_c.get(k).copied().flatten().is_none())
                .count();
            (sensor.id.clone(), absent)
        })
        .filter(|(_, absent)| *absent > 0)
        .collect();
    if missing.is_empty() {
        return;
    }
    let readings: usize = missing.iter().map(|(_, n)| n).sum();
    let listed: Vec<String> = missing
        .iter()
        .map(|(id, n)| format!("`{id}` in {n} of {} snapshots", snaps.len()))
        .collect();
    eprintln!(
        "note: {}: {readings} sensor reading(s) are missing ({}); the calibration fits the \
         readings there are",
        path.display(),
        kalibre_core::some_names(&listed)
    );
}

/// Warns of CRAC setpoints above [`snapshots::MAX_SETPOINT_C`], as setpoints in degrees
/// Fahrenheit are, naming the file, the first and the CRACs.
pub(crate) fn warn_setpoints<'a>(
    path: &Path,
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) {
    let found = snapshots::implausible_setpoints(hall, states);
    let Some(first) = found.first() else {
        return;
    };
    let (_, cracs) = distinct(found.iter().map(|f| f.crac.clone()));
    eprintln!(
        "kalibre: warning: {}: {} setpoint(s) above {} C (CRAC {cracs}); no data hall \
         supplies air that warm (ASHRAE's warmest class allows {} C at the intake). The \
         first, snapshot `{}` CRAC `{}`, is {} C; read as Fahrenheit it is {} C: are the \
         setpoints (and readings) in F? kalibre takes C",
        path.display(),
        found.len(),
        snapshots::MAX_SETPOINT_C,
        snapshots::MAX_SETPOINT_C,
        first.snapshot,
        first.crac,
        snapshots::number(first.setpoint_c),
        fahrenheit_as_c(first.setpoint_c),
    );
}

/// Warns of snapshots whose servers' heat and CRACs' air flow give a mean return-air
/// rise outside the plausible band (a flow in l/s or cfm typed as m3/s, powers in kW
/// typed as W), naming the two files and the first such snapshot. Refuses them when
/// the rise is past [`kalibre_dc::PLAUSIBLE_SENSOR_C`]: every model run would then be
/// refused as implausible, so the refusal comes first and names the inputs.
pub(crate) fn warn_implausible_rises<'a>(
    hall_path: &Path,
    snapshots_path: &Path,
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) -> Result<(), CliError> {
    let slips = snapshots::implausible_rises(hall, states);
    let Some(first) = slips.first() else {
        return Ok(());
    };
    if let Some(beyond) = slips.iter().find(|r| r.mean_rise_k > IMPOSSIBLE_RISE_K) {
        return Err(CliError::Input(format!(
            "{} and {}: snapshot `{}`: the servers' {} W over the CRACs' {} m3/s of air \
             (rated_flow_m3_s x fan_speed) would make the return air {} K warmer than the \
             supply on average, past any temperature a model of the hall can give ({} C); \
             expected a running fan_speed, a rated_flow_m3_s in m3/s and powers in W",
            hall_path.display(),
            snapshots_path.display(),
            beyond.snapshot,
            significant(beyond.power_w),
            significant(beyond.supply_m3_s),
            significant(beyond.mean_rise_k),
            IMPOSSIBLE_RISE_K,
        )));
    }
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
    Ok(())
}

/// The mean return-air rise (K) no model run can give: the top of
/// [`kalibre_dc::PLAUSIBLE_SENSOR_C`], which every hall model's outputs are checked
/// against.
const IMPOSSIBLE_RISE_K: f64 = *kalibre_dc::PLAUSIBLE_SENSOR_C.end();

/// Warns when a what-if (`what`) takes a snapshot's mean return-air rise past
/// [`snapshots::MAX_MEAN_RISE_K`]: the predictions and headroom are then the model's
/// arithmetic far outside any hall, not advice.
pub(crate) fn warn_what_if_beyond_halls<'a>(
    what: &str,
    hall: &Hall,
    states: impl IntoIterator<Item = &'a OperatingState>,
) -> Result<(), CliError> {
    let beyond: Vec<_> = snapshots::implausible_rises(hall, states)
        .into_iter()
        .filter(|r| r.mean_rise_k > snapshots::MAX_MEAN_RISE_K)
        .collect();
    if let Some(past) = beyond.iter().find(|r| r.mean_rise_k > IMPOSSIBLE_RISE_K) {
        return Err(CliError::Input(format!(
            "what if {what}: snapshot `{}` would run its return air {} K above its supply \
             on average, past any temperature a model of the hall can give ({} C); expected \
             a what-if that leaves the hall's air below that",
            past.snapshot,
            significant(past.mean_rise_k),
            IMPOSSIBLE_RISE_K,
        )));
    }
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
    Ok(())
}

/// `v` to three significant figures ([`super::significant`]).
fn significant(v: f64) -> String {
    super::significant(v, 3)
}

/// What the built-in simulator on a grid of `cell_m` should say of the hall at
/// `hall_path` before it runs: the cells it solves on, equipment its grid moves
/// ([`warn_off_grid`]) and front supply it reads far off ([`warn_front_supply`]).
pub(crate) fn warn_builtin_hall(hall_path: &Path, hall: &Hall, cell_m: f64) {
    warn_off_grid(hall_path, hall, cell_m);
    warn_front_supply(hall_path, hall);
}

/// Says what cells the built-in simulator takes when `cell_m` does not divide a side of
/// the room: it puts a whole number of cells on each side (`round(side / cell_m)`), so
/// the cells it solves on differ from the size asked for, and the messages about the
/// grid speak of those.
fn note_cells_per_side(hall_path: &Path, hall: &Hall, cell_m: f64) {
    let grid = kalibre_dc::sim::Grid::new(hall.room.size_m, cell_m);
    if grid.d.iter().all(|d| (d - cell_m).abs() <= 0.01 * cell_m) {
        return;
    }
    let n = snapshots::number;
    let rounded = |x: f64| n((x * 1e4).round() / 1e4);
    let join = |v: [f64; 3]| v.map(rounded).join(" x ");
    eprintln!(
        "kalibre: note: {}: cells of {} m do not divide the room ({} m): the built-in \
         simulator puts a whole number of cells on each side, {} cells of {} m",
        hall_path.display(),
        rounded(cell_m),
        join(hall.room.size_m),
        grid.n.map(|k| k.to_string()).join(" x "),
        join(grid.d)
    );
}

/// Warns when the built-in simulator's grid of `cell_m` moves equipment of the hall at
/// `hall_path` (racks, CRACs, tiles, containment) to its cell faces: a rack a quarter
/// cell off moves the air of its aisle, and the readings by tenths of a degree, without a
/// word otherwise. Names the first such edge, how far the farthest moves, and a finer
/// grid that places them all when one of up to 8 times finer does.
fn warn_off_grid(hall_path: &Path, hall: &Hall, cell_m: f64) {
    // Cells wider than the equipment cannot hold it: where the simulator does not refuse
    // the hall, it solves a blur of it, and edge by edge placement is beside the point.
    let across = (hall.racks.iter().enumerate())
        .map(|(i, r)| (format!("/racks/{i}/size_m"), [r.size_m[0], r.size_m[1]]))
        .chain(
            (hall.cracs.iter().enumerate())
                .map(|(i, c)| (format!("/cracs/{i}/size_m"), [c.size_m[0], c.size_m[1]])),
        )
        .chain(
            (hall.tiles.iter().enumerate()).map(|(i, t)| (format!("/tiles/{i}/size_m"), t.size_m)),
        )
        .flat_map(|(at, size)| [(at.clone(), 0, size[0]), (at, 1, size[1])]);
    let thinnest = across.min_by(|a, b| a.2.total_cmp(&b.2));
    if let Some((at, axis, smallest_m)) = thinnest.filter(|t| t.2 < cell_m) {
        // A hall the simulator refuses on these cells gets its refusal, not this too;
        // built on cells this coarse, it costs next to nothing.
        let config = kalibre_dc::sim::SimConfig {
            cell_m,
            ..Default::default()
        };
        if kalibre_dc::sim::Simulator::new(hall, config).is_err() {
            return;
        }
        let n = snapshots::number;
        eprintln!(
            "kalibre: warning: {}: {at} is {} m across in {}, less than the built-in \
             simulator's cells of {} m: cells that wide cannot hold the racks, CRACs and \
             tiles, and what it solves is a blur of the hall; use cells of at most a third \
             of that (--grid-m {})",
            hall_path.display(),
            n(smallest_m),
            ["x", "y"][axis],
            n(cell_m),
            // In whole 5 cm, so that it prints as one: 3 * 0.05 is 0.15000000000000002.
            n(((smallest_m / 3.0) / 0.05).floor().max(1.0) * 5.0 / 100.0),
        );
        return;
    }
    note_cells_per_side(hall_path, hall, cell_m);
    let moved = kalibre_dc::sim::off_grid_edges(hall, cell_m);
    let Some(first) = moved.first() else {
        return;
    };
    let farthest_m = moved
        .iter()
        .map(|e| (e.given_m - e.placed_m).abs())
        .fold(0.0, f64::max);
    let n = snapshots::number;
    let rounded = |x: f64| n((x * 1e6).round() / 1e6);
    let cure = match kalibre_dc::sim::grid_placing_all(hall, cell_m) {
        Some(c) => format!("--grid-m {} places them as written", rounded(c)),
        None => "a --grid-m that divides their positions places them as written".into(),
    };
    eprintln!(
        "kalibre: warning: {}: {} edge{} of racks, CRACs, tiles or containment {} between \
         the built-in simulator's cells of {} m and {} moved to the nearest cell face, by \
         up to {} m (the first: {}, {} = {} m taken as {} m); {cure}",
        hall_path.display(),
        moved.len(),
        if moved.len() == 1 { "" } else { "s" },
        if moved.len() == 1 { "lies" } else { "lie" },
        rounded(cell_m),
        if moved.len() == 1 { "is" } else { "are" },
        rounded(farthest_m),
        first.pointer,
        ["x", "y", "z"][first.axis],
        rounded(first.given_m),
        rounded(first.placed_m),
    );
}

/// Warns that the built-in simulator reads a hall with `front` CRACs and no ceiling
/// grilles far off: its air has no momentum or buoyancy, so even released along the jet
/// ([`kalibre_dc::sim`]'s front supply) much of it finds its way back into the CRAC tops
/// before the servers draw it. The figures are the ones measured against OpenFOAM
/// (docs/models.md, "Front-supply CRACs and halls without grilles"), which solves such
/// halls; with grilles the built-in model read them as near as floor supply.
fn warn_front_supply(hall_path: &Path, hall: &Hall) {
    if !hall.returns.is_empty() {
        return;
    }
    let fronts: Vec<usize> = (hall.cracs.iter().enumerate())
        .filter(|(_, c)| c.supply == kalibre_dc::hall::SupplyKind::Front)
        .map(|(i, _)| i)
        .collect();
    let Some(&first) = fronts.first() else {
        return;
    };
    let more = match fronts.len() {
        1 => String::new(),
        n => format!(" (and {} more CRACs)", n - 1),
    };
    eprintln!(
        "kalibre: warning: {}: /cracs/{first} (`{}`) supplies through its front{more} and the \
         hall has no ceiling `returns`, so its air returns into the CRAC tops; the built-in \
         simulator's air has no momentum or buoyancy, and on such halls it read 2.5-11.3 C \
         off OpenFOAM (1.1-3.4 C with grilles; docs/models.md, \"Front-supply CRACs and \
         halls without grilles\"); `--model openfoam` solves this hall",
        hall_path.display(),
        hall.cracs[first].id,
    );
}

/// A server's air warms by `1 / (1206 J/(m3 K) x alpha x 4.71947e-4 m3/s per cfm)` K, so
/// the initial alpha of each server type says what rise the hall starts from. Outside
/// these, alpha is in another unit: m3/s per W (2,119 times smaller) gives thousands of
/// kelvin, and no server moves air enough for less than half a kelvin.
const ALPHA_RISE_K: std::ops::RangeInclusive<f64> = 0.5..=100.0;

/// Warns of a server type whose initial `alpha_cfm_per_w` gives a temperature rise
/// through its servers outside [`ALPHA_RISE_K`] (a unit slip that validation, which only
/// asks `0 < min <= initial <= max`, lets through), naming the file and the field.
pub(crate) fn warn_alpha_units(hall_path: &Path, hall: &Hall) {
    // The built-in simulator's air: 1.2 kg/m3 x 1005 J/(kg K).
    const AIR_RHO_CP_J_M3_K: f64 = 1206.0;
    let rise_k = |alpha: f64| 1.0 / (AIR_RHO_CP_J_M3_K * alpha * kalibre_dc::sim::M3_S_PER_CFM);
    let Some((i, t)) = hall
        .server_types
        .iter()
        .enumerate()
        .find(|(_, t)| !ALPHA_RISE_K.contains(&rise_k(t.alpha_cfm_per_w.initial)))
    else {
        return;
    };
    let alpha = t.alpha_cfm_per_w.initial;
    eprintln!(
        "kalibre: warning: {}: /server_types/{i}/alpha_cfm_per_w/initial: {} cfm/W warms \
         the air of a `{}` server by {:.3e} K; servers warm theirs by {}-{} K (about \
         0.02-3.5 cfm/W): is it in another unit (m3/s per W is 2,119 times smaller than \
         cfm/W)?",
        hall_path.display(),
        snapshots::number(alpha),
        t.id,
        rise_k(alpha),
        ALPHA_RISE_K.start(),
        ALPHA_RISE_K.end(),
    );
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

    #[test]
    fn any_number_of_significant_figures() {
        use crate::cli::significant;
        assert_eq!(significant(0.0, 4), "0");
        assert_eq!(significant(13500.0, 4), "13500");
        assert_eq!(significant(18.5, 4), "18.50");
        assert_eq!(significant(5.0002475, 4), "5.000");
        assert_eq!(significant(3.0688e-7, 4), "3.069e-7");
        assert_eq!(significant(f64::INFINITY, 4), "inf");
    }
}
