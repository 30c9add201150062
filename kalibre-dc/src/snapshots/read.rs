//! Reading `snapshots.csv` (`formats.md` section 2) against a hall.
//!
//! Every row is checked as it is read (header, kind, id, value, duplicates); completeness
//! (one setpoint and fan speed per CRAC, one power per server, at least one sensor) is
//! checked per snapshot at the end. Errors name the line and column.

use std::collections::HashMap;
use std::path::Path;

use super::lexical::{next_record, parse_decimal, show, LineCounter};
use super::{air_c_problem, hints, number, HallSnapshot, OperatingState, MAX_POWER_W};
use crate::hall::Hall;
use crate::{Error, Result};

const HEADER: [&str; 4] = ["snapshot", "kind", "id", "value"];
const COLUMNS: [&str; 4] = HEADER;
const KINDS: &str = "setpoint_c, fan_speed, power_w, sensor_c";

/// Parses `snapshots.csv` text against `hall`; `file` names the source in errors.
/// Snapshots come in order of first appearance.
pub fn parse_snapshots(hall: &Hall, text: &str, file: &str) -> Result<Vec<HallSnapshot>> {
    parse_snapshots_bytes(hall, text.as_bytes(), file)
}

/// Reads and checks a `snapshots.csv` file against `hall`.
pub fn load_snapshots(hall: &Hall, path: &Path) -> Result<Vec<HallSnapshot>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_snapshots_bytes(hall, &bytes, &path.display().to_string())
}

/// Like [`load_snapshots`] for operating states to predict: a snapshot needs no reading.
pub fn load_states(hall: &Hall, path: &Path) -> Result<Vec<HallSnapshot>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse(hall, &bytes, &path.display().to_string(), false)
}

/// Like [`parse_snapshots`] for raw bytes; a field that is not UTF-8 is an error naming
/// its line and column.
pub fn parse_snapshots_bytes(hall: &Hall, bytes: &[u8], file: &str) -> Result<Vec<HallSnapshot>> {
    parse(hall, bytes, file, true)
}

fn parse(hall: &Hall, bytes: &[u8], file: &str, need_readings: bool) -> Result<Vec<HallSnapshot>> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(bytes);
    let index = HallIndex::new(hall);
    let mut record = csv::ByteRecord::new();
    let mut header_seen = false;
    let mut order: Vec<Acc> = Vec::new();
    let mut by_label: HashMap<String, usize> = HashMap::new();
    let mut lines = LineCounter::default();
    while let Some(line) = next_record(&mut reader, &mut record, &mut lines, bytes, file)? {
        let row = Row::new(file, line, &record)?;
        // Only a quote lets a field hold a line end: one opened and never closed reads the
        // lines after it into this field, which no count of fields would explain.
        if let Some(c) = row.fields.iter().position(|f| f.contains(['\n', '\r'])) {
            return Err(row.err(
                Some(c.min(COLUMNS.len() - 1)),
                "a quoted value runs on past its line: is a closing `\"` missing?",
            ));
        }
        let start = record.position().map_or(0, csv::Position::byte);
        if let Some(c) = super::lexical::text_after_closing_quote(bytes, start) {
            return Err(row.err(
                Some(c.min(COLUMNS.len() - 1)),
                super::lexical::TEXT_AFTER_QUOTE,
            ));
        }
        if !header_seen {
            if row.fields != HEADER {
                return Err(Error::format(
                    file,
                    format!("line {line}"),
                    format!(
                        "expected the header `snapshot,kind,id,value`, found `{}`{}",
                        show(&row.fields.join(",")),
                        hints::header(&row.fields)
                    ),
                ));
            }
            header_seen = true;
            continue;
        }
        if row.fields.len() != 4 {
            return Err(row.err(
                None,
                format!(
                    "expected 4 fields (snapshot,kind,id,value), found {}{}",
                    row.fields.len(),
                    hints::field_count(&row.fields)
                ),
            ));
        }
        let label = row.fields[0];
        if label.is_empty() {
            return Err(row.err(Some(0), "expected a non-empty snapshot label"));
        }
        if let Some(why) = crate::hall::unprintable_name(label) {
            return Err(row.err(Some(0), format!("snapshot label {why}")));
        }
        // An export's padding would make `night ` another snapshot than `night`, whose
        // rows would then each look incomplete.
        if label.trim() != label {
            return Err(row.err(
                Some(0),
                format!(
                    "snapshot label `{}` starts or ends with a space; labels are taken as \
                     written, so it would be another snapshot than `{}`",
                    show(label),
                    show(label.trim())
                ),
            ));
        }
        let slot = match by_label.get(label) {
            Some(&k) => k,
            None => {
                by_label.insert(label.to_string(), order.len());
                order.push(Acc::new(label, line, hall));
                order.len() - 1
            }
        };
        order[slot].add(&row, hall, &index)?;
    }
    if !header_seen {
        return Err(Error::format(
            file,
            "line 1",
            "empty file; expected the header `snapshot,kind,id,value` and at least one row",
        ));
    }
    if order.is_empty() {
        return Err(Error::format(
            file,
            "line 2",
            "no data rows after the header; expected at least one snapshot",
        ));
    }
    order
        .into_iter()
        .map(|acc| acc.finish(file, hall, need_readings))
        .collect()
}

/// Id lookups of the hall.
struct HallIndex<'h> {
    cracs: HashMap<&'h str, usize>,
    servers: HashMap<&'h str, usize>,
    racks: HashMap<&'h str, usize>,
    sensors: HashMap<&'h str, usize>,
    /// Global index of each rack's first server.
    rack_first_server: Vec<usize>,
}

impl<'h> HallIndex<'h> {
    fn new(hall: &'h Hall) -> Self {
        let mut rack_first_server = Vec::with_capacity(hall.racks.len());
        let mut n = 0;
        for r in &hall.racks {
            rack_first_server.push(n);
            n += r.servers.len();
        }
        HallIndex {
            cracs: ids(hall.cracs.iter().map(|c| c.id.as_str())),
            servers: ids(hall.servers().map(|s| s.server.id.as_str())),
            racks: ids(hall.racks.iter().map(|r| r.id.as_str())),
            sensors: ids(hall.sensors.iter().map(|s| s.id.as_str())),
            rack_first_server,
        }
    }
}

/// First index of each id (a validated hall has unique ids).
fn ids<'h>(it: impl Iterator<Item = &'h str>) -> HashMap<&'h str, usize> {
    let mut m = HashMap::new();
    for (i, id) in it.enumerate() {
        m.entry(id).or_insert(i);
    }
    m
}

/// One CSV record as text, with its line.
struct Row<'a> {
    file: &'a str,
    line: u64,
    fields: Vec<&'a str>,
}

impl<'a> Row<'a> {
    fn new(file: &'a str, line: u64, record: &'a csv::ByteRecord) -> Result<Self> {
        let mut fields = Vec::with_capacity(record.len());
        for (k, f) in record.iter().enumerate() {
            let text = std::str::from_utf8(f).map_err(|_| {
                let column = COLUMNS
                    .get(k)
                    .map_or_else(|| format!("{}", k + 1), |c| c.to_string());
                Error::format(
                    file,
                    format!("line {line}, column {column}"),
                    "expected UTF-8 text",
                )
            })?;
            fields.push(text);
        }
        Ok(Row { file, line, fields })
    }

    /// An error at this row, in `column` (index into the header) or the whole line.
    fn err(&self, column: Option<usize>, message: impl Into<String>) -> Error {
        let field = match column {
            Some(c) => format!("line {}, column {}", self.line, COLUMNS[c]),
            None => format!("line {}", self.line),
        };
        Error::format(self.file, field, message)
    }

    /// The value column as a finite decimal number.
    fn value(&self) -> Result<f64> {
        let text = self.fields[3];
        parse_decimal(text).ok_or_else(|| {
            self.err(
                Some(3),
                format!(
                    "expected a finite decimal number for {} `{}`, found `{}`{}",
                    self.fields[1],
                    show(self.fields[2]),
                    show(text),
                    hints::value(text, |t| parse_decimal(t).is_some())
                ),
            )
        })
    }
}

/// Where a power reading came from: a line, and the rack if it was a rack reading.
#[derive(Clone, Copy)]
struct PowerSource {
    line: u64,
    rack: Option<usize>,
}

/// The rows of one snapshot seen so far, each value with the line that gave it.
struct Acc {
    label: String,
    first_line: u64,
    setpoint_c: Vec<Option<(f64, u64)>>,
    fan_speed: Vec<Option<(f64, u64)>>,
    power_w: Vec<Option<(f64, PowerSource)>>,
    rack_line: Vec<Option<u64>>,
    sensor_c: Vec<Option<(f64, u64)>>,
}

impl Acc {
    fn new(label: &str, first_line: u64, hall: &Hall) -> Self {
        Acc {
            label: label.to_string(),
            first_line,
            setpoint_c: vec![None; hall.cracs.len()],
            fan_speed: vec![None; hall.cracs.len()],
            power_w: vec![None; hall.server_count()],
            rack_line: vec![None; hall.racks.len()],
            sensor_c: vec![None; hall.sensors.len()],
        }
    }

    fn add(&mut self, row: &Row, hall: &Hall, index: &HallIndex) -> Result<()> {
        let (kind, id) = (row.fields[1], row.fields[2]);
        match kind {
            "setpoint_c" | "fan_speed" => {
                let Some(&c) = index.cracs.get(id) else {
                    return Err(row.err(
                        Some(2),
                        format!(
                            "unknown CRAC id `{}` for kind {kind}; expected a CRAC of the hall{}",
                            show(id),
                            hints::nearest_id(id, index.cracs.keys().copied())
                        ),
                    ));
                };
                let v = row.value()?;
                if kind == "setpoint_c" {
                    if let Some(m) = air_c_problem(&format!("setpoint_c of CRAC `{id}`"), v) {
                        return Err(row.err(Some(3), m));
                    }
                }
                if kind == "fan_speed" && !(0.0..=1.0).contains(&v) {
                    return Err(row.err(
                        Some(3),
                        format!(
                            "fan_speed of CRAC `{id}` is {}; expected a ratio in [0, 1]",
                            number(v)
                        ),
                    ));
                }
                let slot = if kind == "setpoint_c" {
                    &mut self.setpoint_c[c]
                } else {
                    &mut self.fan_speed[c]
                };
                if let Some((_, first)) = *slot {
                    return Err(duplicate(row, &self.label, first));
                }
                *slot = Some((v, row.line));
            }
            "sensor_c" => {
                let Some(&k) = index.sensors.get(id) else {
                    return Err(row.err(
                        Some(2),
                        format!(
                            "unknown sensor id `{}` for kind sensor_c; expected a sensor of the \
                             hall{}",
                            show(id),
                            hints::nearest_id(id, index.sensors.keys().copied())
                        ),
                    ));
                };
                let v = row.value()?;
                if let Some(m) = air_c_problem(&format!("sensor_c of `{id}`"), v) {
                    return Err(row.err(Some(3), m));
                }
                if let Some((_, first)) = self.sensor_c[k] {
                    return Err(duplicate(row, &self.label, first));
                }
                self.sensor_c[k] = Some((v, row.line));
            }
            "power_w" => {
                let server = index.servers.get(id).copied();
                let rack = index.racks.get(id).copied();
                let v = row.value()?;
                if !(0.0..=MAX_POWER_W).contains(&v) {
                    return Err(row.err(
                        Some(3),
                        format!(
                            "power_w of `{}` is {}; expected a power in [0, {MAX_POWER_W:e}] W",
                            show(id),
                            number(v)
                        ),
                    ));
                }
                match (server, rack) {
                    (Some(_), Some(_)) => {
                        return Err(row.err(
                            Some(2),
                            format!("id `{}` names both a server and a rack; expected an unambiguous id for power_w", show(id)),
                        ))
                    }
                    (Some(s), None) => self.add_server_power(row, hall, s, v)?,
                    (None, Some(r)) => self.add_rack_power(row, hall, index, r, v)?,
                    (None, None) => {
                        return Err(row.err(
                            Some(2),
                            format!(
                                "unknown id `{}` for kind power_w; expected a server or rack of \
                                 the hall{}",
                                show(id),
                                hints::nearest_id(
                                    id,
                                    index.servers.keys().chain(index.racks.keys()).copied()
                                )
                            ),
                        ))
                    }
                }
            }
            other => {
                return Err(row.err(
                    Some(1),
                    format!("unknown kind `{}`; expected one of {KINDS}", show(other)),
                ))
            }
        }
        Ok(())
    }

    fn add_server_power(&mut self, row: &Row, hall: &Hall, s: usize, v: f64) -> Result<()> {
        let id = row.fields[2];
        match self.power_w[s] {
            Some((_, PowerSource { line, rack: None })) => Err(duplicate(row, &self.label, line)),
            Some((_, PowerSource { line, rack: Some(r) })) => Err(row.err(
                Some(2),
                format!(
                    "server `{id}` gets power both directly (line {}) and through its rack `{}` (line {line}); expected exactly one power per server",
                    row.line, hall.racks[r].id
                ),
            )),
            None => {
                self.power_w[s] = Some((v, PowerSource { line: row.line, rack: None }));
                Ok(())
            }
        }
    }

    fn add_rack_power(
        &mut self,
        row: &Row,
        hall: &Hall,
        index: &HallIndex,
        r: usize,
        v: f64,
    ) -> Result<()> {
        if let Some(first) = self.rack_line[r] {
            return Err(duplicate(row, &self.label, first));
        }
        let rack = &hall.racks[r];
        let first_server = index.rack_first_server[r];
        let total_u: f64 = rack.servers.iter().map(|s| f64::from(s.height_u)).sum();
        if rack.servers.is_empty() || total_u <= 0.0 {
            if v > 0.0 {
                return Err(row.err(
                    Some(3),
                    format!(
                        "rack `{}` has no servers to share power_w {v}; expected 0",
                        rack.id
                    ),
                ));
            }
            self.rack_line[r] = Some(row.line);
            return Ok(());
        }
        for (j, s) in rack.servers.iter().enumerate() {
            if let Some((_, src)) = self.power_w[first_server + j] {
                return Err(row.err(
                    Some(2),
                    format!(
                        "server `{}` gets power both directly (line {}) and through its rack `{}` (line {}); expected exactly one power per server",
                        s.id, src.line, rack.id, row.line
                    ),
                ));
            }
        }
        for (j, s) in rack.servers.iter().enumerate() {
            let share = v * f64::from(s.height_u) / total_u;
            self.power_w[first_server + j] = Some((
                share,
                PowerSource {
                    line: row.line,
                    rack: Some(r),
                },
            ));
        }
        self.rack_line[r] = Some(row.line);
        Ok(())
    }

    fn finish(self, file: &str, hall: &Hall, need_readings: bool) -> Result<HallSnapshot> {
        let field = format!(
            "snapshot `{}` (first at line {})",
            show(&self.label),
            self.first_line
        );
        let missing = |kind: &str, what: &str, id: &str, hint: &str| {
            Error::format(
                file,
                field.clone(),
                format!("missing {kind} for {what} `{id}`; expected {hint}"),
            )
        };
        let mut setpoint_c = Vec::with_capacity(self.setpoint_c.len());
        for (v, crac) in self.setpoint_c.iter().zip(&hall.cracs) {
            let (v, _) = v.ok_or_else(|| {
                missing("setpoint_c", "CRAC", &crac.id, "one per CRAC per snapshot")
            })?;
            setpoint_c.push(v);
        }
        let mut fan_speed = Vec::with_capacity(self.fan_speed.len());
        for (v, crac) in self.fan_speed.iter().zip(&hall.cracs) {
            let (v, _) = v.ok_or_else(|| {
                missing("fan_speed", "CRAC", &crac.id, "one per CRAC per snapshot")
            })?;
            fan_speed.push(v);
        }
        let mut power_w = Vec::with_capacity(self.power_w.len());
        for (v, s) in self.power_w.iter().zip(hall.servers()) {
            let hint = format!(
                "exactly one power per server per snapshot, given directly or through its rack `{}`",
                s.rack.id
            );
            let (v, _) = v.ok_or_else(|| missing("power_w", "server", &s.server.id, &hint))?;
            power_w.push(v);
        }
        if fan_speed.iter().all(|&f| f == 0.0) {
            // Found here, not as a failed run at every design point (an OpenFOAM solve
            // each). Without power too, still no air moves: nothing sets the temperatures.
            let power_total_w: f64 = power_w.iter().sum();
            return Err(Error::format(
                file,
                field,
                format!(
                    "every CRAC's fan_speed is 0 (the servers draw {} kW): no air enters the \
                     hall, so no model of it has a steady state; expected at least one fan \
                     running",
                    super::number(power_total_w.round() / 1000.0)
                ),
            ));
        }
        if need_readings && self.sensor_c.iter().all(Option::is_none) {
            return Err(Error::format(
                file,
                field,
                "snapshot has no sensor_c rows; expected at least one sensor reading",
            ));
        }
        Ok(HallSnapshot {
            state: OperatingState {
                label: self.label,
                setpoint_c,
                fan_speed,
                power_w,
            },
            sensor_c: self.sensor_c.iter().map(|v| v.map(|(v, _)| v)).collect(),
        })
    }
}

/// A repeated `(snapshot, kind, id)`.
fn duplicate(row: &Row, label: &str, first: u64) -> Error {
    row.err(
        Some(2),
        format!(
            "duplicate row for snapshot `{}`, kind {}, id `{}` (first at line {first})",
            show(label),
            row.fields[1],
            show(row.fields[2])
        ),
    )
}
