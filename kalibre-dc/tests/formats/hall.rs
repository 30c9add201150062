//! The malformed `hall.json` inputs: each a mutation of the valid base hall, with the
//! JSON pointer and a key phrase the error must carry.

use serde_json::{json, Value};

use super::{hall_value, set};

pub struct HallCase {
    pub name: &'static str,
    pub text: String,
    pub field: String,
    pub phrase: &'static str,
}

fn hall_case(
    name: &'static str,
    field: &'static str,
    phrase: &'static str,
    mutate: impl FnOnce(&mut Value),
) -> HallCase {
    let mut v = hall_value();
    mutate(&mut v);
    HallCase {
        name,
        text: serde_json::to_string_pretty(&v).unwrap(),
        field: field.to_string(),
        phrase,
    }
}

fn hall_text_case(
    name: &'static str,
    field: &'static str,
    phrase: &'static str,
    edit: impl FnOnce(String) -> String,
) -> HallCase {
    let text = edit(serde_json::to_string_pretty(&hall_value()).unwrap());
    HallCase {
        name,
        text,
        field: field.to_string(),
        phrase,
    }
}

pub fn hall_cases() -> Vec<HallCase> {
    vec![
        hall_case(
            "unknown field",
            "/room/colour",
            "unknown field `colour`",
            |v| set(v, "/room/colour", json!("blue")),
        ),
        hall_case(
            "unknown field in a server",
            "/racks/1/servers/0/power",
            "unknown field",
            |v| set(v, "/racks/1/servers/0/power", json!(3)),
        ),
        hall_case(
            "duplicate rack id",
            "/racks/1/id",
            "duplicate id `R1` (first at /racks/0/id)",
            |v| set(v, "/racks/1/id", json!("R1")),
        ),
        hall_case(
            "an id with an escape sequence",
            "/sensors/2/id",
            "id holds a control character (U+001B)",
            |v| set(v, "/sensors/2/id", json!("h\u{1b}[31m2")),
        ),
        hall_case(
            "an id too long to print",
            "/racks/1/id",
            "id is 100000 characters long; expected at most 200",
            |v| set(v, "/racks/1/id", json!("R".repeat(100_000))),
        ),
        hall_case(
            "duplicate server id across racks",
            "/racks/2/servers/0/id",
            "duplicate id `R1-01`",
            |v| set(v, "/racks/2/servers/0/id", json!("R1-01")),
        ),
        hall_case(
            "duplicate sensor id",
            "/sensors/2/id",
            "duplicate id `h01`",
            |v| set(v, "/sensors/2/id", json!("h01")),
        ),
        hall_case(
            "duplicate server type",
            "/server_types/1/id",
            "duplicate id `1u`",
            |v| set(v, "/server_types/1/id", json!("1u")),
        ),
        hall_case(
            "server above its rack's units",
            "/racks/0/servers/1/height_u",
            "outside its rack's units",
            |v| set(v, "/racks/0/servers/1/u", json!(42)),
        ),
        hall_case(
            "server starting beyond the units",
            "/racks/0/servers/1/u",
            "expected 1..=42",
            |v| set(v, "/racks/0/servers/1/u", json!(43)),
        ),
        hall_case(
            "server at unit 0",
            "/racks/0/servers/0/u",
            "outside its rack's units",
            |v| set(v, "/racks/0/servers/0/u", json!(0)),
        ),
        hall_case(
            "negative unit",
            "/racks/0/servers/0/u",
            "integer `-1`, expected a whole number",
            |v| set(v, "/racks/0/servers/0/u", json!(-1)),
        ),
        hall_case(
            "overlapping servers",
            "/racks/1/servers/1/u",
            "overlaps server `R2-01`",
            |v| set(v, "/racks/1/servers/1/u", json!(10)),
        ),
        hall_case(
            "zero height",
            "/racks/0/servers/0/height_u",
            "height_u >= 1",
            |v| set(v, "/racks/0/servers/0/height_u", json!(0)),
        ),
        hall_case("zero units", "/racks/2/units", "units >= 1", |v| {
            set(v, "/racks/2/units", json!(0))
        }),
        hall_case(
            "overlapping racks",
            "/racks/1",
            "rack `R2` overlaps rack `R1`",
            |v| set(v, "/racks/1/position_m/0", json!(2.3)),
        ),
        hall_case(
            "rack overlapping a CRAC",
            "/racks/0",
            "overlaps CRAC `crac-1`",
            |v| set(v, "/racks/0/position_m", json!([0.5, 1.4, 0.0])),
        ),
        hall_case(
            "rack outside the room",
            "/racks/2/position_m/1",
            "outside the room",
            |v| set(v, "/racks/2/position_m/1", json!(5.5)),
        ),
        hall_case(
            "rack with zero size",
            "/racks/2/size_m/2",
            "expected a positive size",
            |v| set(v, "/racks/2/size_m/2", json!(0.0)),
        ),
        hall_case(
            "CRAC outside the room",
            "/cracs/0/position_m/0",
            "outside the room",
            |v| set(v, "/cracs/0/position_m/0", json!(-0.5)),
        ),
        hall_case(
            "sensor inside a rack",
            "/sensors/0/position_m",
            "inside rack `R1`",
            |v| set(v, "/sensors/0/position_m", json!([2.3, 2.0, 1.0])),
        ),
        hall_case(
            "sensor inside a CRAC",
            "/sensors/2/position_m",
            "inside CRAC `crac-1`",
            |v| set(v, "/sensors/2/position_m", json!([0.4, 3.0, 1.0])),
        ),
        hall_case(
            "sensor outside the room",
            "/sensors/1/position_m",
            "outside the room",
            |v| set(v, "/sensors/1/position_m/2", json!(3.5)),
        ),
        hall_case(
            "inverted alpha bounds",
            "/server_types/0/alpha_cfm_per_w",
            "inverted bounds",
            |v| {
                set(
                    v,
                    "/server_types/0/alpha_cfm_per_w",
                    json!({ "initial": 1.5, "min": 2.0, "max": 1.0 }),
                )
            },
        ),
        hall_case(
            "initial alpha outside its bounds",
            "/server_types/1/alpha_cfm_per_w/initial",
            "outside [0.01, 3]",
            |v| set(v, "/server_types/1/alpha_cfm_per_w/initial", json!(5.0)),
        ),
        hall_case(
            "alpha minimum zero",
            "/server_types/0/alpha_cfm_per_w/min",
            "0 < min",
            |v| set(v, "/server_types/0/alpha_cfm_per_w/min", json!(0.0)),
        ),
        hall_case(
            "floor supply with no tiles",
            "/cracs/0/supply",
            "has no tiles",
            |v| set(v, "/tiles", json!([])),
        ),
        hall_case(
            "tiles with no floor supply",
            "/tiles",
            "no CRAC has supply `floor` to feed them",
            |v| set(v, "/cracs/0/supply", json!("front")),
        ),
        hall_case(
            "unknown supply kind",
            "/cracs/0/supply",
            "unknown variant `ceiling`",
            |v| set(v, "/cracs/0/supply", json!("ceiling")),
        ),
        hall_case(
            "unknown server type",
            "/racks/0/servers/0/type",
            "unknown server type `3u`; expected one of: 1u, 2u",
            |v| set(v, "/racks/0/servers/0/type", json!("3u")),
        ),
        hall_case(
            "bad inlet side",
            "/racks/0/inlet",
            "unknown variant `up`",
            |v| set(v, "/racks/0/inlet", json!("up")),
        ),
        hall_case(
            "wrong schema",
            "/schema",
            "expected \"kalibre.hall/1\"",
            |v| set(v, "/schema", json!("kalibre.hall/2")),
        ),
        hall_case("missing schema", "/schema", "missing field `schema`", |v| {
            v.as_object_mut().unwrap().remove("schema");
        }),
        hall_case(
            "missing rack units",
            "/racks/1/units",
            "missing field `units`",
            |v| {
                v["racks"][1].as_object_mut().unwrap().remove("units");
            },
        ),
        hall_case(
            "tile open fraction zero",
            "/tiles/0/open_fraction",
            "(0, 1]",
            |v| set(v, "/tiles/0/open_fraction", json!(0.0)),
        ),
        hall_case(
            "tile open fraction above one",
            "/tiles/0/open_fraction",
            "(0, 1]",
            |v| set(v, "/tiles/0/open_fraction", json!(1.5)),
        ),
        hall_case(
            "tile outside the room",
            "/tiles/0/position_m/0",
            "outside the room",
            |v| set(v, "/tiles/0/position_m/0", json!(7.8)),
        ),
        hall_case(
            "two tiles on the same floor",
            "/tiles/1",
            "overlaps tile 0",
            |v| {
                let tile = v["tiles"][0].clone();
                let mut other = tile.clone();
                other["position_m"] = json!([2.3, 2.9]);
                set(v, "/tiles", json!([tile, other]));
            },
        ),
        hall_case(
            "two return grilles on the same ceiling",
            "/returns/1",
            "overlaps return grille 0",
            |v| {
                let grille = v["returns"][0].clone();
                let mut other = grille.clone();
                other["position_m"] = json!([3.0, 5.2]);
                set(v, "/returns", json!([grille, other]));
            },
        ),
        hall_case(
            "return with negative size",
            "/returns/0/size_m/1",
            "expected a positive size",
            |v| set(v, "/returns/0/size_m/1", json!(-0.6)),
        ),
        hall_case(
            "negative rated flow",
            "/cracs/0/rated_flow_m3_s",
            "positive rated flow",
            |v| set(v, "/cracs/0/rated_flow_m3_s", json!(-1.0)),
        ),
        hall_case(
            "rated flow beyond any CRAC",
            "/cracs/0/rated_flow_m3_s",
            "at most 300 m3/s, found 1e308",
            |v| set(v, "/cracs/0/rated_flow_m3_s", json!(1e308)),
        ),
        hall_case(
            "alpha bound below any server",
            "/server_types/0/alpha_cfm_per_w/min",
            "expected min >= 1e-6 cfm/W",
            |v| set(v, "/server_types/0/alpha_cfm_per_w/min", json!(1e-200)),
        ),
        hall_case(
            "alpha bound beyond any server",
            "/server_types/0/alpha_cfm_per_w/max",
            "expected max <= 100 cfm/W",
            |v| set(v, "/server_types/0/alpha_cfm_per_w/max", json!(1e308)),
        ),
        hall_case(
            "room of zero height",
            "/room/size_m/2",
            "positive room size",
            |v| set(v, "/room/size_m/2", json!(0.0)),
        ),
        hall_case(
            "inverted containment",
            "/containment/0/max_m/1",
            "positive size",
            |v| set(v, "/containment/0/max_m/1", json!(4.0)),
        ),
        hall_case(
            "containment outside the room",
            "/containment/0/max_m/1",
            "inside the room",
            |v| set(v, "/containment/0/max_m/1", json!(6.5)),
        ),
        hall_case(
            "effect without kind",
            "/effects/0/kind",
            "missing field `kind`",
            |v| set(v, "/effects", json!([{ "fraction": 0.1 }])),
        ),
        hall_case(
            "effect kind not a string",
            "/effects/0/kind",
            "expected a string",
            |v| set(v, "/effects", json!([{ "kind": 3 }])),
        ),
        hall_case(
            "unknown calibrate mode",
            "/calibrate/alpha",
            "unknown variant `per_rack`",
            |v| set(v, "/calibrate/alpha", json!("per_rack")),
        ),
        hall_case(
            "string where a number belongs",
            "/room/size_m/0",
            "invalid type",
            |v| set(v, "/room/size_m/0", json!("8")),
        ),
        hall_text_case(
            "NaN literal",
            "/tiles/0/open_fraction",
            "NaN and Infinity are not JSON",
            |t| t.replacen("0.25", "NaN", 1),
        ),
        hall_text_case(
            "infinite number",
            "/tiles/0/open_fraction",
            "number out of range",
            |t| t.replacen("0.25", "1e400", 1),
        ),
        hall_text_case(
            "truncated file",
            "/racks/1/servers/0/id",
            "EOF while parsing",
            |t| {
                let cut = t.find("\"R2-01\"").unwrap();
                t[..cut].to_string()
            },
        ),
        {
            // No field to blame: the place in the text is named instead.
            let mut c = hall_text_case(
                "trailing characters",
                "",
                "expected the end of the file",
                |t| t + "\n{}",
            );
            c.field = format!("line {}, column 1", c.text.lines().count());
            c
        },
        hall_text_case("empty file", "line 1", "EOF while parsing", |_| {
            String::new()
        }),
        hall_text_case("null document", "/", "invalid type: null", |_| {
            "null".to_string()
        }),
        hall_case("no CRAC", "/cracs", "a hall needs at least one CRAC", |v| {
            set(v, "/cracs", json!([]))
        }),
        hall_case(
            "more units than racks have",
            "/racks/0/units",
            "at most 100",
            |v| set(v, "/racks/0/units", json!(101)),
        ),
        {
            // serde_json would keep the second value without a word.
            let mut v = hall_value();
            set(
                &mut v,
                "/effects",
                json!([{ "kind": "bypass", "behind_rack": "R1", "fraction": 0.05 }]),
            );
            let text = serde_json::to_string(&v)
                .unwrap()
                .replace("\"fraction\":0.05", "\"fraction\":0.05,\"fraction\":0.2");
            assert!(text.contains("0.2"));
            HallCase {
                name: "a key twice in one object",
                text,
                field: "/effects/0".into(),
                phrase: "key `fraction` appears twice",
            }
        },
    ]
}
