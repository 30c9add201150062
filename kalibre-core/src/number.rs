//! Numbers and lists in messages: as written, unless that would take many digits or
//! names; the largest magnitude kalibre fits; and which names can be printed.

/// The largest magnitude of a number kalibre fits (a bound, a measurement, its `sd`, a
/// model's output): the fits square differences and sum them over every output, so a
/// value near `f64::MAX` (1.8e308) turns them into infinity and NaN. Beyond this, a
/// value is refused where it is read, naming its file and field, instead of failing a
/// fit later with a message that names nothing. No quantity in any unit system comes
/// near it (the observable universe holds about 1e80 atoms).
///
/// ```
/// use kalibre_core::{within_magnitude, MAX_MAGNITUDE};
/// assert!(within_magnitude(-1e150) && within_magnitude(6.02e23));
/// assert!(!within_magnitude(1e300) && !within_magnitude(f64::NAN));
/// assert_eq!(MAX_MAGNITUDE, 1e150);
/// ```
pub const MAX_MAGNITUDE: f64 = 1e150;

/// Finite and at most [`MAX_MAGNITUDE`] in magnitude.
pub fn within_magnitude(v: f64) -> bool {
    v.abs() <= MAX_MAGNITUDE
}

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

/// The longest name (an id, a snapshot or scenario label) kalibre takes: names are
/// printed in messages, reports, journals and file names.
pub const MAX_NAME_CHARS: usize = 200;

/// Why a name (an id, a snapshot or scenario label) cannot be printed as it is, if it
/// cannot: a control character (an escape sequence would reach the terminal, a NUL byte
/// no argument or file can carry) or more than [`MAX_NAME_CHARS`] characters.
///
/// ```
/// use kalibre_core::unprintable_name;
/// assert_eq!(unprintable_name("winter"), None);
/// assert!(unprintable_name("win\u{7}ter").unwrap().contains("U+0007"));
/// assert!(unprintable_name(&"x".repeat(201)).unwrap().contains("201 characters"));
/// ```
pub fn unprintable_name(name: &str) -> Option<String> {
    if let Some(why) = control_character(name) {
        return Some(why);
    }
    let n = name.chars().count();
    (n > MAX_NAME_CHARS)
        .then(|| format!("is {n} characters long; expected at most {MAX_NAME_CHARS}"))
}

/// Reads `null` (how JSON writes a non-finite number) back as NaN, so that a file
/// holding one (a report with a diverged fit, a journaled timeout without a finite
/// limit) still loads.
pub(crate) fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// The first control character of `name`, as the reason it cannot be printed as it is
/// (an escape sequence would reach the terminal, a NUL byte no argument or file can
/// carry).
pub(crate) fn control_character(name: &str) -> Option<String> {
    let c = name.chars().find(|c| c.is_control())?;
    Some(format!(
        "holds a control character (U+{:04X}); expected printable text",
        c as u32
    ))
}
