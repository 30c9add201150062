//! Synthetic halls with a hidden truth: presets `demo`, `hall-a`, `hall-b`.
//!
//! [`generate`] draws, from one seed, a hall layout (rows of 42U racks in pairs around
//! hot aisles, CRACs at the row ends, a raised floor with a tile before each rack, ceiling
//! returns over the hot aisles, sensors at inlets and behind exhausts), true server air
//! flows (a per-type alpha times a +-3 % per-server jitter), operating snapshots that vary
//! fan speeds, setpoints and powers, and the readings: the built-in simulator at the true
//! alphas and any hidden effects on a grid finer than the model's default (so that
//! model-form error exists), plus seeded Gaussian noise rounded to 0.01 C.
//!
//! `hall.json` carries a plausible but wrong initial alpha (one value for every type) and
//! no effects; the truth, hidden effects included, goes to `truth.json` only.
//!
//! Seeds: the layout, the powers, the true alphas, the operating states and the noise
//! each draw from their own stream of the seed, so that changing the number of snapshots
//! or the noise leaves the hall itself unchanged.
//!
//! ```no_run
//! use kalibre_dc::synth::{generate, write_dir, Preset, SynthOptions};
//! let opts = SynthOptions::new(Preset::Demo, 7).with_noise_c(0.15);
//! let synth = generate(&opts)?;
//! write_dir(std::path::Path::new("out/demo-7"), &synth)?;
//! # Ok::<(), kalibre_dc::Error>(())
//! ```

mod catalogue;
mod effect_arg;
mod layout;
mod measure;
mod operate;
mod preset;
mod truth;

use std::path::Path;

use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

pub use effect_arg::parse_effect_arg;
pub use preset::Preset;
pub use truth::{
    GridInfo, HiddenEffect, InitialAlpha, Noise, ReferenceErrors, ServerAlpha, Truth,
    TruthSnapshot, TRUTH_SCHEMA,
};

use crate::hall::{EffectSpec, Hall};
use crate::snapshots::HallSnapshot;
use crate::{Error, Result};

/// Default measurement noise (C).
pub const DEFAULT_NOISE_C: f64 = 0.2;
/// Default number of snapshots.
pub const DEFAULT_SNAPSHOTS: usize = 3;

/// The most snapshots one synthetic hall gets.
pub const MAX_SNAPSHOTS: usize = 1000;

/// The most sensor noise (standard deviation, C) a synthetic hall gets.
pub const MAX_NOISE_C: f64 = 10.0;

/// What to generate.
///
/// | field | default | meaning |
/// |---|---|---|
/// | `preset` | `demo` | layout size |
/// | `seed` | 0 | the one seed everything is drawn from |
/// | `effects` | none | effects hidden in the measurements (`truth.json` only) |
/// | `noise_c` | 0.2 | Gaussian sensor noise (C), `>= 0` |
/// | `snapshots` | 3 | operating states, `>= 1` |
/// | `containment` | true | hot-aisle containment (leaky panels, as the simulator models them) |
/// | `model_cell_m` | simulator default | grid of the reference model runs |
/// | `measurement_cell_m` | preset default | grid of the measurement simulation: 0.1 m for `demo`, 0.15 m for the halls, see [`SynthOptions::measurement_cell`] |
/// | `initial_alpha` | preset policy | the `hall.json` initial alpha of every type, in `[0.01, 3]` |
/// | `reference_runs` | true | also run the model on its default grid (uncalibrated and at truth) and record its errors |
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Layout preset.
    pub preset: Preset,
    /// Seed.
    pub seed: u64,
    /// Hidden effects.
    pub effects: Vec<EffectSpec>,
    /// Noise standard deviation (C).
    pub noise_c: f64,
    /// Number of snapshots.
    pub snapshots: usize,
    /// Hot-aisle containment on or off.
    pub containment: bool,
    /// Cell size of the reference model runs (m); `None` is the simulator's default.
    pub model_cell_m: Option<f64>,
    /// Cell size of the measurement simulation (m); `None` is the preset's default.
    pub measurement_cell_m: Option<f64>,
    /// Initial alpha written for every type (cfm/W); `None` is the preset's policy.
    pub initial_alpha: Option<f64>,
    /// Run the reference model runs.
    pub reference_runs: bool,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions::new(Preset::Demo, 0)
    }
}

impl SynthOptions {
    /// Defaults for `preset` and `seed`.
    pub fn new(preset: Preset, seed: u64) -> Self {
        SynthOptions {
            preset,
            seed,
            effects: Vec::new(),
            noise_c: DEFAULT_NOISE_C,
            snapshots: DEFAULT_SNAPSHOTS,
            containment: true,
            model_cell_m: None,
            measurement_cell_m: None,
            initial_alpha: None,
            reference_runs: true,
        }
    }

    /// Adds a hidden effect.
    pub fn with_effect(mut self, effect: EffectSpec) -> Self {
        self.effects.push(effect);
        self
    }

    /// Sets the noise (C).
    pub fn with_noise_c(mut self, sigma_c: f64) -> Self {
        self.noise_c = sigma_c;
        self
    }

    /// Sets the number of snapshots.
    pub fn with_snapshots(mut self, count: usize) -> Self {
        self.snapshots = count;
        self
    }

    /// Turns hot-aisle containment on or off.
    pub fn with_containment(mut self, on: bool) -> Self {
        self.containment = on;
        self
    }

    /// Sets the reference model's cell size (m).
    pub fn with_model_cell_m(mut self, cell_m: f64) -> Self {
        self.model_cell_m = Some(cell_m);
        self
    }

    /// Sets the measurement simulation's cell size (m).
    pub fn with_measurement_cell_m(mut self, cell_m: f64) -> Self {
        self.measurement_cell_m = Some(cell_m);
        self
    }

    /// Sets the initial alpha of every type in `hall.json` (cfm/W).
    pub fn with_initial_alpha(mut self, alpha_cfm_per_w: f64) -> Self {
        self.initial_alpha = Some(alpha_cfm_per_w);
        self
    }

    /// Turns the reference model runs on or off.
    pub fn with_reference_runs(mut self, on: bool) -> Self {
        self.reference_runs = on;
        self
    }

    /// Checks the options.
    pub fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Mismatch(format!("synth options: {m}")));
        if !(self.noise_c.is_finite() && self.noise_c >= 0.0) {
            return bad(format!(
                "noise_c must be finite and >= 0, got {}",
                crate::snapshots::number(self.noise_c)
            ));
        }
        // Readings beyond [-50, 150] C would be refused by every reader of the file.
        if self.noise_c > MAX_NOISE_C {
            return bad(format!(
                "noise_c must be at most {MAX_NOISE_C} C (a sensor noisier is no sensor), got {}",
                crate::snapshots::number(self.noise_c)
            ));
        }
        if !(1..=MAX_SNAPSHOTS).contains(&self.snapshots) {
            return bad(format!(
                "snapshots must lie in [1, {MAX_SNAPSHOTS}] (each is a fine-grid solve), got {}",
                self.snapshots
            ));
        }
        for (name, v) in [
            ("model_cell_m", self.model_cell_m),
            ("measurement_cell_m", self.measurement_cell_m),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && (0.02..=1.0).contains(&v)) {
                    return bad(format!("{name} must lie in [0.02, 1] m, got {v}"));
                }
            }
        }
        if let Some(a) = self.initial_alpha {
            if !(a.is_finite() && (ALPHA_MIN..=ALPHA_MAX).contains(&a)) {
                return bad(format!(
                    "initial_alpha must lie in [{ALPHA_MIN}, {ALPHA_MAX}] cfm/W, got {a}"
                ));
            }
        }
        Ok(())
    }

    /// The reference model's cell size (m).
    pub fn model_cell(&self) -> f64 {
        self.model_cell_m
            .unwrap_or_else(|| crate::sim::SimConfig::default().cell_m)
    }

    /// The measurement simulation's cell size (m): half the model's for `demo` (0.1 m at
    /// the default 0.2 m); three quarters of it for `hall-a` and `hall-b` (0.15 m), which
    /// keeps generation to about 30-50 s of CPU in a release build and the model-form
    /// floor (model at the true alphas against the measurements) near 0.35 C; at two
    /// thirds (0.133 m) hall-b's floor was 0.48 C.
    pub fn measurement_cell(&self) -> f64 {
        self.measurement_cell_m.unwrap_or_else(|| {
            let model = self.model_cell();
            match self.preset {
                Preset::Demo => model / 2.0,
                Preset::HallA | Preset::HallB => model * 0.75,
            }
        })
    }
}

/// Alpha bounds written into `hall.json` (cfm/W), as in the paper.
pub const ALPHA_MIN: f64 = 0.01;
/// Upper alpha bound (cfm/W).
pub const ALPHA_MAX: f64 = 3.0;

/// A generated hall with its snapshots and its hidden truth.
#[derive(Debug, Clone)]
pub struct Synthesised {
    /// The hall as `hall.json` describes it (initial alpha guessed, no effects).
    pub hall: Hall,
    /// Operating states with noisy readings.
    pub snapshots: Vec<HallSnapshot>,
    /// The hidden truth.
    pub truth: Truth,
}

/// Seed streams: each purpose draws from its own generator.
#[derive(Clone, Copy)]
enum Stream {
    Layout = 1,
    Power = 2,
    Alpha = 3,
    States = 4,
    Noise = 5,
}

/// The seed of a stream.
fn stream_seed(seed: u64, stream: Stream) -> u64 {
    seed ^ (stream as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

fn rng(seed: u64, stream: Stream) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(stream_seed(seed, stream))
}

/// The hall with its hidden parts: true alphas and nominal powers.
struct Drawn {
    hall: Hall,
    alpha: operate::TrueAlpha,
    nominal_power_w: Vec<f64>,
    initial: InitialAlpha,
}

fn draw_hall(options: &SynthOptions) -> Result<Drawn> {
    options.check()?;
    let spec = options.preset.layout();
    let name = format!("{}-{}", options.preset, options.seed);
    let layout::Layout { mut hall, types } = layout::build(
        &name,
        &spec,
        layout::LayoutOptions {
            containment: options.containment,
        },
        &mut rng(options.seed, Stream::Layout),
    )?;
    let nominal_power_w =
        operate::draw_nominal_power(&mut rng(options.seed, Stream::Power), &hall, &types);
    let alpha = operate::draw_true_alpha(&mut rng(options.seed, Stream::Alpha), &hall);
    operate::set_rated_flows(&mut hall, &alpha.per_server, &nominal_power_w);
    let initial = initial_alpha(options, &alpha, &nominal_power_w);
    for t in &mut hall.server_types {
        t.alpha_cfm_per_w.initial = initial.value_cfm_per_w;
        t.alpha_cfm_per_w.min = ALPHA_MIN;
        t.alpha_cfm_per_w.max = ALPHA_MAX;
    }
    hall.validate("synthetic hall.json")?;
    Ok(Drawn {
        hall,
        alpha,
        nominal_power_w,
        initial,
    })
}

/// The hall alone (geometry, CRAC ratings, initial alpha), without simulating: the same
/// hall [`generate`] returns for these options.
pub fn generate_hall(options: &SynthOptions) -> Result<Hall> {
    Ok(draw_hall(options)?.hall)
}

/// Generates a synthetic hall, its snapshots and its truth.
pub fn generate(options: &SynthOptions) -> Result<Synthesised> {
    let Drawn {
        hall,
        alpha,
        nominal_power_w,
        initial,
    } = draw_hall(options)?;
    let states = operate::draw_states(
        &mut rng(options.seed, Stream::States),
        &hall,
        &alpha.per_server,
        &nominal_power_w,
        options.snapshots,
    );
    let measured = measure::measure(
        &hall,
        &states,
        &alpha,
        options,
        initial,
        stream_seed(options.seed, Stream::Noise),
        &mut rng(options.seed, Stream::Noise),
    )?;
    Ok(Synthesised {
        hall,
        snapshots: measured.snapshots,
        truth: measured.truth,
    })
}

/// The initial alpha written for every type: one common value, [`INITIAL_OVER_TRUE`]
/// times the power-weighted mean true alpha, rounded to 0.01 cfm/W. It stands for a
/// modeller's nameplate estimate (fans at full speed) that over-states every server's
/// flow, so the uncalibrated model moves too much air and misplaces the differences
/// between types, as in the paper's halls and the OpenFOAM development data (0.25 cfm/W
/// against true 0.12-0.17). Tied to the truth so that the uncalibrated error lands in the
/// paper's 2-6 C whatever the seed draws.
fn initial_alpha(
    options: &SynthOptions,
    alpha: &operate::TrueAlpha,
    nominal_power_w: &[f64],
) -> InitialAlpha {
    if let Some(v) = options.initial_alpha {
        return InitialAlpha {
            value_cfm_per_w: v,
            policy: "given".into(),
        };
    }
    let power: f64 = nominal_power_w.iter().sum();
    let mean = alpha
        .per_server
        .iter()
        .zip(nominal_power_w)
        .map(|(a, p)| a * p)
        .sum::<f64>()
        / power.max(f64::MIN_POSITIVE);
    let value = operate::round_to(INITIAL_OVER_TRUE * mean, 0.01).clamp(ALPHA_MIN, ALPHA_MAX);
    InitialAlpha {
        value_cfm_per_w: value,
        policy: format!(
            "common value for every type: {INITIAL_OVER_TRUE} x the power-weighted mean true \
             alpha ({mean:.4} cfm/W), rounded to 0.01"
        ),
    }
}

/// The default initial alpha over the power-weighted mean true alpha.
pub const INITIAL_OVER_TRUE: f64 = 1.3;

/// Writes `hall.json`, `snapshots.csv` and `truth.json` into `dir` (created if needed).
pub fn write_dir(dir: &Path, synth: &Synthesised) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let write = |name: &str, text: String| {
        let path = dir.join(name);
        kalibre_core::write_atomic(&path, text).map_err(|e| Error::io(&path, e))
    };
    synth.hall.save(&dir.join("hall.json"))?;
    write(
        "snapshots.csv",
        crate::snapshots::write_snapshots(&synth.hall, &synth.snapshots),
    )?;
    let truth = serde_json::to_string_pretty(&synth.truth)
        .map_err(|e| Error::Mismatch(format!("truth.json: cannot serialise: {e}")))?;
    write("truth.json", truth + "\n")
}
