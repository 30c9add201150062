//! The parts of an external command's fingerprint, each with its own digest, and which
//! of them differ between two fingerprints: what a refusal of old runs names.

use super::StableHasher;

/// The parts of `now` whose digests differ from `then`'s (or that either lacks), in
/// `now`'s order, then those only `then` has: what changed between two fingerprints.
///
/// A file part is named by its path, so a project moved to another directory names every
/// file anew: a part only one side names is paired with the other side's of the same
/// kind and file name (`template /old/params.in.tmpl` with `template /new/params.in.tmpl`),
/// and counts as changed only when its digest does, under its new name.
pub fn changed_parts(then: &[(String, String)], now: &[(String, String)]) -> Vec<String> {
    let named = |name: &str, list: &[(String, String)]| list.iter().any(|(n, _)| n == name);
    // The part of `then` that `now`'s part stands for: the same name, else the same kind
    // and file name among the parts `now` does not name.
    let counterpart = |name: &str| -> Option<&(String, String)> {
        then.iter().find(|(n, _)| n == name).or_else(|| {
            let key = moved_file_key(name)?;
            then.iter()
                .find(|(n, _)| !named(n, now) && moved_file_key(n) == Some(key))
        })
    };
    let mut changed = Vec::new();
    let mut paired = Vec::new();
    for (name, digest) in now {
        match counterpart(name) {
            Some((n, d)) => {
                paired.push(n.as_str());
                if d != digest {
                    changed.push(name.clone());
                }
            }
            None => changed.push(name.clone()),
        }
    }
    for (name, _) in then {
        if !paired.contains(&name.as_str()) && !changed.contains(name) {
            changed.push(name.clone());
        }
    }
    changed
}

/// What pairs a file part across a move: its kind (`template ` or none) and the file's
/// name; `None` for the parts that are not files (`program`, `args`, ...).
fn moved_file_key(part: &str) -> Option<(bool, &str)> {
    let (template, path) = match part.strip_prefix("template ") {
        Some(p) => (true, p),
        None => (false, part),
    };
    let file = std::path::Path::new(path).file_name()?.to_str()?;
    (template || path.contains('/') || path.contains('\\')).then_some((template, file))
}

/// The fingerprint's parts, each digested on its own, so that runs of another
/// fingerprint can be told what changed since (the script, a template, an input file).
#[derive(Default)]
pub(crate) struct Parts(Vec<(String, StableHasher)>);

impl Parts {
    pub(crate) fn field(&mut self, part: &str, data: impl AsRef<[u8]>) {
        match self.0.iter_mut().find(|(n, _)| n == part) {
            Some((_, h)) => {
                h.field(data);
            }
            None => {
                let mut h = StableHasher::new();
                h.field(data);
                self.0.push((part.to_string(), h));
            }
        }
    }

    pub(crate) fn finish(self) -> Vec<(String, String)> {
        (self.0.into_iter())
            .map(|(n, h)| (n, format!("{:032x}", h.finish())))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts(list: &[(&str, &str)]) -> Vec<(String, String)> {
        list.iter()
            .map(|(n, d)| (n.to_string(), d.to_string()))
            .collect()
    }

    #[test]
    fn changed_parts_names_the_edited_added_and_removed_parts() {
        let then = parts(&[
            ("program", "1"),
            ("template a.tmpl", "2"),
            ("data.csv", "3"),
        ]);
        let now = parts(&[
            ("program", "1"),
            ("template a.tmpl", "9"),
            ("extra.csv", "4"),
        ]);
        assert_eq!(
            changed_parts(&then, &now),
            vec!["template a.tmpl", "extra.csv", "data.csv"]
        );
        assert!(changed_parts(&now, &now).is_empty());
    }

    #[test]
    fn a_moved_project_names_only_what_changed_once() {
        let then = parts(&[
            ("program", "1"),
            ("template /old/params.in.tmpl", "2"),
            ("/old/model.py", "3"),
        ]);
        let now = parts(&[
            ("program", "1"),
            ("template /new/params.in.tmpl", "2"),
            ("/new/model.py", "4"),
        ]);
        assert_eq!(changed_parts(&then, &now), vec!["/new/model.py"]);
        let unedited = parts(&[
            ("program", "1"),
            ("template /new/params.in.tmpl", "2"),
            ("/new/model.py", "3"),
        ]);
        assert!(changed_parts(&then, &unedited).is_empty());
    }

    #[test]
    fn a_part_digests_its_fields_in_order() {
        let digest = |fields: &[&str]| {
            let mut p = Parts::default();
            for f in fields {
                p.field("args", f);
            }
            p.finish()
        };
        assert_eq!(digest(&["a", "b"]), digest(&["a", "b"]));
        assert_ne!(digest(&["a", "b"]), digest(&["b", "a"]));
        assert_ne!(digest(&["ab"]), digest(&["a", "b"]));
    }
}
