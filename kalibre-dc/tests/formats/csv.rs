//! The malformed `snapshots.csv` inputs: each an edit of the valid base rows, with the
//! line (and column) and a key phrase the error must carry.

use super::{csv_rows, csv_text};

pub struct CsvCase {
    pub name: &'static str,
    pub text: String,
    pub field: String,
    pub phrase: &'static str,
}

/// A case built by editing the data rows (row `k` is on line `k + 2`).
fn csv_case(
    name: &'static str,
    field: &str,
    phrase: &'static str,
    edit: impl FnOnce(&mut Vec<String>),
) -> CsvCase {
    let mut rows = csv_rows();
    edit(&mut rows);
    CsvCase {
        name,
        text: csv_text(&rows),
        field: field.to_string(),
        phrase,
    }
}

fn replace_row(rows: &mut [String], at: usize, with: &str) {
    rows[at] = with.to_string();
}

pub fn csv_cases() -> Vec<CsvCase> {
    vec![
        CsvCase {
            name: "bad header",
            text: csv_text(&csv_rows()).replacen("value", "val", 1),
            field: "line 1".into(),
            phrase: "expected the header `snapshot,kind,id,value`, found `snapshot,kind,id,val`",
        },
        CsvCase {
            name: "header in another order",
            text: csv_text(&csv_rows()).replacen(
                "snapshot,kind,id,value",
                "kind,snapshot,id,value",
                1,
            ),
            field: "line 1".into(),
            phrase: "expected the header",
        },
        CsvCase {
            name: "line numbers count blank lines",
            text: {
                let mut rows = csv_rows();
                rows[7] = "t0,humidity,h01,40".into();
                rows.insert(1, String::new());
                rows.insert(1, String::new());
                csv_text(&rows)
            },
            field: "line 11, column kind".into(),
            phrase: "unknown kind `humidity`",
        },
        CsvCase {
            name: "empty file",
            text: String::new(),
            field: "line 1".into(),
            phrase: "empty file",
        },
        CsvCase {
            name: "header only",
            text: csv_text(&[]),
            field: "line 2".into(),
            phrase: "no data rows",
        },
        csv_case(
            "text after a closing quote",
            "line 4, column value",
            "text follows a closing `\"`",
            |r| replace_row(r, 2, "t0,power_w,R1-01,\"3\"10"),
        ),
        csv_case(
            "negative power",
            "line 4, column value",
            "power_w of `R1-01` is -5; expected a power in [0, 1e7] W",
            |r| replace_row(r, 2, "t0,power_w,R1-01,-5"),
        ),
        csv_case(
            "negative rack power",
            "line 6, column value",
            "in [0, 1e7] W",
            |r| replace_row(r, 4, "t0,power_w,R2,-4000"),
        ),
        csv_case(
            "power beyond a hall's",
            "line 4, column value",
            "power_w of `R1-01` is 1e308",
            |r| replace_row(r, 2, "t0,power_w,R1-01,1e308"),
        ),
        csv_case(
            "setpoint below absolute zero",
            "line 2, column value",
            "setpoint_c of CRAC `crac-1` is -300 C; expected an air temperature in [-50, 150] C",
            |r| replace_row(r, 0, "t0,setpoint_c,crac-1,-300"),
        ),
        csv_case(
            "sensor reading beyond any air",
            "line 8, column value",
            "sensor_c of `c01` is 1e308 C",
            |r| replace_row(r, 6, "t0,sensor_c,c01,1e308"),
        ),
        csv_case(
            "fan speed above 1",
            "line 3, column value",
            "expected a ratio in [0, 1]",
            |r| replace_row(r, 1, "t0,fan_speed,crac-1,1.2"),
        ),
        csv_case(
            "negative fan speed",
            "line 12, column value",
            "[0, 1]",
            |r| replace_row(r, 10, "t1,fan_speed,crac-1,-0.1"),
        ),
        csv_case(
            "unknown sensor id",
            "line 9, column id",
            "unknown sensor id `c99`",
            |r| replace_row(r, 7, "t0,sensor_c,c99,30"),
        ),
        csv_case(
            "unknown power id",
            "line 5, column id",
            "unknown id `R9-01` for kind power_w",
            |r| replace_row(r, 3, "t0,power_w,R9-01,30"),
        ),
        csv_case(
            "setpoint for a sensor id",
            "line 2, column id",
            "unknown CRAC id `c01`",
            |r| replace_row(r, 0, "t0,setpoint_c,c01,18"),
        ),
        csv_case(
            "missing power for a server",
            "snapshot `t0` (first at line 2)",
            "missing power_w for server `R1-02`",
            |r| {
                r.remove(3);
            },
        ),
        csv_case(
            "missing rack power",
            "snapshot `t0` (first at line 2)",
            "missing power_w for server `R2-01`",
            |r| {
                r.remove(4);
            },
        ),
        csv_case(
            "every fan off under load",
            "snapshot `t1` (first at line 11)",
            "every CRAC's fan_speed is 0 (the servers draw 6.8 kW): no air enters the hall",
            |r| replace_row(r, 10, "t1,fan_speed,crac-1,0"),
        ),
        csv_case(
            "missing setpoint",
            "snapshot `t1` (first at line 11)",
            "missing setpoint_c for CRAC `crac-1`",
            |r| {
                r.remove(9);
            },
        ),
        csv_case(
            "missing fan speed",
            "snapshot `t0` (first at line 2)",
            "missing fan_speed for CRAC `crac-1`",
            |r| {
                r.remove(1);
            },
        ),
        csv_case(
            "empty snapshot",
            "snapshot `t1` (first at line 11)",
            "no sensor_c rows",
            |r| {
                r.truncate(16);
            },
        ),
        csv_case(
            "duplicate row",
            "line 20, column id",
            "duplicate row for snapshot `t0`, kind sensor_c, id `c01` (first at line 8)",
            |r| r.push("t0,sensor_c,c01,21.5".into()),
        ),
        csv_case(
            "duplicate setpoint",
            "line 20, column id",
            "duplicate row",
            |r| r.push("t1,setpoint_c,crac-1,19.5".into()),
        ),
        csv_case(
            "duplicate rack power",
            "line 20, column id",
            "duplicate row for snapshot `t0`, kind power_w, id `R2`",
            |r| r.push("t0,power_w,R2,4000".into()),
        ),
        csv_case(
            "server powered directly and through its rack",
            "line 20, column id",
            "server `R2-01` gets power both directly (line 20) and through its rack `R2` (line 6)",
            |r| r.push("t0,power_w,R2-01,100".into()),
        ),
        csv_case(
            "rack powered after its server",
            "line 20, column id",
            "server `R2-01` gets power both directly (line 15) and through its rack `R2` (line 20)",
            |r| r.push("t1,power_w,R2,100".into()),
        ),
        csv_case(
            "non-numeric value",
            "line 8, column value",
            "expected a finite decimal number for sensor_c `c01`, found `warm`",
            |r| replace_row(r, 6, "t0,sensor_c,c01,warm"),
        ),
        csv_case(
            "NaN value",
            "line 8, column value",
            "finite decimal number",
            |r| replace_row(r, 6, "t0,sensor_c,c01,NaN"),
        ),
        csv_case(
            "infinite value",
            "line 2, column value",
            "finite decimal number",
            |r| replace_row(r, 0, "t0,setpoint_c,crac-1,inf"),
        ),
        csv_case(
            "overflowing value",
            "line 4, column value",
            "finite decimal number",
            |r| replace_row(r, 2, "t0,power_w,R1-01,1e400"),
        ),
        csv_case("empty value", "line 9, column value", "found ``", |r| {
            replace_row(r, 7, "t0,sensor_c,h01,")
        }),
        csv_case(
            "unknown kind",
            "line 9, column kind",
            "unknown kind `humidity`",
            |r| replace_row(r, 7, "t0,humidity,h01,40"),
        ),
        csv_case("missing column", "line 9", "expected 4 fields", |r| {
            replace_row(r, 7, "t0,sensor_c,h01")
        }),
        csv_case("extra column", "line 9", "found 5", |r| {
            replace_row(r, 7, "t0,sensor_c,h01,30,1")
        }),
        csv_case(
            "empty label",
            "line 9, column snapshot",
            "non-empty snapshot label",
            |r| replace_row(r, 7, ",sensor_c,h01,30"),
        ),
        csv_case(
            "a label with an escape sequence",
            "line 9, column snapshot",
            "snapshot label holds a control character (U+001B)",
            |r| replace_row(r, 7, "t\u{1b}[31m0,sensor_c,h01,30"),
        ),
        csv_case(
            "a decimal comma splits a value",
            "line 9",
            "found 5: a decimal comma? `30,5` reads as two fields; write `30.5`",
            |r| replace_row(r, 7, "t0,sensor_c,h01,30,5"),
        ),
        csv_case(
            "a space after a number",
            "line 9, column value",
            "found `30.5 `; a space before or after the number: remove it",
            |r| replace_row(r, 7, "t0,sensor_c,h01,30.5 "),
        ),
        csv_case(
            "a swapped id",
            "line 9, column id",
            "unknown sensor id `c10` for kind sensor_c; expected a sensor of the hall; did \
             you mean `c01`?",
            |r| replace_row(r, 7, "t0,sensor_c,c10,30"),
        ),
        CsvCase {
            name: "an export's extra columns",
            text: csv_text(&csv_rows()).replacen(
                "snapshot,kind,id,value",
                "snapshot,kind,id,value,unit",
                1,
            ),
            field: "line 1".into(),
            phrase: "; remove the other columns (kalibre reads exactly these four, in this order)",
        },
    ]
}
