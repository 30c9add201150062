//! `runs.jsonl`: exact-bit keys, torn last lines, garbage lines, foreign fingerprints,
//! parallel appends.

mod common;

use std::fs;
use std::io::Write;

use kalibre_core::{ModelError, Outputs, RunStatus, RunStore};
use rayon::prelude::*;

fn names() -> Vec<String> {
    vec!["a".into(), "b".into()]
}

fn ok(v: &[f64]) -> Result<Outputs, ModelError> {
    Ok(Outputs::from(v.to_vec()))
}

/// A journal in a fresh directory `name` holding one ok run at `t0` per value of `a`
/// (b = 1, output a), its store closed.
fn journal_of(name: &str, a_values: &[f64]) -> std::path::PathBuf {
    let path = common::temp_dir(name).join("runs.jsonl");
    let store = RunStore::open(&path, "m1").unwrap();
    for &a in a_values {
        store
            .record("t0", &names(), &[a, 1.0], &ok(&[a]), 0.0)
            .unwrap();
    }
    path
}

fn lines(path: &std::path::Path) -> Vec<String> {
    fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

#[test]
fn values_round_trip_bit_exactly_and_keys_are_exact() {
    let dir = common::temp_dir("journal-bits");
    let path = dir.join("runs.jsonl");
    let p = [0.1 + 0.2, 1.0 / 3.0];
    let out = [std::f64::consts::PI, 1e-300, -2.5e17, 0.1 + 0.7];
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store.record("t0", &names(), &p, &ok(&out), 0.5).unwrap();
        store
            .record(
                "t0",
                &names(),
                &[0.3, 1.0 / 3.0],
                &Err(ModelError::failed("boom")),
                0.1,
            )
            .unwrap();
    }
    let store = RunStore::open(&path, "m1").unwrap();
    assert!(store.load_report().is_clean());
    // 0.1 + 0.2 != 0.3: a different key, which holds the failed run. A failure is not
    // replayed by a later opening: it runs again when asked for.
    assert_eq!(store.len(), 1);
    assert_eq!(store.load_report().failed_to_retry, 1);
    let rec = store.get("t0", &names(), &p).unwrap();
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(rec.outputs.as_ref().unwrap()), bits(&out));
    assert_eq!(bits(&rec.params), bits(&p));
    assert!(store.get("t0", &names(), &[0.3, 1.0 / 3.0]).is_none());
    assert!(store.get("t1", &names(), &p).is_none());
    assert!(store.get("t0", &["a".into(), "c".into()], &p).is_none());
}

/// A failed run is replayed within the opening that recorded it, and run again by a
/// later one (its cause may have passed); the retry's result is the one kept, and a
/// point that failed again stays to retry.
#[test]
fn failed_runs_run_again_after_reopening() {
    let dir = common::temp_dir("journal-retry");
    let path = dir.join("runs.jsonl");
    let (a, b) = ([1.0, 2.0], [3.0, 4.0]);
    let timeout = || {
        Err(ModelError::Timeout {
            seconds: 0.5,
            log_tail: None,
        })
    };
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store.record("t0", &names(), &a, &timeout(), 0.5).unwrap();
        store.record("t0", &names(), &b, &timeout(), 0.5).unwrap();
        let again = store.get("t0", &names(), &a).unwrap();
        assert_eq!(again.status, RunStatus::Failed);
    }
    {
        let store = RunStore::open(&path, "m1").unwrap();
        assert_eq!(store.load_report().failed_to_retry, 2);
        assert!(store.get("t0", &names(), &a).is_none());
        store.record("t0", &names(), &a, &ok(&[20.0]), 3.0).unwrap();
        store.record("t0", &names(), &b, &timeout(), 0.5).unwrap();
    }
    let store = RunStore::open(&path, "m1").unwrap();
    let load = store.load_report();
    assert!(load.is_clean() && load.conflicts.is_empty(), "{load:?}");
    assert_eq!((store.len(), load.failed_to_retry), (1, 1));
    assert_eq!(
        store.get("t0", &names(), &a).unwrap().outputs,
        Some(vec![20.0])
    );
    assert!(store.get("t0", &names(), &b).is_none());
}

/// Opened to replay failures, a journal gives a point that only failed as its failure
/// (the model is not asked again), and a point whose retry succeeded as that result.
#[test]
fn replayed_failures_are_failures_and_a_retrys_result_wins() {
    let dir = common::temp_dir("journal-replay");
    let path = dir.join("runs.jsonl");
    let (a, b) = ([1.0, 2.0], [3.0, 4.0]);
    let diverged = || Err(ModelError::failed("diverged"));
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store.record("t0", &names(), &a, &diverged(), 0.5).unwrap();
        store.record("t0", &names(), &b, &diverged(), 0.5).unwrap();
        store.record("t0", &names(), &b, &diverged(), 0.5).unwrap();
        store.record("t0", &names(), &a, &ok(&[20.0]), 3.0).unwrap();
    }
    let store = RunStore::open_replaying_failures(&path, "m1").unwrap();
    let load = store.load_report();
    assert!(load.is_clean() && load.conflicts.is_empty(), "{load:?}");
    assert_eq!(
        (load.loaded, load.failed_replayed, load.failed_to_retry),
        (1, 1, 0)
    );
    assert_eq!(
        store.get("t0", &names(), &a).unwrap().outputs,
        Some(vec![20.0])
    );
    let failed = store.get("t0", &names(), &b).unwrap();
    assert_eq!(failed.status, RunStatus::Failed);
    assert!(failed
        .result()
        .unwrap_err()
        .to_string()
        .contains("diverged"));
    drop(store);
    // The same journal opened as usual runs b again.
    let store = RunStore::open(&path, "m1").unwrap();
    assert_eq!(store.load_report().failed_to_retry, 1);
    assert!(store.get("t0", &names(), &b).is_none());
}

/// What else a run computed (`Outputs::extras`) is journaled with it, bit for bit, and a
/// run without any writes no `extras` key (older readers see the line they know).
#[test]
fn extras_are_journaled_with_the_run() {
    let dir = common::temp_dir("journal-extras");
    let path = dir.join("runs.jsonl");
    let intakes = vec![20.0 + 1.0 / 3.0, 1e-300, 31.7];
    let with = Outputs {
        values: vec![1.0, 2.0],
        extras: [("server_intake_c".to_string(), intakes.clone())].into(),
        ..Default::default()
    };
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store
            .record("t0", &names(), &[1.0, 2.0], &Ok(with.clone()), 0.5)
            .unwrap();
        store
            .record("t1", &names(), &[1.0, 2.0], &ok(&[3.0, 4.0]), 0.5)
            .unwrap();
    }
    let text = lines(&path);
    assert!(
        text[0].contains("\"extras\"") && !text[1].contains("extras"),
        "{text:?}"
    );
    let store = RunStore::open(&path, "m1").unwrap();
    let back = store
        .get("t0", &names(), &[1.0, 2.0])
        .unwrap()
        .result()
        .unwrap();
    assert_eq!(back, with);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&back.extras["server_intake_c"]), bits(&intakes));
    let plain = store
        .get("t1", &names(), &[1.0, 2.0])
        .unwrap()
        .result()
        .unwrap();
    assert!(plain.extras.is_empty());
}

#[test]
fn a_torn_last_line_is_reported_cut_and_never_fatal() {
    let path = journal_of("journal-torn", &[0.0, 1.0, 2.0]);
    let whole = fs::read(&path).unwrap();
    let clean_len = whole.len();
    // A crash mid-write: half of a fourth line, no newline.
    let mut f = fs::OpenOptions::new().append(true).open(&path).unwrap();
    f.write_all(br#"{"seq":3,"fingerprint":"m1","scenario":"t0","param_names":["a","b"],"par"#)
        .unwrap();
    drop(f);

    let store = RunStore::open(&path, "m1").unwrap();
    let load = store.load_report();
    assert_eq!(load.loaded, 3);
    assert!(load.bad_lines.is_empty());
    let torn = load.torn_tail.as_ref().expect("torn tail reported");
    assert_eq!(torn.line, 4);
    // Opening writes nothing (a command refused after it leaves the file as it was);
    // the torn bytes are cut when the next run is appended.
    assert!(fs::read(&path).unwrap().len() > clean_len);
    let rec = store
        .record("t0", &names(), &[9.0, 1.0], &ok(&[9.0]), 0.0)
        .unwrap();
    assert_eq!(rec.seq, 3);
    assert_eq!(
        fs::read(&path).unwrap()[..clean_len],
        whole[..],
        "torn bytes cut off, the whole lines kept"
    );
    drop(store);
    let again = RunStore::open(&path, "m1").unwrap();
    assert!(again.load_report().is_clean());
    assert_eq!(again.len(), 4);
    assert_eq!(lines(&path).len(), 4);
}

#[test]
fn a_complete_last_line_without_newline_is_kept() {
    let path = journal_of("journal-nonewline", &[1.0, 2.0]);
    let mut bytes = fs::read(&path).unwrap();
    assert_eq!(bytes.pop(), Some(b'\n'));
    fs::write(&path, &bytes).unwrap();
    let store = RunStore::open(&path, "m1").unwrap();
    assert!(store.load_report().is_clean());
    assert_eq!(store.len(), 2);
    store
        .record("t0", &names(), &[3.0, 1.0], &ok(&[3.0]), 0.0)
        .unwrap();
    drop(store);
    let again = RunStore::open(&path, "m1").unwrap();
    assert!(again.load_report().is_clean());
    assert_eq!(again.len(), 3);
}

#[test]
fn garbage_lines_and_foreign_runs_are_skipped_and_reported() {
    let dir = common::temp_dir("journal-garbage");
    let path = dir.join("runs.jsonl");
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store
            .record("t0", &names(), &[1.0, 1.0], &ok(&[1.0]), 0.0)
            .unwrap();
        let other = RunStore::in_memory("m2");
        let foreign = other
            .record("t0", &names(), &[5.0, 1.0], &ok(&[5.0]), 0.0)
            .unwrap();
        drop(store);
        let mut f = fs::OpenOptions::new().append(true).open(&path).unwrap();
        writeln!(f, "this is not json").unwrap();
        writeln!(f, "{}", serde_json::to_string(&foreign).unwrap()).unwrap();
        // Parses as JSON but breaks the record's rules (ok without outputs).
        writeln!(
            f,
            r#"{{"seq":9,"fingerprint":"m1","scenario":"t0","param_names":["a","b"],"params":[7.0,1.0],"status":"ok","wall_s":0.0}}"#
        )
        .unwrap();
        writeln!(f, r#"{{"seq":10,"unknown_field":1}}"#).unwrap();
    }
    {
        let store = RunStore::open(&path, "m1").unwrap();
        store
            .record("t0", &names(), &[2.0, 1.0], &ok(&[2.0]), 0.0)
            .unwrap();
        // Each run knows its journal line, bad and foreign lines counted, so a record
        // the loop refuses can be named.
        let line = |p: &[f64]| store.get_with_line("t0", &names(), p).unwrap().0;
        assert_eq!((line(&[1.0, 1.0]), line(&[2.0, 1.0])), (1, 6));
    }
    let store = RunStore::open(&path, "m1").unwrap();
    let load = store.load_report();
    assert_eq!(load.lines, 6);
    assert_eq!(load.loaded, 2);
    assert_eq!(load.other_fingerprint, 1);
    assert!(load.torn_tail.is_none());
    let bad: Vec<usize> = load.bad_lines.iter().map(|b| b.line).collect();
    assert_eq!(bad, vec![2, 4, 5]);
    assert!(load.bad_lines[1].reason.contains("without outputs"));
    assert!(
        store.get("t0", &names(), &[5.0, 1.0]).is_none(),
        "foreign run ignored"
    );
    assert!(store.get("t0", &names(), &[2.0, 1.0]).is_some());
    // The foreign line's sequence number (0 of m2) and the bad ones do not collide with new ones.
    assert_eq!(store.get("t0", &names(), &[2.0, 1.0]).unwrap().seq, 1);
}

#[test]
fn parallel_appends_give_whole_lines() {
    let dir = common::temp_dir("journal-parallel");
    let path = dir.join("runs.jsonl");
    let store = RunStore::open(&path, "m1").unwrap();
    (0..64).into_par_iter().for_each(|i| {
        let p = [i as f64, 0.5];
        store
            .record("t0", &names(), &p, &ok(&[i as f64; 8]), 0.0)
            .unwrap();
    });
    drop(store);
    let store = RunStore::open(&path, "m1").unwrap();
    assert!(store.load_report().is_clean());
    assert_eq!(store.len(), 64);
    let mut seqs: Vec<u64> = (0..64)
        .map(|i| store.get("t0", &names(), &[i as f64, 0.5]).unwrap().seq)
        .collect();
    seqs.sort();
    assert_eq!(seqs, (0..64).collect::<Vec<_>>());
}

#[test]
fn a_whole_last_line_that_is_no_run_is_kept_as_a_bad_line() {
    let path = journal_of("journal-bad-tail", &[1.0]);
    // Complete JSON, not a record (say, a later version's), and no newline: not torn.
    let mut f = fs::OpenOptions::new().append(true).open(&path).unwrap();
    f.write_all(br#"{"seq":1,"note":"not a run"}"#).unwrap();
    drop(f);
    let before = fs::read(&path).unwrap();
    let store = RunStore::open(&path, "m1").unwrap();
    let load = store.load_report();
    assert!(load.torn_tail.is_none());
    assert_eq!(load.bad_lines.len(), 1);
    assert_eq!(load.bad_lines[0].line, 2);
    assert_eq!(fs::read(&path).unwrap(), before, "nothing written on open");
    let rec = store
        .record("t0", &names(), &[2.0, 1.0], &ok(&[2.0]), 0.0)
        .unwrap();
    assert_eq!(rec.seq, 1);
    assert_eq!(
        store.get_with_line("t0", &names(), &[2.0, 1.0]).unwrap().0,
        3
    );
    drop(store);
    let text = fs::read_to_string(&path).unwrap();
    assert!(text.starts_with(std::str::from_utf8(&before).unwrap()));
    assert_eq!(text.lines().count(), 3);
    let again = RunStore::open(&path, "m1").unwrap();
    assert_eq!(again.len(), 2);
    assert_eq!(again.load_report().bad_lines[0].line, 2);
}

#[test]
fn the_sequence_never_wraps() {
    let path = journal_of("journal-seq-max", &[1.0]);
    let text = fs::read_to_string(&path)
        .unwrap()
        .replace("\"seq\":0", &format!("\"seq\":{}", u64::MAX));
    fs::write(&path, text).unwrap();
    let store = RunStore::open(&path, "m1").unwrap();
    let rec = store
        .record("t0", &names(), &[2.0, 1.0], &ok(&[2.0]), 0.0)
        .unwrap();
    assert_eq!(rec.seq, u64::MAX);
}

#[test]
fn a_repeated_run_with_another_result_is_named() {
    let path = journal_of("journal-conflict", &[1.0, 2.0]);
    let text = fs::read_to_string(&path).unwrap();
    let first = text.lines().next().unwrap().to_string();
    // The same run twice more: once as it was, once with another output.
    let other = first.replace("\"outputs\":[1.0]", "\"outputs\":[7.0]");
    assert_ne!(other, first);
    fs::write(&path, format!("{text}{first}\n{other}\n")).unwrap();
    let store = RunStore::open(&path, "m1").unwrap();
    let load = store.load_report();
    assert_eq!(load.duplicates, 2);
    assert_eq!(load.conflicts.len(), 1);
    assert_eq!(load.conflicts[0].line, 4);
    assert!(load.conflicts[0].reason.contains("line 1's is used"));
    let kept = store.get("t0", &names(), &[1.0, 1.0]).unwrap();
    assert_eq!(kept.outputs, Some(vec![1.0]));
}

/// A file at the journal's path that is not a journal (text with no newline, an HTML
/// page) is refused and left as it was: it used to be cut as a "torn tail", or written
/// into.
#[test]
fn a_file_that_is_not_a_journal_is_refused_and_left_alone() {
    let dir = common::temp_dir("journal-foreign");
    for (name, text) in [
        ("flat", "x".repeat(3000)),
        ("page", "<html>\n<body>notes</body>\n</html>\n".to_string()),
        (
            "page-no-newline",
            "<html>\n<body>notes</body>\n</html>".to_string(),
        ),
    ] {
        let path = dir.join(format!("{name}.jsonl"));
        std::fs::write(&path, &text).unwrap();
        let err = RunStore::open(&path, "m1").unwrap_err().to_string();
        assert!(err.contains("not a kalibre run journal"), "{name}: {err}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), text, "{name}");
    }
}

/// Lines no run could write, a negative or non-finite wall time, a negative spread or
/// one of another length than the outputs, are skipped as bad lines, naming why, and
/// their runs are not replayed.
#[test]
fn records_with_impossible_times_or_spreads_are_bad_lines() {
    let path = journal_of("journal-impossible", &[1.0]);
    let good = lines(&path)[0].clone();
    let with = |a: f64, edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
        v["params"][0] = serde_json::json!(a);
        v["outputs"] = serde_json::json!([a]);
        edit(&mut v);
        v.to_string()
    };
    let edited = [
        with(2.0, &|v| v["wall_s"] = serde_json::json!(-1.0)),
        with(3.0, &|v| v["spread"] = serde_json::json!([-0.1])),
        with(4.0, &|v| v["spread"] = serde_json::json!([0.1, 0.1])),
        with(5.0, &|v| v["spread"] = serde_json::json!([0.1])),
    ];
    let mut f = fs::OpenOptions::new().append(true).open(&path).unwrap();
    for line in &edited {
        writeln!(f, "{line}").unwrap();
    }
    drop(f);
    let store = RunStore::open(&path, "m1").unwrap();
    let load = store.load_report();
    let bad: Vec<(usize, &str)> = load
        .bad_lines
        .iter()
        .map(|b| (b.line, b.reason.as_str()))
        .collect();
    assert_eq!(
        bad,
        vec![
            (2, "wall_s -1 is not a duration"),
            (3, "spread 0 is negative (-0.1)"),
            (4, "2 spreads for 1 outputs"),
        ]
    );
    assert_eq!(load.loaded, 2);
    for a in [2.0, 3.0, 4.0] {
        assert!(store.get("t0", &names(), &[a, 1.0]).is_none(), "a = {a}");
    }
    let kept = store.get("t0", &names(), &[5.0, 1.0]).unwrap();
    assert_eq!(kept.result().unwrap().spread, Some(vec![0.1]));
}

#[test]
fn a_run_no_reader_could_take_back_is_refused_before_it_is_written() {
    let path = journal_of("journal-refused", &[0.5]);
    let store = RunStore::open(&path, "m1").unwrap();
    let before = lines(&path);
    let refused = [
        store.record("t0", &names(), &[0.6, 1.0], &ok(&[f64::NAN]), 0.1),
        store.record("t0", &names(), &[f64::INFINITY, 1.0], &ok(&[1.0]), 0.1),
        store.record("t0", &names(), &[0.6], &ok(&[1.0]), 0.1),
        store.record("t0", &names(), &[0.6, 1.0], &ok(&[1.0]), -1.0),
    ];
    let reasons = [
        "output 0 is not finite (NaN)",
        "parameter 0 is not finite (inf)",
        "1 parameter values for 2 names",
        "wall_s -1 is not a duration",
    ];
    for (r, why) in refused.into_iter().zip(reasons) {
        let e = r.unwrap_err().to_string();
        assert!(e.contains("not recorded") && e.contains(why), "{e}");
    }
    // Nothing was written, and the journal still opens with its one run.
    assert_eq!(lines(&path), before);
    drop(store);
    let store = RunStore::open(&path, "m1").unwrap();
    assert_eq!(store.len(), 1);
}

/// A journal open in one store cannot be opened by a second until the first is gone:
/// two calibrations appending to one file would each run what the other ran.
#[test]
fn a_journal_in_use_is_refused_until_it_is_closed() {
    let path = journal_of("in-use", &[1.0]);
    let first = RunStore::open(&path, "m1").unwrap();
    let err = RunStore::open(&path, "m1").unwrap_err().to_string();
    assert!(
        err.contains("runs.jsonl: another calibration has it open"),
        "{err}"
    );
    drop(first);
    let again = RunStore::open(&path, "m1").unwrap();
    assert!(again.get("t0", &names(), &[1.0, 1.0]).is_some());
}

/// A model whose fingerprint changed (what it covers, not what the model computes) reads
/// the runs journaled under the old one, given as an alias; other models' runs stay
/// ignored, and new runs are journaled under the new fingerprint.
#[test]
fn a_store_opened_with_an_alias_reads_the_aliases_lines_as_its_own() {
    let path = journal_of("journal-alias", &[1.0, 2.0]);
    {
        let other = RunStore::open(&path, "another model").unwrap();
        other
            .record("t0", &names(), &[3.0, 1.0], &ok(&[3.0]), 0.0)
            .unwrap();
    }
    // Without the alias, the old runs are another model's.
    let plain = RunStore::open(&path, "m2").unwrap();
    assert_eq!(plain.load_report().other_fingerprint, 3);
    assert!(plain.get("t0", &names(), &[1.0, 1.0]).is_none());
    drop(plain);

    let aliases = ["m1".to_string()];
    let store = RunStore::open_with_aliases(&path, "m2", &aliases, false).unwrap();
    let load = store.load_report();
    assert_eq!((load.loaded, load.other_fingerprint), (2, 1), "{load:?}");
    for a in [1.0, 2.0] {
        let hit = store
            .get("t0", &names(), &[a, 1.0])
            .expect("an alias's run");
        assert_eq!(hit.outputs, Some(vec![a]));
    }
    assert!(store.get("t0", &names(), &[3.0, 1.0]).is_none());
    assert_eq!(store.fingerprint(), "m2");
    let new = store
        .record("t0", &names(), &[4.0, 1.0], &ok(&[4.0]), 0.0)
        .unwrap();
    assert_eq!(new.fingerprint, "m2");
    drop(store);
    let last = lines(&path).pop().unwrap();
    assert!(last.contains(r#""fingerprint":"m2""#), "{last}");
    // Reopened, old and new lines alike are the model's.
    let again = RunStore::open_with_aliases(&path, "m2", &aliases, true).unwrap();
    assert_eq!(again.load_report().loaded, 3);
    assert_eq!(again.load_report().other_fingerprint, 1);
}
