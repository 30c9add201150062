//! The external command model's configuration file (`model.toml`, docs/models.md): the
//! documented example loads and runs, errors name the key, scenarios given elsewhere,
//! and paths that mean the same inside a run directory.

use std::path::PathBuf;

use kalibre_core::external::{CommandModelConfig, ExternalError};
use kalibre_core::Model;

mod external_support;
use external_support::{fixture, scratch};

/// Copies the example configuration and its files into a scratch directory.
fn example_config(test: &str) -> (PathBuf, String) {
    let dir = scratch(test);
    for f in ["model.toml", "model.py", "params.in.tmpl"] {
        std::fs::copy(fixture(f), dir.join(f)).unwrap();
    }
    let text = std::fs::read_to_string(dir.join("model.toml")).unwrap();
    (dir, text)
}

#[test]
fn example_config_loads_and_runs() {
    let (dir, _) = example_config("config_example");
    let cfg = CommandModelConfig::load(dir.join("model.toml")).unwrap();
    assert_eq!(cfg.space.names(), ["k", "h"]);
    assert_eq!(cfg.command.output_names(), ["t_in", "t_out"]);
    assert_eq!(cfg.command.retry().max_attempts, 2);
    assert_eq!(cfg.command.runs_root(), dir.join("runs"));
    let labels: Vec<_> = cfg.scenarios.iter().map(|s| s.label.as_str()).collect();
    assert_eq!(labels, ["winter", "summer"]);
    let x = cfg.space.initial();
    for (s, ambient) in cfg.scenarios.iter().zip([5.0, 30.0]) {
        let out = cfg.command.evaluate(s, &x).unwrap();
        let t_in = ambient + 0.5 * 2.5;
        assert_eq!(out.values, vec![t_in, t_in + 1000.0 / 25.0]);
    }
    // Editing the script changes the fingerprint (fingerprint_files).
    let before = cfg.command.fingerprint();
    std::fs::write(dir.join("model.py"), "# edited\n").unwrap();
    let after = CommandModelConfig::load(dir.join("model.toml")).unwrap();
    assert_ne!(before, after.command.fingerprint());
}

#[test]
fn config_errors_name_the_key() {
    let (dir, text) = example_config("config_errors");
    let file = dir.join("model.toml");
    let key_of = |edited: String| match CommandModelConfig::from_toml_str(&edited, &file) {
        Err(ExternalError::Config { key, file: f, .. }) => {
            assert_eq!(f, file.display().to_string());
            key
        }
        Err(e) => panic!("not a config error: {e}"),
        Ok(_) => panic!("accepted a bad config"),
    };
    // Each edit of the example and the key its error names.
    let edits: [(&str, &str, &str); 15] = [
        ("timeout_s = 30", "timout_s = 30", "timout_s"),
        ("timeout_s = 30\n", "", "timeout_s"),
        ("timeout_s = 30", "timeout_s = -1", "timeout_s"),
        ("upper = 100.0", "upper = \"high\"", "params[1].upper"),
        ("initial = 10.0", "initial = 1000.0", "params[1]"),
        ("scale = \"log\"", "scale = \"ln\"", "params[0].scale"),
        ("parser = \"csv\" ", "parser = \"json\"", "output.parser"),
        (
            "retry_on = [\"timeout\", \"exit\"]",
            "retry_on = [\"timeout\", \"segfault\"]",
            "retry_on[1]",
        ),
        (
            "destination = \"params.in\"",
            "destination = \"../escape.in\"",
            "templates[0].destination",
        ),
        (
            "source = \"params.in.tmpl\"",
            "source = \"missing.tmpl\"",
            "templates[0].source",
        ),
        (
            "parser = \"csv\" ",
            "parser = \"regex\"\nregex = { t_in = 'a(b)(c)', t_out = 'x(y)' }\n",
            "output.regex.t_in",
        ),
        (
            "variables = { ambient_c = 5.0 }",
            "variables = { ambient_c = 5.0, k = 1.0 }",
            "scenarios[0].variables",
        ),
        (
            "label = \"summer\"",
            "label = \"winter\"",
            "scenarios[1].label",
        ),
        ("timeout_s = 30", "timeout_s = 30 30", "line 6"),
        // A failure that repeats every time would be retried without end.
        ("retries = 1 ", "retries = 1000000000 ", "retries"),
    ];
    for (from, to, key) in edits {
        assert!(text.contains(from), "the example lacks `{from}`");
        assert_eq!(key_of(text.replace(from, to)), key, "{from} -> {to}");
    }
    // A placeholder no scenario provides names its template, and the first scenario
    // that lacks it (others may set it).
    std::fs::write(dir.join("params.in.tmpl"), "k = {{k}}\nx = {{ambient}}\n").unwrap();
    match CommandModelConfig::load(&file).unwrap_err() {
        ExternalError::Template {
            file: template,
            placeholder,
            reason,
            ..
        } => {
            assert!(
                template.ends_with("params.in.tmpl") && placeholder == "ambient",
                "{template} {placeholder}"
            );
            assert!(
                reason.ends_with(&format!(
                    "in scenario `winter` (scenarios[0].variables of {})",
                    file.display()
                )),
                "{reason}"
            );
        }
        e => panic!("{e}"),
    }
    // So does a number's format on a text value, before any run.
    std::fs::write(dir.join("params.in.tmpl"), "k = {{k}}\n# {{scenario:.3}}\n").unwrap();
    match CommandModelConfig::load(&file).unwrap_err() {
        ExternalError::Template {
            line, placeholder, ..
        } => assert_eq!((line, placeholder.as_str()), (2, "scenario:.3")),
        e => panic!("{e}"),
    }
}

/// Where the scenarios come from elsewhere, a `[[scenarios]]` list is refused as such
/// (not for a variable its entries lack), and a file without one loads as with `load`.
#[test]
fn a_file_whose_scenarios_come_from_elsewhere_refuses_a_scenarios_list() {
    let (dir, text) = example_config("config_no_scenarios");
    let file = dir.join("model.toml");
    match CommandModelConfig::load_without_scenarios(&file, "the snapshots are the scenarios")
        .unwrap_err()
    {
        ExternalError::Config { key, reason, .. } => {
            assert_eq!(key, "scenarios");
            assert_eq!(reason, "the snapshots are the scenarios");
        }
        e => panic!("{e}"),
    }
    let without = &text[..text
        .find("[[scenarios]]")
        .expect("the example lists scenarios")];
    std::fs::write(&file, without).unwrap();
    let cfg = CommandModelConfig::load_without_scenarios(&file, "unused").unwrap();
    assert!(cfg.scenarios.is_empty());
    assert_eq!(
        cfg.space.names(),
        CommandModelConfig::load(&file).unwrap().space.names()
    );
}

/// A config named by a relative path still gives the program absolute paths: the program
/// runs inside its run directory, where `{{run_dir}}` and `KALIBRE_RUN_DIR` relative to
/// kalibre's directory would name nothing (they did).
#[test]
fn a_config_by_relative_path_gives_the_program_absolute_run_dirs() {
    let (dir, text) = example_config("config_relative");
    std::fs::write(
        dir.join("check.sh"),
        "case \"$1\" in /*) ;; *) echo \"run_dir $1\" >&2; exit 3;; esac\n\
         case \"$KALIBRE_RUN_DIR\" in /*) ;; *) echo \"env $KALIBRE_RUN_DIR\" >&2; exit 4;; esac\n\
         test -f \"$1/params.in\" || exit 5\n\
         exec python3 \"$2\" params.in out.csv\n",
    )
    .unwrap();
    let text = text
        .replace("program = \"python3\"", "program = \"sh\"")
        .replace(
            "args = [\"{{config_dir}}/model.py\", \"params.in\", \"out.csv\"]",
            "args = [\"{{config_dir}}/check.sh\", \"{{run_dir}}\", \"{{config_dir}}/model.py\"]",
        );
    assert!(text.contains("check.sh"), "the example's args changed");
    std::fs::write(dir.join("model.toml"), text).unwrap();
    // The same file by a path relative to this process's directory.
    let cwd = std::env::current_dir().unwrap();
    let mut relative = PathBuf::new();
    for _ in 1..cwd.components().count() {
        relative.push("..");
    }
    relative.push(
        dir.strip_prefix("/")
            .expect("an absolute scratch directory"),
    );
    assert!(relative.is_relative());
    let cfg = CommandModelConfig::load(relative.join("model.toml")).unwrap();
    assert!(
        cfg.command.runs_root().is_absolute(),
        "{:?}",
        cfg.command.runs_root()
    );
    let out = cfg
        .command
        .evaluate(&cfg.scenarios[0], &cfg.space.initial())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(out.values.len(), 2);
}

/// The key and the whole message of the error a config text gets; the message must be
/// one line naming the file and the key.
fn refusal(text: &str, file: &std::path::Path) -> (String, String) {
    match CommandModelConfig::from_toml_str(text, file) {
        Err(e @ ExternalError::Config { .. }) => {
            let ExternalError::Config { key, file: f, .. } = &e else {
                unreachable!()
            };
            assert_eq!(*f, file.display().to_string());
            let message = e.to_string();
            assert!(
                !message.contains('\n') && message.starts_with(&format!("{f}: `{key}`: ")),
                "not one line naming the file and the key: {message:?}"
            );
            // A refused control character is named, not printed.
            assert!(
                !message.chars().any(|c| c.is_control()),
                "prints a control character: {message:?}"
            );
            (key.clone(), message)
        }
        Err(e) => panic!("not a config error: {e}"),
        Ok(_) => panic!("accepted a bad config:\n{text}"),
    }
}

/// Scenario labels follow the rules of a hall's snapshot labels (`snapshots.csv`):
/// non-empty, no control character, no space at either end, at most 200 characters. An
/// empty label was accepted, and a measurements row with an empty scenario matched it.
#[test]
fn scenario_labels_follow_the_snapshot_label_rules() {
    let (dir, text) = example_config("config_labels");
    let file = dir.join("model.toml");
    let long = "w".repeat(201);
    let edits = [
        ("label = \"\"", "non-empty"),
        ("label = \"win\\u0007ter\"", "control character (U+0007)"),
        ("label = \"win\tter\"", "control character (U+0009)"),
        ("label = \" winter\"", "starts or ends with a space"),
        ("label = \"winter \"", "starts or ends with a space"),
        (&format!("label = \"{long}\"")[..], "at most 200"),
    ];
    for (to, why) in edits {
        let (key, message) = refusal(&text.replace("label = \"winter\"", to), &file);
        assert_eq!(key, "scenarios[0].label", "{to}");
        assert!(message.contains(why), "{to}: {message}");
    }
    // 200 characters are still a label.
    let ok = text.replace("label = \"winter\"", &format!("label = \"{}\"", &long[1..]));
    CommandModelConfig::from_toml_str(&ok, &file).unwrap();
}

/// A `runs_root` that is a file (or under one) failed every run with `cannot create a
/// run directory under .../model.py: File exists`, naming neither model.toml nor the key.
#[test]
fn a_runs_root_that_is_not_a_directory_is_refused_at_load() {
    let (dir, text) = example_config("config_runs_root");
    let file = dir.join("model.toml");
    for root in ["model.py", "model.py/runs"] {
        let edited = text.replace("runs_root = \"runs\"", &format!("runs_root = \"{root}\""));
        let (key, message) = refusal(&edited, &file);
        assert_eq!(key, "runs_root", "{root}");
        assert!(message.contains("not a directory"), "{message}");
    }
    // One that does not exist yet is made by the first run; an existing directory is used.
    std::fs::create_dir(dir.join("made")).unwrap();
    for root in ["not/yet", "made"] {
        let edited = text.replace("runs_root = \"runs\"", &format!("runs_root = \"{root}\""));
        CommandModelConfig::from_toml_str(&edited, &file).unwrap();
    }
}

/// A NUL byte cannot reach a program's argument list, its environment or a path: every
/// run failed with `nul byte found in provided data`. Refused at load, by key.
#[test]
fn nul_bytes_are_refused_at_load() {
    let (dir, text) = example_config("config_nul");
    let file = dir.join("model.toml");
    let edits = [
        (
            "args = [\"{{config_dir}}/model.py\", \"params.in\", \"out.csv\"]",
            "args = [\"{{config_dir}}/model.py\", \"params.in\", \"out.csv\", \"a\\u0000b\"]",
            "args[3]",
        ),
        (
            "program = \"python3\"",
            "program = \"python3\\u0000\"",
            "program",
        ),
        (
            "program = \"python3\"",
            "program = \"bin/python3\\u0000\"",
            "program",
        ),
        (
            "source = \"params.in.tmpl\"",
            "source = \"params.in.tmpl\\u0000\"",
            "templates[0].source",
        ),
        (
            "destination = \"params.in\"",
            "destination = \"params\\u0000.in\"",
            "templates[0].destination",
        ),
        (
            "runs_root = \"runs\"",
            "runs_root = \"ru\\u0000ns\"",
            "runs_root",
        ),
        (
            "OMP_NUM_THREADS = \"1\"",
            "OMP_NUM_THREADS = \"1\\u0000\"",
            "env.OMP_NUM_THREADS",
        ),
        (
            "file = \"out.csv\"",
            "file = \"out\\u0000.csv\"",
            "output.file",
        ),
        (
            "fingerprint_files = [\"model.py\"]",
            "fingerprint_files = [\"model.py\\u0000\"]",
            "fingerprint_files[0]",
        ),
    ];
    for (from, to, want) in edits {
        assert!(text.contains(from), "the example lacks `{from}`");
        let (key, message) = refusal(&text.replace(from, to), &file);
        assert_eq!(key, want, "{to}");
        assert!(message.contains("NUL"), "{message}");
    }
}

/// Parameter, output and variable names with a control character, and a name given
/// twice, are refused at load naming the entry's key.
#[test]
fn bad_or_repeated_names_are_refused_by_key() {
    let (dir, text) = example_config("config_names");
    let file = dir.join("model.toml");
    let edits = [
        (
            "name = \"k\"",
            "name = \"k\\u001b[31m\"",
            "params[0].name",
            "control character",
        ),
        (
            "name = \"h\"",
            "name = \"h\\t\"",
            "params[1].name",
            "control character",
        ),
        (
            "name = \"h\"",
            "name = \"k\"",
            "params[1].name",
            "duplicate",
        ),
        (
            "name = \"k\"",
            "name = \"k rod\"",
            "params[0].name",
            "cannot be written as a template placeholder",
        ),
        (
            "name = \"h\"",
            "name = \"h:1\"",
            "params[1].name",
            "expected e.g. `h_1`",
        ),
        (
            "names = [\"t_in\", \"t_out\"]",
            "names = [\"t_in\", \"t\\u0000out\"]",
            "output.names[1]",
            "control character",
        ),
        (
            "names = [\"t_in\", \"t_out\"]",
            "names = [\"t_in\", \"t_in\"]",
            "output.names[1]",
            "duplicate",
        ),
        (
            "variables = { ambient_c = 5.0 }",
            "variables = { ambient_c = 5.0, \"x\\u0007\" = 1.0 }",
            "scenarios[0].variables",
            "control character",
        ),
    ];
    for (from, to, want, why) in edits {
        assert!(text.contains(from), "the example lacks `{from}`");
        let (key, message) = refusal(&text.replace(from, to), &file);
        assert_eq!(key, want, "{to}");
        assert!(message.contains(why), "{to}: {message}");
    }
}
