//! Numbers and lists in messages: as written, unless that would take many digits or
//! names.

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

/// A list of names for a message: all of a short one, the first few and the count of a
/// long one (a per-server hall has thousands of parameters).
///
/// ```
/// use kalibre_core::some_names;
/// let names: Vec<String> = (1..=8).map(|i| format!("p{i}")).collect();
/// assert_eq!(some_names(&names[..2]), "p1, p2");
/// assert_eq!(some_names(&names), "p1, p2, p3, p4, p5, p6, ... (8 in all)");
/// ```
pub fn some_names(names: &[String]) -> String {
    const SHOWN: usize = 6;
    match names.len() {
        n if n > SHOWN => format!("{}, ... ({n} in all)", names[..SHOWN].join(", ")),
        _ => names.join(", "),
    }
}
