//! Physical effects a model may lack, each with its own calibrated parameters.
//!
//! An [`Effect`] names its parameters (with bounds) and changes a simulator run by adding
//! entries to a [`SimMods`]. `hall.json` `effects` turns effects on; an
//! [`EffectRegistry`] builds them from their entries ([`from_spec`] uses the built-in
//! registry). A downstream crate adds a kind by implementing [`Effect`] and
//! [`EffectFactory`] and registering the factory.
//!
//! Built-in kinds (fields documented on each type):
//! `containment_leakage` ([`ContainmentLeakage`]), `bypass` ([`Bypass`]),
//! `crac_supply_offset` ([`CracSupplyOffset`]), `rack_recirculation`
//! ([`RackRecirculationEffect`]).
//!
//! Every parameter field takes the same shape: `"<name>": initial value` (optional, with
//! a default) and `"<name>_bounds": [lower, upper]` (optional, with default bounds that
//! the given bounds must lie within).

mod bypass;
pub(crate) mod fields;
mod leakage;
mod offset;
mod recirculation;

pub use bypass::{Bypass, BypassFactory, CANDIDATE_TILE_SHARE};
pub use fields::Fields;
pub use leakage::{ContainmentLeakage, ContainmentLeakageFactory};
pub use offset::{CracSupplyOffset, CracSupplyOffsetFactory};
pub use recirculation::{RackRecirculationEffect, RackRecirculationFactory};

use kalibre_core::Param;

use crate::hall::{Aabb, EffectSpec, Hall, GEOMETRY_TOL_M};
use crate::sim::SimMods;
use crate::{Error, Result};

/// How a surrogate represents an effect's parameters (completed with diagnosis).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum SurrogateTerm {
    /// A linear term in the effect's parameters, learned from model runs that vary them
    /// (the default for every kind until a knowledge-based block exists).
    LearnedLinear,
}

/// A physical effect added to the model.
pub trait Effect: Send + Sync + std::fmt::Debug {
    /// The kind, e.g. `bypass`.
    fn kind(&self) -> &str;

    /// Parameters, with names relative to the effect (e.g. `fraction`); the calibration
    /// names them `<kind>/<name>`.
    fn parameters(&self) -> Vec<Param>;

    /// The `hall.json` `effects` entry that recreates this effect.
    fn to_spec(&self) -> EffectSpec;

    /// Adds this effect's modifications of one simulator run, for parameter values in the
    /// order of [`Self::parameters`].
    fn modify(&self, values: &[f64], hall: &Hall, mods: &mut SimMods) -> Result<()>;

    /// The surrogate's term for this effect (hook for diagnosis, issue 6).
    fn surrogate_term(&self) -> SurrogateTerm {
        SurrogateTerm::LearnedLinear
    }
}

/// Builds effects of one kind from `hall.json` entries.
pub trait EffectFactory: Send + Sync {
    /// The kind this factory builds.
    fn kind(&self) -> &str;

    /// Builds an effect from its entry, checking every field against the hall.
    fn build(&self, spec: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>>;

    /// Candidate placements of this kind in a hall, as `effects` entries: the hypotheses
    /// a diagnosis tries (e.g. one per CRAC, per rack, per containment side); the default
    /// has none. The diagnosis linearises each candidate from its parameters at 0 (clamped
    /// into their bounds), so an effect must be absent there (a zero fraction, offset or
    /// opening).
    fn candidates(&self, _hall: &Hall) -> Vec<EffectSpec> {
        Vec::new()
    }

    /// What the effect is in a hall, in a few plain words for a diagnosis's listing
    /// (what to look for on the floor); the default says nothing.
    fn meaning(&self) -> &str {
        ""
    }
}

/// The set of known effect kinds.
pub struct EffectRegistry {
    factories: Vec<Box<dyn EffectFactory>>,
}

impl std::fmt::Debug for EffectRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EffectRegistry")
            .field("kinds", &self.kinds())
            .finish()
    }
}

impl Default for EffectRegistry {
    fn default() -> Self {
        Self::builtin()
    }
}

impl EffectRegistry {
    /// A registry with no kind.
    pub fn empty() -> Self {
        EffectRegistry {
            factories: Vec::new(),
        }
    }

    /// The four built-in kinds.
    pub fn builtin() -> Self {
        EffectRegistry {
            factories: vec![
                Box::new(ContainmentLeakageFactory),
                Box::new(BypassFactory),
                Box::new(CracSupplyOffsetFactory),
                Box::new(RackRecirculationFactory),
            ],
        }
    }

    /// Adds a kind; a kind already known is an error.
    pub fn register(&mut self, factory: Box<dyn EffectFactory>) -> Result<()> {
        if self.get(factory.kind()).is_some() {
            return Err(Error::Effect {
                kind: factory.kind().to_string(),
                message: "kind is already registered".into(),
            });
        }
        self.factories.push(factory);
        Ok(())
    }

    /// Builder form of [`Self::register`].
    pub fn with(mut self, factory: Box<dyn EffectFactory>) -> Result<Self> {
        self.register(factory)?;
        Ok(self)
    }

    /// Known kinds, in registration order.
    pub fn kinds(&self) -> Vec<&str> {
        self.factories.iter().map(|f| f.kind()).collect()
    }

    /// The factory of a kind.
    pub fn get(&self, kind: &str) -> Option<&dyn EffectFactory> {
        self.factories
            .iter()
            .find(|f| f.kind() == kind)
            .map(|f| f.as_ref())
    }

    /// Builds an effect from its entry.
    pub fn build(&self, spec: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
        match self.get(&spec.kind) {
            Some(f) => f.build(spec, hall),
            None => Err(Error::Effect {
                kind: spec.kind.clone(),
                message: format!("unknown effect kind (known: {})", self.kinds().join(", ")),
            }),
        }
    }

    /// Builds every entry of `hall.effects`, naming the entry index on error. Two entries
    /// of one kind in one place are refused ([`first_repeat`]), as are openings that could
    /// take the whole supply ([`first_oversubscribed`]).
    pub fn build_all(&self, hall: &Hall) -> Result<Vec<Box<dyn Effect>>> {
        let effects = self.build_each(hall)?;
        check_together(&effects, hall)?;
        Ok(effects)
    }

    fn build_each(&self, hall: &Hall) -> Result<Vec<Box<dyn Effect>>> {
        hall.effects
            .iter()
            .enumerate()
            .map(|(i, s)| {
                self.build(s, hall).map_err(|e| match e {
                    Error::Effect { kind, message } => Error::Effect {
                        kind,
                        message: format!("effects/{i}: {message}"),
                    },
                    other => other,
                })
            })
            .collect()
    }
}

/// What `effect` asks of a run at its parameters' upper bounds, so that no share or
/// flow is zero: every region where it acts, for checks and meshing before any run.
pub fn mods_at_upper_bounds(effect: &dyn Effect, hall: &Hall) -> Result<SimMods> {
    let upper: Vec<f64> = effect.parameters().iter().map(|p| p.upper).collect();
    let mut mods = SimMods::new(hall.cracs.len());
    effect.modify(&upper, hall, &mut mods)?;
    Ok(mods)
}

/// The placement of an effect entry: the entry without its parameters' values and
/// bounds, i.e. where and how the effect acts.
pub fn placement(spec: &EffectSpec, effect: &dyn Effect) -> EffectSpec {
    let mut spec = spec.clone();
    for p in effect.parameters() {
        spec.fields.remove(&p.name);
        spec.fields.remove(&format!("{}_bounds", p.name));
    }
    spec
}

/// The first pair `(earlier, later)` of effects with the same kind and placement (as
/// each writes itself, so a default written out or left off makes no difference). Two
/// such entries act as one: only the sum of their parameters could be calibrated.
pub fn first_repeat(effects: &[Box<dyn Effect>]) -> Option<(usize, usize)> {
    let placements: Vec<EffectSpec> = effects
        .iter()
        .map(|e| placement(&e.to_spec(), e.as_ref()))
        .collect();
    (1..placements.len()).find_map(|j| {
        (0..j)
            .find(|&i| placements[i] == placements[j])
            .map(|i| (i, j))
    })
}

/// The share of the supply that `effect`'s openings take at its parameters' upper
/// bounds (0 when it opens none, or when it cannot take its upper bounds: that is
/// reported where it is built).
pub fn supply_share_at_upper_bounds(effect: &dyn Effect, hall: &Hall) -> f64 {
    mods_at_upper_bounds(effect, hall).map_or(0.0, |m| m.supply_opening_share())
}

/// Where the effects' supply openings, each at its parameters' upper bounds, first take
/// the whole supply: the entry at which their shares reach 1, and each opening entry's
/// share so far. The tiles (or CRAC fronts) must deliver some of the supply, so such a
/// box holds points no run can take: a calibration would lose every run there (the
/// design's upper bounds among them).
pub fn first_oversubscribed(
    effects: &[Box<dyn Effect>],
    hall: &Hall,
) -> Option<(usize, Vec<(usize, f64)>)> {
    let mut parts = Vec::new();
    let mut total = 0.0;
    for (i, e) in effects.iter().enumerate() {
        let share = supply_share_at_upper_bounds(e.as_ref(), hall);
        if share > 0.0 {
            parts.push((i, share));
            total += share;
            if total >= 1.0 {
                return Some((i, parts));
            }
        }
    }
    None
}

/// The first two entries whose supply openings overlap on the floor, `(earlier, later)`,
/// with the overlap's `[x0, x1, y0, y1]` (m). Air entering the overlap could be either's,
/// as with overlapping tiles (refused when the hall is read), and the part of each
/// opening over the other would be counted twice.
pub fn first_overlapping_openings(
    effects: &[Box<dyn Effect>],
    hall: &Hall,
) -> Option<(usize, usize, [f64; 4])> {
    let regions: Vec<Vec<Aabb>> = effects
        .iter()
        .map(|e| supply_openings(e.as_ref(), hall))
        .collect();
    (1..effects.len()).find_map(|j| {
        (0..j).find_map(|i| openings_overlap(&regions[i], &regions[j]).map(|o| (i, j, o)))
    })
}

/// The floor regions where `effect` lets supply air in, at its upper bounds.
pub fn supply_openings(effect: &dyn Effect, hall: &Hall) -> Vec<Aabb> {
    mods_at_upper_bounds(effect, hall).map_or_else(
        |_| Vec::new(),
        |m| m.supply_openings.iter().map(|o| o.region).collect(),
    )
}

/// Where two sets of floor openings first overlap, as `[x0, x1, y0, y1]` (m). Openings
/// lie on the floor (no height), so they overlap where their plans do.
pub fn openings_overlap(a: &[Aabb], b: &[Aabb]) -> Option<[f64; 4]> {
    let overlap = |a: &Aabb, b: &Aabb| {
        let x = [a.min[0].max(b.min[0]), a.max[0].min(b.max[0])];
        let y = [a.min[1].max(b.min[1]), a.max[1].min(b.max[1])];
        (x[1] - x[0] > GEOMETRY_TOL_M && y[1] - y[0] > GEOMETRY_TOL_M)
            .then_some([x[0], x[1], y[0], y[1]])
    };
    a.iter()
        .flat_map(|p| b.iter().map(move |q| (p, q)))
        .find_map(|(p, q)| overlap(p, q))
}

/// The checks across the entries of a hall, each error naming the entry (and the field
/// to change) as [`EffectRegistry::build_all`]'s entry errors do.
fn check_together(effects: &[Box<dyn Effect>], hall: &Hall) -> Result<()> {
    if let Some((first, again)) = first_repeat(effects) {
        return Err(Error::Effect {
            kind: effects[again].kind().to_string(),
            message: format!("effects/{again}: {}", repeat_message(first)),
        });
    }
    if let Some((first, again, [x0, x1, y0, y1])) = first_overlapping_openings(effects, hall) {
        // To the millimetre of the geometry's tolerance: edges computed as sums read
        // 3.9000000000000004 otherwise.
        let n = |v: f64| crate::snapshots::number((v * 1000.0).round() / 1000.0);
        return Err(Error::Effect {
            kind: effects[again].kind().to_string(),
            message: format!(
                "effects/{again}: its floor opening overlaps effects/{first}'s (x {}-{} m, \
                 y {}-{} m): air entering there could be either's, so the two could not be \
                 told apart; make the openings disjoint, or keep one entry",
                n(x0),
                n(x1),
                n(y0),
                n(y1)
            ),
        });
    }
    if let Some((whole, at, per_crac)) = offset::offsets_set_twice(effects, hall) {
        let entries: Vec<String> = per_crac.iter().map(|j| format!("effects/{j}")).collect();
        return Err(Error::Effect {
            kind: effects[at].kind().to_string(),
            message: format!(
                "effects/{at}: with effects/{whole} (every CRAC) and {} (one CRAC each), \
                 every CRAC's supply offset is set twice: only each CRAC's sum acts, so \
                 the entries could not be told apart; drop the entry for every CRAC or \
                 one CRAC's entry",
                entries.join(", ")
            ),
        });
    }
    if let Some((at, parts)) = first_oversubscribed(effects, hall) {
        // The field to change: the bounds of the effect's one parameter, if one.
        let field = match effects[at].parameters().as_slice() {
            [p] => format!("field `{}_bounds`: ", p.name),
            _ => String::new(),
        };
        return Err(Error::Effect {
            kind: effects[at].kind().to_string(),
            message: format!("effects/{at}: {field}{}", oversubscribed_message(&parts)),
        });
    }
    Ok(())
}

fn oversubscribed_message(parts: &[(usize, f64)]) -> String {
    let terms: Vec<String> = parts
        .iter()
        .map(|(i, s)| format!("effects/{i} {}", crate::snapshots::number(*s)))
        .collect();
    let total: f64 = parts.iter().map(|(_, s)| s).sum();
    format!(
        "at their upper bounds the supply openings take the whole supply ({}: {} in all), \
         leaving the tiles none, so no run could be made there; lower an upper bound so \
         that the shares sum below 1",
        terms.join(", "),
        crate::snapshots::number(total)
    )
}

fn repeat_message(first: usize) -> String {
    format!(
        "the same kind in the same place as effects/{first}: the two could not be told \
         apart (only their sum acts); keep one entry"
    )
}

impl EffectRegistry {
    /// Checks every entry of `hall.effects` as [`Self::build_all`] does, naming the file
    /// and the field on error: an [`Error::Format`] whose field is a JSON pointer, e.g.
    /// `hall.json: /effects/0/fraction: effect `bypass`: 0.9 is outside [0, 0.5]`. Tools
    /// call it right after loading a hall (loading alone cannot check the entries: the
    /// kinds depend on the registry).
    pub fn check_hall(&self, hall: &Hall, file: &str) -> Result<()> {
        // An entry's own error without a field is about its kind (an unknown one).
        let effects = self
            .build_each(hall)
            .map_err(|e| e.in_hall_file_at(file, Some("kind")))?;
        check_together(&effects, hall).map_err(|e| e.in_hall_file(file))
    }
}

/// Builds an effect from its `hall.json` entry with the built-in registry, checking its
/// fields against the hall.
pub fn from_spec(spec: &EffectSpec, hall: &Hall) -> Result<Box<dyn Effect>> {
    EffectRegistry::builtin().build(spec, hall)
}

/// Checks the number of parameter values an effect receives.
pub(crate) fn check_values(kind: &str, values: &[f64], want: usize) -> Result<()> {
    if values.len() != want {
        return Err(Error::Effect {
            kind: kind.to_string(),
            message: format!("expected {want} parameter values, got {}", values.len()),
        });
    }
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(Error::Effect {
            kind: kind.to_string(),
            message: format!("parameter value {v} is not finite"),
        });
    }
    Ok(())
}
