//! The calibrated parameters of a hall: alpha (per type, per server or fixed) and the
//! parameters of its effects, laid out in one [`ParamSpace`].

use kalibre_core::{Param, ParamSpace, Scale};

use crate::effects::Effect;
use crate::hall::{AlphaMode, Hall};
use crate::{Error, Result};

/// Where each calibrated value of a hall sits in the flat parameter vector.
///
/// Alpha parameters come first (`alpha/<type id>` or `alpha/<server id>`), on a log
/// scale because a server's temperature rise goes as `1 / alpha`; then each effect's
/// parameters, `<kind>/<name>` (`<kind>#2/<name>` for a second effect of one kind). A
/// server type no server uses has no alpha parameter: nothing could calibrate it.
#[derive(Debug, Clone)]
pub struct ParamLayout {
    space: ParamSpace,
    /// Per server: the index of its alpha in the vector, or `None` when alpha is fixed.
    alpha_index: Vec<Option<usize>>,
    /// Per server: its alpha when fixed (the type's initial value).
    alpha_fixed: Vec<f64>,
    /// Per effect: the range of its parameters in the vector.
    effect_ranges: Vec<std::ops::Range<usize>>,
    mode: AlphaMode,
}

impl ParamLayout {
    /// The layout for a hall with its alpha mode and the given effects.
    pub fn new(hall: &Hall, effects: &[Box<dyn Effect>]) -> Result<Self> {
        Self::with_mode(hall, hall.calibrate.alpha, effects)
    }

    /// The layout with an explicit alpha mode.
    pub fn with_mode(hall: &Hall, mode: AlphaMode, effects: &[Box<dyn Effect>]) -> Result<Self> {
        let mut space = ParamSpace::new();
        let type_index = hall.server_type_indices();
        // Per type: its parameter's index when alpha is calibrated per type (types in
        // hall order, those no server uses left out).
        let mut type_param: Vec<Option<usize>> = vec![None; hall.server_types.len()];
        if mode == AlphaMode::PerType {
            for t in type_index.iter().flatten() {
                type_param[*t] = Some(0);
            }
            for (k, p) in type_param.iter_mut().flatten().enumerate() {
                *p = k;
            }
        }
        let mut alpha_index = Vec::with_capacity(type_index.len());
        let mut alpha_fixed = Vec::with_capacity(type_index.len());
        for (s, t) in hall.servers().zip(&type_index) {
            let t = t.ok_or_else(|| {
                Error::Mismatch(format!(
                    "server `{}` has unknown type `{}`",
                    s.server.id, s.server.server_type
                ))
            })?;
            let bounds = &hall.server_types[t].alpha_cfm_per_w;
            // Predictions check only the calibrated alphas; the fixed ones are checked here.
            if !(bounds.initial > 0.0 && bounds.initial.is_finite()) {
                return Err(Error::Mismatch(format!(
                    "server type `{}`: alpha_cfm_per_w.initial must be positive, got {}",
                    hall.server_types[t].id, bounds.initial
                )));
            }
            alpha_fixed.push(bounds.initial);
            alpha_index.push(match mode {
                AlphaMode::Fixed => None,
                AlphaMode::PerType => type_param[t],
                AlphaMode::PerServer => {
                    space.push(Param::new(
                        format!("alpha/{}", s.server.id),
                        bounds.min,
                        bounds.max,
                        bounds.initial,
                        Scale::Log,
                    )?)?;
                    Some(space.dim() - 1)
                }
            });
        }
        if mode == AlphaMode::PerType {
            for (t, _) in hall
                .server_types
                .iter()
                .zip(&type_param)
                .filter(|(_, p)| p.is_some())
            {
                let b = &t.alpha_cfm_per_w;
                space.push(Param::new(
                    format!("alpha/{}", t.id),
                    b.min,
                    b.max,
                    b.initial,
                    Scale::Log,
                )?)?;
            }
        }
        let mut effect_ranges = Vec::with_capacity(effects.len());
        let mut seen: Vec<&str> = Vec::new();
        for e in effects {
            let n = seen.iter().filter(|k| **k == e.kind()).count();
            seen.push(e.kind());
            let prefix = if n == 0 {
                e.kind().to_string()
            } else {
                format!("{}#{}", e.kind(), n + 1)
            };
            let start = space.dim();
            for p in e.parameters() {
                space.push(Param::new(
                    format!("{prefix}/{}", p.name),
                    p.lower,
                    p.upper,
                    p.initial,
                    p.scale,
                )?)?;
            }
            effect_ranges.push(start..space.dim());
        }
        Ok(ParamLayout {
            space,
            alpha_index,
            alpha_fixed,
            effect_ranges,
            mode,
        })
    }

    /// The parameter space.
    pub fn space(&self) -> &ParamSpace {
        &self.space
    }

    /// The alpha mode.
    pub fn mode(&self) -> AlphaMode {
        self.mode
    }

    /// The indices of the alpha parameters: they come first, before the effects'.
    pub fn alpha_params(&self) -> std::ops::Range<usize> {
        0..self
            .effect_ranges
            .first()
            .map_or(self.space.dim(), |r| r.start)
    }

    /// Alpha (cfm/W) of every server, in hall order.
    ///
    /// # Panics
    /// When `params` is shorter than the layout's parameter vector (a kernel for
    /// vectors the layout made; the loop checks lengths at its boundary).
    pub fn alpha_per_server(&self, params: &[f64]) -> Vec<f64> {
        self.alpha_per_server_iter(params).collect()
    }

    /// [`Self::alpha_per_server`] without the vector, for loops that read it once.
    pub fn alpha_per_server_iter<'a>(
        &'a self,
        params: &'a [f64],
    ) -> impl Iterator<Item = f64> + 'a {
        self.alpha_index
            .iter()
            .zip(&self.alpha_fixed)
            .map(move |(i, fixed)| i.map_or(*fixed, |i| params[i]))
    }

    /// Index of each server's alpha in the parameter vector (`None` when fixed).
    pub fn alpha_index(&self) -> &[Option<usize>] {
        &self.alpha_index
    }

    /// Adds a gradient with respect to per-server alpha into a gradient over parameters.
    ///
    /// # Panics
    /// When `grad_params` is shorter than the layout's parameter vector.
    pub fn accumulate_alpha_gradient(
        &self,
        grad_alpha_per_server: &[f64],
        grad_params: &mut [f64],
    ) {
        for (i, g) in self.alpha_index.iter().zip(grad_alpha_per_server) {
            if let Some(i) = i {
                grad_params[*i] += g;
            }
        }
    }

    /// The values of effect `e`'s parameters.
    ///
    /// # Panics
    /// When there is no effect `e`, or `params` is shorter than the layout's vector.
    pub fn effect_values<'p>(&self, params: &'p [f64], e: usize) -> &'p [f64] {
        &params[self.effect_ranges[e].clone()]
    }

    /// The range of effect `e`'s parameters in the vector.
    ///
    /// # Panics
    /// When there is no effect `e`.
    pub fn effect_range(&self, e: usize) -> std::ops::Range<usize> {
        self.effect_ranges[e].clone()
    }
}
