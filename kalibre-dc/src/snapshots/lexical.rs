//! The lexical pieces of `snapshots.csv`: physical line numbers, decimal numbers, and
//! fields shown in messages.

/// Physical line numbers of records. The csv crate's own line count drifts after blank
/// lines (which it skips), so lines are counted from the record's byte offset instead.
#[derive(Default)]
pub(super) struct LineCounter {
    counted_to: usize,
    line: u64,
}

impl LineCounter {
    /// The 1-based line where the record at byte offset `byte` starts; offsets must come in
    /// increasing order.
    pub(super) fn line_at(&mut self, bytes: &[u8], byte: u64) -> u64 {
        let mut start = usize::try_from(byte).unwrap_or(usize::MAX).min(bytes.len());
        // The offset may include the terminators of skipped blank lines.
        while start < bytes.len() && matches!(bytes[start], b'\r' | b'\n') {
            start += 1;
        }
        let from = self.counted_to.min(start);
        for (k, &b) in bytes[from..start].iter().enumerate() {
            let lone_cr = b == b'\r' && bytes.get(from + k + 1) != Some(&b'\n');
            if b == b'\n' || lone_cr {
                self.line += 1;
            }
        }
        self.counted_to = self.counted_to.max(start);
        self.line + 1
    }
}

/// Reads the next record of `reader` (over `bytes`, from `file`) into `record` and returns
/// its physical line, or `None` at the end; an unreadable record is an error naming its
/// line.
pub(super) fn next_record(
    reader: &mut csv::Reader<&[u8]>,
    record: &mut csv::ByteRecord,
    lines: &mut LineCounter,
    bytes: &[u8],
    file: &str,
) -> crate::Result<Option<u64>> {
    let more = reader.read_byte_record(record).map_err(|e| {
        let line = lines.line_at(bytes, e.position().map_or(0, csv::Position::byte));
        crate::Error::format(file, format!("line {line}"), format!("unreadable CSV: {e}"))
    })?;
    Ok(more.then(|| lines.line_at(bytes, record.position().map_or(0, csv::Position::byte))))
}

/// The message for [`text_after_closing_quote`]'s finding.
pub(super) const TEXT_AFTER_QUOTE: &str = "text follows a closing `\"`; expected the quoted \
     value to end the field (a `\"` inside a quoted value is written `\"\"`)";

/// The field (0-based) of the record starting at byte `start` of `bytes` in which text
/// follows a closing quote (`"3"000`, `"t0"x`), or `None`. The csv crate reads such a
/// field as the quoted part and the rest run together, a guess at what was meant; RFC
/// 4180 allows only a delimiter or the line's end after the closing quote.
pub(super) fn text_after_closing_quote(bytes: &[u8], start: u64) -> Option<usize> {
    let mut i = usize::try_from(start)
        .unwrap_or(usize::MAX)
        .min(bytes.len());
    // The offset may include the terminators of skipped blank lines.
    while i < bytes.len() && matches!(bytes[i], b'\r' | b'\n') {
        i += 1;
    }
    let mut field = 0;
    let mut at_field_start = true;
    while i < bytes.len() {
        match bytes[i] {
            b'"' if at_field_start => {
                // A quoted field: to its closing quote, `""` standing for one quote.
                i += 1;
                loop {
                    match bytes.get(i) {
                        None => return None, // unclosed: the reader reports it
                        Some(b'"') if bytes.get(i + 1) == Some(&b'"') => i += 2,
                        Some(b'"') => break,
                        Some(_) => i += 1,
                    }
                }
                i += 1;
                match bytes.get(i) {
                    None | Some(b',' | b'\r' | b'\n') => {}
                    Some(_) => return Some(field),
                }
                at_field_start = false;
            }
            b',' => {
                field += 1;
                at_field_start = true;
                i += 1;
            }
            b'\r' | b'\n' => return None,
            _ => {
                at_field_start = false;
                i += 1;
            }
        }
    }
    None
}

/// A finite decimal number: optional sign, digits with an optional fraction, an optional
/// exponent. Rejects `nan`, `inf`, hex, empty text and values that overflow to infinity.
pub(crate) fn parse_decimal(text: &str) -> Option<f64> {
    let b = text.as_bytes();
    let mut i = 0;
    if matches!(b.first(), Some(b'+' | b'-')) {
        i += 1;
    }
    let int_start = i;
    while i < b.len() && b[i].is_ascii_digit() {
        i += 1;
    }
    let mut digits = i - int_start;
    if i < b.len() && b[i] == b'.' {
        i += 1;
        let frac_start = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        digits += i - frac_start;
    }
    if digits == 0 {
        return None;
    }
    if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        i += 1;
        if matches!(b.get(i), Some(b'+' | b'-')) {
            i += 1;
        }
        let exp_start = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        if i == exp_start {
            return None;
        }
    }
    if i != b.len() {
        return None;
    }
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Text for a message, cut short so that a huge field does not flood the error.
pub(super) fn show(text: &str) -> String {
    const MAX: usize = 60;
    match text.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}...", &text[..cut]),
        None => text.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::{parse_decimal, text_after_closing_quote, LineCounter};

    #[test]
    fn lines_count_blank_lines_crlf_and_quoted_breaks() {
        let text = "h\n\na\n\n\"b\nx\"\nc\r\n\r\nd\re\n";
        let mut r = csv::ReaderBuilder::new()
            .has_headers(false)
            .from_reader(text.as_bytes());
        let mut rec = csv::ByteRecord::new();
        let mut lines = LineCounter::default();
        let mut got = Vec::new();
        while r.read_byte_record(&mut rec).unwrap() {
            let byte = rec.position().unwrap().byte();
            got.push((
                String::from_utf8(rec[0].to_vec()).unwrap(),
                lines.line_at(text.as_bytes(), byte),
            ));
        }
        let want = [
            ("h", 1),
            ("a", 3),
            ("b\nx", 5),
            ("c", 7),
            ("d", 9),
            ("e", 10),
        ];
        let want: Vec<(String, u64)> = want.iter().map(|(s, l)| (s.to_string(), *l)).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn text_after_a_closing_quote_is_found_in_its_field() {
        let at = |text: &str| text_after_closing_quote(text.as_bytes(), 0);
        assert_eq!(at("t0,power_w,S,\"3\"000\n"), Some(3));
        assert_eq!(at("\"t0\"x,power_w,S,3\n"), Some(0));
        for fine in [
            "t0,power_w,S,3000\n",
            "\"t0\",\"power_w\",\"S\",\"3000\"\r\n",
            "t0,power_w,\"S \"\"big\"\", one\",3000",
            "t0,power_w,\"S\nwrapped\",3\n",
            "t0,power_w,S,\"3",
            "a\"b,c\n",
        ] {
            assert_eq!(at(fine), None, "{fine:?}");
        }
        // From a record's offset, past blank lines' terminators; only that record.
        let text = "h\n\r\n\"x\"y,1\n\"z\"w\n";
        assert_eq!(text_after_closing_quote(text.as_bytes(), 2), Some(0));
        assert_eq!(text_after_closing_quote(b"a,b\n\"z\"w\n", 0), None);
    }

    #[test]
    fn decimals() {
        for (t, v) in [
            ("1", 1.0),
            ("-2.5", -2.5),
            ("+.5", 0.5),
            ("3.", 3.0),
            ("1e3", 1000.0),
            ("2.5E-1", 0.25),
        ] {
            assert_eq!(parse_decimal(t), Some(v), "{t}");
        }
        for t in [
            "", "nan", "NaN", "inf", "-inf", "infinity", "0x10", "1e", ".", "-", "1,5", " 1",
            "1e400", "1.2.3",
        ] {
            assert_eq!(parse_decimal(t), None, "{t}");
        }
    }
}
