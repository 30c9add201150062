//! The thermal graph's edges: CRAC-to-sensor (`Wcs`) and server-to-sensor (`Wss`) weights
//! from normalised reciprocal distances, cut below a threshold and stored sparse.
//!
//! Both matrices are stored by sensor (one CSR row per sensor), which is the order the
//! forward pass reads them in.
//!
//! | matrix | from | to | weight before the cut | after the cut |
//! |---|---|---|---|---|
//! | `Wcs` | CRAC box centre | sensor | `r_ik / max_i r_ik` (nearest CRAC = 1) | kept as is: they are softmax logits (times fan speed), so their scale must not depend on how many CRACs a sensor sees |
//! | `Wss` | server exhaust-face centre | hot-aisle sensor | `r_jk / max_j r_jk` | row rescaled to sum 1, so `X_hot` is a distance-weighted mean of `P / alpha` whose scale does not grow with the number of servers |
//!
//! with `r = 1 / max(d, min_distance_m)`: the floor keeps a sensor sitting on an exhaust
//! grille from giving one server all the weight. Entries whose relative weight is below the
//! threshold are cut (absent from the CSR, i.e. zero): a CRAC with no edge to a sensor takes
//! no part in that sensor's softmax. Cold-aisle sensors have no `Wss` row: their output uses
//! the cooling block only.
//!
//! For `Wss`, [`AdjacencySettings::server_vertical_scale`] multiplies the height difference
//! inside `d`, and the kept entries weigh `r^server_distance_power` before the row rescale
//! (the cut still compares `r`, so the power keeps the same servers). The defaults, 1 and
//! 1, are the paper's rule; `examples/fig7_edges.rs` measures others.

use crate::hall::{distance, Aabb, Aisle, Hall};
use crate::{Error, Result};

/// A compressed sparse row matrix (rows = sensors).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Csr {
    /// `row_ptr[k]..row_ptr[k + 1]` are the entries of row `k`.
    pub row_ptr: Vec<usize>,
    /// Column (CRAC or server index) of each entry; ascending within a row.
    pub col: Vec<u32>,
    /// Value of each entry.
    pub val: Vec<f64>,
}

impl Csr {
    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.row_ptr.len().saturating_sub(1)
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.val.len()
    }

    /// The entry range of row `k`.
    pub fn range(&self, k: usize) -> std::ops::Range<usize> {
        self.row_ptr[k]..self.row_ptr[k + 1]
    }

    /// The stored value at (`row`, `col`), zero when the entry is cut.
    pub fn get(&self, row: usize, col: usize) -> f64 {
        let r = self.range(row);
        match self.col[r.clone()].binary_search(&(col as u32)) {
            Ok(i) => self.val[r.start + i],
            Err(_) => 0.0,
        }
    }

    fn push_row(&mut self, mut entries: Vec<(u32, f64)>) {
        if self.row_ptr.is_empty() {
            self.row_ptr.push(0);
        }
        entries.sort_by_key(|e| e.0);
        for (c, v) in entries {
            self.col.push(c);
            self.val.push(v);
        }
        self.row_ptr.push(self.val.len());
    }
}

/// How the adjacency is built.
///
/// | Name | Default | Meaning | Range |
/// |---|---|---|---|
/// | `crac_threshold` | 0.3 | relative weight below which a CRAC-sensor edge is cut | `[0, 1]` |
/// | `server_threshold` | 0.6 | relative weight below which a server-sensor edge is cut | `[0, 1]` |
/// | `min_distance_m` | 0.5 | distance floor in the reciprocal (m) | `> 0` |
/// | `server_distance_power` | 1 | server-sensor weight `1 / d^p` (the cut compares `1 / d`, so it keeps the same servers at any power) | `> 0` |
/// | `server_vertical_scale` | 1 | factor on the height difference in the server-sensor distance | `> 0` |
///
/// With the defaults a hot-aisle sensor keeps the servers within about 1.7 times the
/// distance of the nearest one (at least 0.83 m), typically the servers whose exhausts face
/// it across the aisle and their neighbours along the row. A wider cut (0.3) smears each
/// sensor's slope over types it barely sees: the loop's error after 10 iterations on the
/// synthetic halls rose from 0.37 to 0.45-0.50 C with it (docs/performance.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjacencySettings {
    /// Relative cut-off for `Wcs`.
    pub crac_threshold: f64,
    /// Relative cut-off for `Wss`.
    pub server_threshold: f64,
    /// Distance floor (m).
    pub min_distance_m: f64,
    /// Power of the server-sensor reciprocal distance.
    pub server_distance_power: f64,
    /// Factor on the height difference in the server-sensor distance.
    pub server_vertical_scale: f64,
}

impl Default for AdjacencySettings {
    fn default() -> Self {
        AdjacencySettings {
            crac_threshold: 0.3,
            server_threshold: 0.6,
            min_distance_m: 0.5,
            server_distance_power: 1.0,
            server_vertical_scale: 1.0,
        }
    }
}

impl AdjacencySettings {
    /// Sets the CRAC cut-off.
    pub fn with_crac_threshold(mut self, t: f64) -> Self {
        self.crac_threshold = t;
        self
    }

    /// Sets the server cut-off.
    pub fn with_server_threshold(mut self, t: f64) -> Self {
        self.server_threshold = t;
        self
    }

    /// Sets the distance floor (m).
    pub fn with_min_distance_m(mut self, d: f64) -> Self {
        self.min_distance_m = d;
        self
    }

    /// Sets the power of the server-sensor reciprocal distance.
    pub fn with_server_distance_power(mut self, p: f64) -> Self {
        self.server_distance_power = p;
        self
    }

    /// Sets the factor on the height difference in the server-sensor distance.
    pub fn with_server_vertical_scale(mut self, s: f64) -> Self {
        self.server_vertical_scale = s;
        self
    }

    /// Validates the settings.
    pub fn check(self) -> Result<Self> {
        for (name, t) in [
            ("crac_threshold", self.crac_threshold),
            ("server_threshold", self.server_threshold),
        ] {
            if !(0.0..=1.0).contains(&t) {
                return Err(setting(name, format!("must lie in [0, 1], got {t}")));
            }
        }
        for (name, v) in [
            ("min_distance_m", self.min_distance_m),
            ("server_distance_power", self.server_distance_power),
            ("server_vertical_scale", self.server_vertical_scale),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(setting(
                    name,
                    format!("must be positive and finite, got {v}"),
                ));
            }
        }
        Ok(self)
    }
}

pub(crate) fn setting(name: &str, reason: String) -> Error {
    Error::Core(kalibre_core::Error::InvalidSetting {
        name: name.to_string(),
        reason,
    })
}

/// The two adjacency matrices of a hall.
#[derive(Debug, Clone, PartialEq)]
pub struct Adjacency {
    /// CRAC-to-sensor weights `Wcs`, one row per sensor, columns are CRACs.
    pub cs: Csr,
    /// Server-to-sensor weights `Wss`, one row per sensor (empty for cold-aisle sensors),
    /// columns are servers in hall order.
    pub ss: Csr,
}

impl Adjacency {
    /// Builds both matrices from the hall's geometry (see the module docs).
    pub fn from_hall(hall: &Hall, settings: &AdjacencySettings) -> Result<Self> {
        let settings = settings.check()?;
        if hall.cracs.is_empty() {
            return Err(Error::Mismatch(format!(
                "hall `{}` has no CRAC: the thermal graph needs at least one",
                hall.name
            )));
        }
        if hall.sensors.is_empty() {
            return Err(Error::Mismatch(format!(
                "hall `{}` has no sensor",
                hall.name
            )));
        }
        let floor = settings.min_distance_m;
        let recip = |a: [f64; 3], b: [f64; 3]| 1.0 / distance(a, b).max(floor);
        let crac_centres: Vec<[f64; 3]> = hall
            .cracs
            .iter()
            .map(|c| Aabb::from_position_size(c.position_m, c.size_m).centre())
            .collect();
        let exhausts: Vec<[f64; 3]> = hall.servers().map(|s| s.exhaust_centre()).collect();
        let mut cs = Csr::default();
        let mut ss = Csr::default();
        for sensor in &hall.sensors {
            let p = sensor.position_m;
            let r: Vec<f64> = crac_centres.iter().map(|&c| recip(c, p)).collect();
            cs.push_row(relative_cut(&r, settings.crac_threshold));
            if sensor.aisle == Aisle::Hot && !exhausts.is_empty() {
                let vz = settings.server_vertical_scale;
                let r: Vec<f64> = exhausts
                    .iter()
                    .map(|&e| recip([e[0], e[1], p[2] + vz * (e[2] - p[2])], p))
                    .collect();
                let mut row = relative_cut(&r, settings.server_threshold);
                let power = settings.server_distance_power;
                for e in &mut row {
                    e.1 = e.1.powf(power);
                }
                let sum: f64 = row.iter().map(|e| e.1).sum();
                for e in &mut row {
                    e.1 /= sum;
                }
                ss.push_row(row);
            } else {
                ss.push_row(Vec::new());
            }
        }
        Ok(Adjacency { cs, ss })
    }

    /// Replaces the hot-aisle `Wss` rows with edges from the model's own air flow:
    /// `influence[k][j]` is sensor `k`'s sensitivity to server `j`'s temperature rise at
    /// fixed flows (K per K, from [`crate::sim::Simulator::sensor_influence`]), and
    /// `power_w` the servers' power at the state it was computed for.
    ///
    /// The heating block sums `P_j / alpha_j * Wss_jk`, and at fixed flows the sensor
    /// warms by `sum_j G_kj * rise_j` with `rise_j` proportional to `1 / alpha_j`; so
    /// `Wss_jk = G_kj / P_j`, cut below `cut` times the row's largest entry (it keeps the
    /// servers that matter: at 0.01, about 60 per sensor on `hall-a` instead of 2,240) and
    /// rescaled to sum 1, as the geometric rows are. A hot-aisle sensor that no server's
    /// exhaust reaches in the flow (no positive entry) keeps its geometric row.
    ///
    /// ```
    /// use kalibre_dc::surrogate::{Adjacency, AdjacencySettings};
    /// use kalibre_dc::synth::{self, Preset, SynthOptions};
    ///
    /// let hall = synth::generate(&SynthOptions::new(Preset::Demo, 1)).unwrap().hall;
    /// let geometric = Adjacency::from_hall(&hall, &AdjacencySettings::default()).unwrap();
    /// // An influence that sees only the first server: every hot row keeps that one edge.
    /// let mut influence = vec![vec![0.0; hall.server_count()]; hall.sensors.len()];
    /// for row in &mut influence {
    ///     row[0] = 0.3;
    /// }
    /// let power = vec![200.0; hall.server_count()];
    /// let adj = geometric.with_server_influence(&influence, &power, 0.01).unwrap();
    /// let hot = (0..hall.sensors.len()).find(|&k| adj.ss.range(k).len() > 0).unwrap();
    /// assert_eq!(adj.ss.range(hot).len(), 1);
    /// assert_eq!(adj.ss.get(hot, 0), 1.0);
    /// ```
    pub fn with_server_influence(
        mut self,
        influence: &[Vec<f64>],
        power_w: &[f64],
        cut: f64,
    ) -> Result<Self> {
        let rows = self.ss.rows();
        if influence.len() != rows {
            return Err(Error::Mismatch(format!(
                "server influence has {} sensor rows, the adjacency {rows}",
                influence.len()
            )));
        }
        if !(0.0..=1.0).contains(&cut) {
            return Err(setting("influence_cut", format!("{cut} is outside [0, 1]")));
        }
        let mut ss = Csr::default();
        for (k, g) in influence.iter().enumerate() {
            let geometric: Vec<(u32, f64)> = self
                .ss
                .range(k)
                .map(|e| (self.ss.col[e], self.ss.val[e]))
                .collect();
            if geometric.is_empty() {
                // A cold-aisle sensor: no heating block.
                ss.push_row(geometric);
                continue;
            }
            if g.len() != power_w.len() {
                return Err(Error::Mismatch(format!(
                    "server influence row {k} has {} servers, the power {}",
                    g.len(),
                    power_w.len()
                )));
            }
            if let Some(j) = g.iter().position(|v| !v.is_finite()) {
                return Err(Error::Mismatch(format!(
                    "server influence of server {j} on sensor {k} is not finite"
                )));
            }
            let w: Vec<f64> = g
                .iter()
                .zip(power_w)
                .map(|(&g, &p)| if p > 0.0 && g > 0.0 { g / p } else { 0.0 })
                .collect();
            if w.iter().all(|&v| v <= 0.0) {
                ss.push_row(geometric);
                continue;
            }
            let mut row: Vec<(u32, f64)> = relative_cut(&w, cut)
                .into_iter()
                .filter(|e| e.1 > 0.0)
                .collect();
            let sum: f64 = row.iter().map(|e| e.1).sum();
            for e in &mut row {
                e.1 /= sum;
            }
            ss.push_row(row);
        }
        self.ss = ss;
        Ok(self)
    }
}

/// Entries `r_i / max r` at or above `threshold` (the maximum itself is always kept).
fn relative_cut(r: &[f64], threshold: f64) -> Vec<(u32, f64)> {
    let max = r.iter().copied().fold(0.0, f64::max);
    r.iter()
        .enumerate()
        .map(|(i, &v)| (i as u32, v / max))
        .filter(|&(_, w)| w >= threshold)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_cut_keeps_the_nearest_and_drops_far_entries() {
        let kept = relative_cut(&[1.0, 0.5, 0.1, 0.29], 0.3);
        assert_eq!(kept, vec![(0, 1.0), (1, 0.5)]);
    }

    #[test]
    fn csr_get_returns_zero_for_cut_entries() {
        let mut m = Csr::default();
        m.push_row(vec![(3, 0.5), (1, 0.25)]);
        m.push_row(vec![]);
        assert_eq!(m.rows(), 2);
        assert_eq!(m.get(0, 1), 0.25);
        assert_eq!(m.get(0, 3), 0.5);
        assert_eq!(m.get(0, 2), 0.0);
        assert_eq!(m.get(1, 0), 0.0);
    }

    #[test]
    fn bad_settings_are_rejected() {
        assert!(AdjacencySettings::default()
            .with_server_threshold(1.5)
            .check()
            .is_err());
        assert!(AdjacencySettings::default()
            .with_min_distance_m(0.0)
            .check()
            .is_err());
    }
}
