//! The parts of an external command's fingerprint, each with its own digest, and which
//! of them differ between two fingerprints: what a refusal of old runs names.

use super::StableHasher;

/// The parts of `now` whose digests differ from `then`'s (or that either lacks), in
/// `now`'s order, then those only `then` has: what changed between two fingerprints.
pub fn changed_parts(then: &[(String, String)], now: &[(String, String)]) -> Vec<String> {
    let differs = |(name, digest): &(String, String), other: &[(String, String)]| {
        other.iter().all(|(n, d)| n != name || d != digest)
    };
    let mut changed: Vec<String> = (now.iter())
        .filter(|p| differs(p, then))
        .map(|(n, _)| n.clone())
        .collect();
    for (name, _) in then.iter().filter(|p| differs(p, now)) {
        if !changed.contains(name) {
            changed.push(name.clone());
        }
    }
    changed
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
