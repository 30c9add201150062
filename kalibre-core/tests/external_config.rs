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
