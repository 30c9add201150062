//! The heat exchanger of the model-of-your-own tests: a small Python program
//! (effectiveness-NTU) driven through `model.toml`, with noise-free measurements made by
//! running it at a known truth.

#![allow(dead_code)] // each test file uses its own part

use std::path::{Path, PathBuf};

use super::cli_support::{kalibre, tmp};

/// A counter-flow heat exchanger: `UA = UA0 * m_hot^n`, and a heat loss `loss` (W/K) of
/// the hot stream to 20 C ambient before it enters.
pub const MODEL_PY: &str = r#"import math, sys
v = {}
for line in open(sys.argv[1]):
    if "=" in line:
        k, x = line.split("=")
        v[k.strip()] = float(x)
if v["m_hot"] <= 0:
    sys.exit("m_hot must be positive")
cp = 4180.0
ch, cc = v["m_hot"] * cp, v["m_cold"] * cp
th = v["t_hot_in"] - v["loss"] * (v["t_hot_in"] - 20.0) / ch
ua = v["UA0"] * v["m_hot"] ** v["n"]
cmin, cmax = min(ch, cc), max(ch, cc)
cr, ntu = cmin / cmax, ua / cmin
eps = (1 - math.exp(-ntu * (1 - cr))) / (1 - cr * math.exp(-ntu * (1 - cr)))
q = eps * cmin * (th - v["t_cold_in"])
with open(sys.argv[2], "w") as f:
    f.write("t_hot_out,t_cold_out,q_kw\n")
    f.write("%.9f,%.9f,%.9f\n" % (th - q / ch, v["t_cold_in"] + q / cc, q / 1000))
"#;

pub const TEMPLATE: &str = "UA0 = {{UA0}}\nn = {{n}}\nloss = {{loss}}\nm_hot = {{m_hot}}\n\
m_cold = {{m_cold}}\nt_hot_in = {{t_hot_in}}\nt_cold_in = {{t_cold_in}}\n";

pub const MODEL_TOML: &str = r#"description = "counter-flow heat exchanger"
program = "python3"
args = ["{{config_dir}}/hx.py", "params.in", "out.csv"]
runs_root = "runs"
timeout_s = 30
fingerprint_files = ["hx.py"]

[[templates]]
source = "params.in.tmpl"
destination = "params.in"

[output]
file = "out.csv"
parser = "csv"
names = ["t_hot_out", "t_cold_out", "q_kw"]

[[params]]
name = "UA0"
lower = 1000.0
upper = 20000.0
initial = 3000.0
scale = "log"

[[params]]
name = "n"
lower = 0.2
upper = 1.0
initial = 0.5

[[params]]
name = "loss"
lower = 0.0
upper = 500.0
initial = 100.0

[[scenarios]]
label = "low"
variables = { m_hot = 0.5, m_cold = 0.6, t_hot_in = 70.0, t_cold_in = 12.0 }

[[scenarios]]
label = "mid"
variables = { m_hot = 1.0, m_cold = 0.8, t_hot_in = 80.0, t_cold_in = 15.0 }

[[scenarios]]
label = "high"
variables = { m_hot = 2.0, m_cold = 1.5, t_hot_in = 85.0, t_cold_in = 15.0 }

[[scenarios]]
label = "unbalanced"
variables = { m_hot = 1.5, m_cold = 0.4, t_hot_in = 60.0, t_cold_in = 10.0 }
"#;

/// The truth the measurements are made at.
pub const TRUTH: [(&str, f64); 3] = [("UA0", 5000.0), ("n", 0.6), ("loss", 150.0)];

/// The model's directory (`hx.py`, its template and `model.toml`) and noise-free
/// measurements of every scenario at the truth, made by running the model itself.
pub fn setup(name: &str) -> (PathBuf, PathBuf, PathBuf) {
    setup_with(name, MODEL_PY, TEMPLATE, MODEL_TOML, &TRUTH)
}

/// [`setup`] with another script, template, `model.toml` and truth.
pub fn setup_with(
    name: &str,
    script: &str,
    template: &str,
    model_toml: &str,
    truth: &[(&str, f64)],
) -> (PathBuf, PathBuf, PathBuf) {
    let dir = tmp(name);
    std::fs::write(dir.join("hx.py"), script).unwrap();
    std::fs::write(dir.join("params.in.tmpl"), template).unwrap();
    let config = dir.join("model.toml");
    std::fs::write(&config, model_toml).unwrap();
    let scenarios = [
        ("low", [0.5, 0.6, 70.0, 12.0]),
        ("mid", [1.0, 0.8, 80.0, 15.0]),
        ("high", [2.0, 1.5, 85.0, 15.0]),
        ("unbalanced", [1.5, 0.4, 60.0, 10.0]),
    ];
    let mut rows = String::from("scenario,output,value\n");
    for (label, [mh, mc, th, tc]) in scenarios {
        let input = dir.join(format!("truth-{label}.in"));
        let mut text: String = truth.iter().map(|(k, v)| format!("{k} = {v}\n")).collect();
        text += &format!("m_hot = {mh}\nm_cold = {mc}\nt_hot_in = {th}\nt_cold_in = {tc}\n");
        std::fs::write(&input, text).unwrap();
        let output = dir.join(format!("truth-{label}.csv"));
        let o = std::process::Command::new("python3")
            .arg(dir.join("hx.py"))
            .arg(&input)
            .arg(&output)
            .output()
            .expect("python3 runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let out = std::fs::read_to_string(&output).unwrap();
        let mut lines = out.lines();
        let names: Vec<&str> = lines.next().unwrap().split(',').collect();
        let values: Vec<&str> = lines.next().unwrap().split(',').collect();
        for (n, v) in names.iter().zip(values) {
            rows += &format!("{label},{n},{v}\n");
        }
    }
    let measurements = dir.join("measurements.csv");
    std::fs::write(&measurements, rows).unwrap();
    (dir, config, measurements)
}

pub fn calibrate(config: &Path, measurements: &Path, out: &Path) -> std::process::Command {
    let mut c = kalibre();
    c.args(["calibrate", "--model", "command", "--config"])
        .arg(config)
        .arg("--measurements")
        .arg(measurements)
        .arg("--out")
        .arg(out)
        .args(["--seed", "1", "--threads", "2", "--quiet"]);
    c
}

pub fn report(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}
