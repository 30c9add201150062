//! Duplicate keys in a JSON object. `serde_json` keeps the last of two equal keys in a map
//! without a word, so a hall's effect written twice with different values, or a parameter
//! named twice in a `--params` file, would silently lose one; the readers refuse them.

use std::cell::RefCell;
use std::collections::HashSet;
use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};

/// A key as a token of a JSON pointer: `~` and `/` escaped (RFC 6901), so that
/// `alpha/db` reads as one key.
///
/// ```
/// assert_eq!(kalibre_dc::json_keys::escape_pointer_token("a/b~c"), "a~1b~0c");
/// ```
pub fn escape_pointer_token(token: &str) -> String {
    token.replace('~', "~0").replace('/', "~1")
}

/// The JSON pointer of the first object in `text` that repeats a key (`""` for the
/// top-level object) and that key, or `None` when no object repeats a key (or `text` is
/// not JSON: the full parse reports that).
///
/// ```
/// use kalibre_dc::json_keys::first_duplicate_key;
/// assert_eq!(first_duplicate_key(r#"{"a": 1, "b": {"c": 2}}"#), None);
/// assert_eq!(
///     first_duplicate_key(r#"{"a": [{"x": 1, "x": 2}]}"#),
///     Some(("/a/0".to_string(), "x".to_string()))
/// );
/// ```
pub fn first_duplicate_key(text: &str) -> Option<(String, String)> {
    let found = RefCell::new(None);
    let mut de = serde_json::Deserializer::from_str(text);
    let _ = Walk {
        pointer: String::new(),
        found: &found,
    }
    .deserialize(&mut de);
    found.into_inner()
}

/// [`first_duplicate_key`] as a field (`/` for the top-level object) and a message, the
/// way the readers of `hall.json` and `--params` report it.
///
/// ```
/// use kalibre_dc::json_keys::duplicate_key_problem;
/// assert_eq!(
///     duplicate_key_problem(r#"{"k": 1, "k": 2}"#),
///     Some(("/".to_string(), "key `k` appears twice".to_string()))
/// );
/// ```
pub fn duplicate_key_problem(text: &str) -> Option<(String, String)> {
    first_duplicate_key(text).map(|(pointer, key)| {
        let field = if pointer.is_empty() {
            "/".to_string()
        } else {
            pointer
        };
        (field, format!("key `{key}` appears twice"))
    })
}

/// Visits every value, carrying its pointer; stops at the first repeated key.
struct Walk<'f> {
    pointer: String,
    found: &'f RefCell<Option<(String, String)>>,
}

impl Walk<'_> {
    fn child(&self, segment: &str) -> Self {
        Walk {
            pointer: format!("{}/{}", self.pointer, escape_pointer_token(segment)),
            found: self.found,
        }
    }
}

impl<'de> DeserializeSeed<'de> for Walk<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0usize;
        while seq.next_element_seed(self.child(&i.to_string()))?.is_some() {
            i += 1;
        }
        Ok(())
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut seen = HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            let child = self.child(&key);
            if !seen.insert(key.clone()) {
                *self.found.borrow_mut() = Some((self.pointer, key));
                return Err(de::Error::custom("duplicate key"));
            }
            map.next_value_seed(child)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_first_repeat_at_any_depth_and_escapes_the_pointer() {
        assert_eq!(first_duplicate_key("[1, 2.5, null, true, \"x\"]"), None);
        assert_eq!(
            first_duplicate_key(r#"{"a/b": {"k~": 1, "k~": 2}}"#),
            Some(("/a~1b".to_string(), "k~".to_string()))
        );
        // The same key in two objects is no repeat.
        assert_eq!(first_duplicate_key(r#"[{"a": 1}, {"a": 2}]"#), None);
        assert_eq!(
            first_duplicate_key(r#"{"a/b": 1, "a/b": 2}"#),
            Some((String::new(), "a/b".to_string()))
        );
        // Not JSON: left to the full parse.
        assert_eq!(first_duplicate_key("{\"a\": "), None);
    }
}
