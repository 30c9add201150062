//! What a refused `snapshots.csv` row most likely means, said after the refusal: a
//! decimal comma that split a value in two, a space around a number, columns an export
//! added, an id one slip away from one the hall has.

/// Why a data row has other than 4 fields, where the fields show it: a decimal comma
/// (`17,5` read as two fields), or columns an export added. Empty when nothing shows.
pub(super) fn field_count(fields: &[&str]) -> String {
    split_decimal(fields, 4).unwrap_or_else(|| {
        if fields.len() > 4 {
            "; an export's extra columns? kalibre reads exactly snapshot,kind,id,value".into()
        } else {
            String::new()
        }
    })
}

/// The hint for one field too many whose last two read as a number split at a comma
/// (`30,5`), in a file of `columns` columns whose last is a number.
fn split_decimal(fields: &[&str], columns: usize) -> Option<String> {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let signed = |s: &str| digits(s.trim_start_matches(['-', '+']));
    let (a, b) = (fields.get(columns - 1)?, fields.get(columns)?);
    (fields.len() == columns + 1 && signed(a) && digits(b))
        .then(|| comma(": ", a, b, "reads as two fields"))
}

/// [`field_count`] for `measurements.csv`, whose header has `columns` fields (3, or 4
/// with `sd`): a decimal comma in its value (or sd), or an sd under a 3-column header.
pub(super) fn measurement_field_count(fields: &[&str], columns: usize) -> String {
    split_decimal(fields, columns).unwrap_or_else(|| {
        if columns == 3 && fields.len() == 4 {
            "; a standard uncertainty? name it in the header: scenario,output,value,sd".into()
        } else {
            String::new()
        }
    })
}

/// The hint for `a,b`, a value with a comma: a decimal comma, or with three digits after
/// it a thousands separator as likely (`4,200` W).
/// `lead` starts it (`: ` or `; `, as the message before it reads).
fn comma(lead: &str, a: &str, b: &str, what: &str) -> String {
    if b.len() == 3 {
        format!(
            "{lead}a thousands separator or a decimal comma? `{a},{b}` {what}; write `{a}{b}` \
             or `{a}.{b}`, whichever it means"
        )
    } else {
        format!("{lead}a decimal comma? `{a},{b}` {what}; write `{a}.{b}`")
    }
}

/// What a header with the four columns and others, or in another order, needs.
pub(super) fn header(fields: &[&str]) -> String {
    let wanted = ["snapshot", "kind", "id", "value"];
    let has_all = wanted.iter().all(|w| fields.contains(w));
    if has_all && fields.len() > wanted.len() {
        "; remove the other columns (kalibre reads exactly these four, in this order)".into()
    } else if has_all {
        "; put the columns in this order".into()
    } else {
        String::new()
    }
}

/// What is wrong with a value that is no number, where it shows: a space around it, or a
/// decimal comma. Empty when nothing shows.
pub(super) fn value(text: &str, parses: impl Fn(&str) -> bool) -> String {
    if text.trim() != text && parses(text.trim()) {
        "; a space before or after the number: remove it".into()
    } else if text.matches(',').count() == 1 && parses(&text.replace(',', ".")) {
        let (a, b) = text.split_once(',').expect("one comma");
        comma("; ", a, b, "is no number")
    } else {
        String::new()
    }
}

/// The edit distance between `a` and `b` with adjacent swaps counted as one edit (a
/// typist's slips), by characters.
fn slips(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, cell) in d[0].iter_mut().enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            d[i][j] = (d[i - 1][j] + 1)
                .min(d[i][j - 1] + 1)
                .min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                d[i][j] = d[i][j].min(d[i - 2][j - 2] + 1);
            }
        }
    }
    d[a.len()][b.len()]
}

/// `; did you mean `x`?` for the one id of `ids` within two slips of `id` (case aside),
/// closer than any other; of equally close ones, the one with the same characters (a
/// swap). Empty when none or several are.
pub(super) fn nearest_id<'a>(id: &str, ids: impl IntoIterator<Item = &'a str>) -> String {
    let lower = id.to_lowercase();
    let sorted = |s: &str| {
        let mut c: Vec<char> = s.chars().collect();
        c.sort_unstable();
        c
    };
    let letters = sorted(&lower);
    let length = lower.chars().count();
    // Rank: fewer slips first, then the same characters.
    let mut best: Option<((usize, bool), &str)> = None;
    let mut tie = false;
    for candidate in ids {
        // More than two characters apart in length is more than two slips.
        if candidate.chars().count().abs_diff(length) > 2 {
            continue;
        }
        let c = candidate.to_lowercase();
        let rank = (slips(&lower, &c), sorted(&c) != letters);
        match best {
            Some((b, _)) if rank > b => {}
            Some((b, _)) if rank == b => tie = true,
            _ => {
                best = Some((rank, candidate));
                tie = false;
            }
        }
    }
    match best {
        Some(((d, _), c)) if d <= 2 && !tie => format!("; did you mean `{c}`?"),
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_decimal_comma_and_extra_columns_are_told_apart() {
        assert_eq!(
            field_count(&["t0", "sensor_c", "c-1", "19", "95"]),
            ": a decimal comma? `19,95` reads as two fields; write `19.95`"
        );
        assert!(
            field_count(&["t0", "sensor_c", "c-1", "19.9", "building-7"]).contains("extra columns")
        );
        assert_eq!(field_count(&["t0", "sensor_c", "c-1"]), "");
        assert!(header(&["snapshot", "kind", "id", "value", "unit"]).contains("remove"));
        assert!(header(&["kind", "snapshot", "id", "value"]).contains("order"));
        assert_eq!(header(&["time", "sensor", "temp"]), "");
    }

    #[test]
    fn values_with_spaces_or_commas_say_so() {
        let parses = |s: &str| s.parse::<f64>().is_ok();
        assert!(value("19.95 ", parses).contains("space"));
        assert_eq!(
            value("19,95", parses),
            "; a decimal comma? `19,95` is no number; write `19.95`"
        );
        assert!(value("4,200", parses).contains("thousands separator"));
        assert!(field_count(&["t0", "power_w", "A02", "4", "200"]).contains("write `4200` or"));
        assert_eq!(value("n/a", parses), "");
        assert_eq!(value("1,000,5", parses), "");
    }

    #[test]
    fn an_id_one_slip_away_is_suggested_and_a_tie_is_not() {
        let ids = ["c-A07-17", "c-A07-11", "h-A07-11"];
        assert_eq!(nearest_id("c-A07-71", ids), "; did you mean `c-A07-17`?");
        assert_eq!(nearest_id("C-A07-17", ids), "; did you mean `c-A07-17`?");
        // c-A07-1 is one slip from two ids.
        assert_eq!(nearest_id("c-A07-1", ids), "");
        assert_eq!(nearest_id("z-Q99-00", ids), "");
    }
}
