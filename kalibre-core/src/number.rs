//! Numbers in messages: as written, unless that would take many digits.

/// A number as written, or in exponent form when that would run to many digits (an
/// error message quoting 1e308 should not print 309 of them, nor 1e-300 its 300 zeros).
///
/// ```
/// use kalibre_core::number;
/// assert_eq!(number(0.25), "0.25");
/// assert_eq!(number(0.0), "0");
/// assert_eq!(number(-2.5e300), "-2.5e300");
/// assert_eq!(number(1e-300), "1e-300");
/// ```
pub fn number(v: f64) -> String {
    if v == 0.0 || (1e-4..1e6).contains(&v.abs()) || !v.is_finite() {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}
