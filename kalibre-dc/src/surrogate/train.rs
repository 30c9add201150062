//! Training the thermal graph (step 1 of the loop): loss `L1`, hand-written gradients,
//! a least-squares start and full-batch Adam.
//!
//! `L1` is the mean squared error over every sample and every sensor. Each fit:
//! 1. resets the adjacency to the geometric one and computes `X_cold`, `X_hot` (and term
//!    features) for every sample once; with a fixed adjacency they never change during
//!    training (alpha is frozen at each sample's value), so every epoch costs
//!    `O(samples x sensors)` whatever the number of servers;
//! 2. standardises them per sensor over the samples (see [`super::graph`]); a term's
//!    scale is at least its [`super::SurrogateTerm::min_scale`], so a feature that hardly
//!    moved in training is not blown up where it does move;
//! 3. starts from ridge-regularised least squares per sensor: with a fixed adjacency the
//!    model is linear in `a, c, e` given the hidden variables, so this is close to the
//!    optimum already. The ridge pulls toward the physical prior `T_cold = X_cold + b`
//!    (slope one in setpoints) and no rise response, which decides the slopes that the
//!    data cannot (e.g. `a` when every sample shares one operating state);
//! 4. runs Adam (lr 0.1, staircase decay 0.8 every 10 epochs, 150 epochs), and keeps the
//!    weights with the lowest loss seen, so training never ends worse than it started.
//!    With `adam_ridge` (the default) that loss includes the start's ridges, among them
//!    the stronger one on hall-wide terms' weights (`hall_wide_ridge`).
//!
//! The flat weight vector is `[a, b, c, d, e, omega_cs, omega_ss]` (the last two only with
//! a trainable adjacency). Trainable edges are `W = W_geometric * omega` with `omega`
//! starting at one and projected onto `omega >= 0`: Adam's step is then a relative change
//! of every edge whatever its size, and a trained edge never turns into a negative impact.

use kalibre_core::{FitSummary, TrainingSet};

use super::graph::{ThermalGraph, Weights};
use super::ridge::{mean_scale, ridge_and_grad, solve_spd, wdot};
use crate::snapshots::OperatingState;
use crate::{Error, Result};

/// Per-sample inputs of the training loss.
struct Prepared<'a> {
    scen: Vec<&'a OperatingState>,
    /// `P_j / alpha_j` per sample.
    h: Vec<Vec<f64>>,
    /// Raw term features per sample.
    f: Vec<Vec<f64>>,
    y: Vec<&'a [f64]>,
    /// Sample weights, scaled to mean 1.
    wt: Vec<f64>,
}

/// Standardised hidden variables and term features of every sample (`[s * n + k]`,
/// terms `[(s * T + t) * n + k]`), for a fixed adjacency.
struct Standardised {
    xc: Vec<f64>,
    xh: Vec<f64>,
    f: Vec<f64>,
    /// 1 for hot-aisle sensors, 0 for cold: a multiplier instead of a branch.
    hot: Vec<f64>,
}

impl ThermalGraph {
    /// The ridge on each term's weights: `hall_wide_ridge` for hall-wide terms, `ridge`
    /// for the others.
    fn term_ridges(&self) -> Vec<f64> {
        self.terms
            .iter()
            .map(|t| {
                if t.hall_wide() {
                    self.settings.hall_wide_ridge
                } else {
                    self.settings.ridge
                }
            })
            .collect()
    }

    fn standardise(
        &self,
        prep: &Prepared,
        cache: &[(Vec<f64>, Vec<f64>)],
        w: &Weights,
    ) -> Standardised {
        let n = self.hot.len();
        let nt = self.terms.len();
        let mut st = Standardised {
            xc: Vec::with_capacity(cache.len() * n),
            xh: Vec::with_capacity(cache.len() * n),
            f: Vec::with_capacity(cache.len() * n * nt),
            hot: self.hot.iter().map(|&h| f64::from(u8::from(h))).collect(),
        };
        for (s, (xc, xh)) in cache.iter().enumerate() {
            for k in 0..n {
                st.xc.push((xc[k] - w.cold_mean[k]) / w.cold_scale[k]);
                st.xh.push(if self.hot[k] {
                    (xh[k] - w.hot_mean[k]) / w.hot_scale[k]
                } else {
                    0.0
                });
            }
            for i in 0..n * nt {
                st.f.push((prep.f[s][i] - w.term_mean[i]) / w.term_scale[i]);
            }
        }
        st
    }

    /// `L1` and its gradient with a fixed adjacency: the hidden variables are inputs, so
    /// an epoch is a few multiply-adds per sample and sensor.
    fn loss_and_grad_fixed(
        &self,
        st: &Standardised,
        y: &[&[f64]],
        wt: &[f64],
        theta: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let n = self.hot.len();
        let nt = self.terms.len();
        let samples = y.len();
        let norm = 1.0 / (samples * n) as f64;
        grad.iter_mut().for_each(|g| *g = 0.0);
        let (a, rest) = theta.split_at(n);
        let (b, rest) = rest.split_at(n);
        let (c, rest) = rest.split_at(n);
        let (d, rest) = rest.split_at(n);
        let e = &rest[..n * nt];
        let (ga, rest) = grad.split_at_mut(n);
        let (gb, rest) = rest.split_at_mut(n);
        let (gc, rest) = rest.split_at_mut(n);
        let (gd, rest) = rest.split_at_mut(n);
        let ge = &mut rest[..n * nt];
        let mut loss = 0.0;
        for (s, ys) in y.iter().enumerate() {
            let xc = &st.xc[s * n..(s + 1) * n];
            let xh = &st.xh[s * n..(s + 1) * n];
            let f = &st.f[s * n * nt..(s + 1) * n * nt];
            for k in 0..n {
                let hm = st.hot[k];
                let mut t = a[k] * xc[k] + b[k] + hm * (c[k] * xh[k] + d[k]);
                for tt in 0..nt {
                    t += e[tt * n + k] * f[tt * n + k];
                }
                let r = t - ys[k];
                loss += wt[s] * r * r;
                let g = 2.0 * wt[s] * r * norm;
                ga[k] += g * xc[k];
                gb[k] += g;
                gc[k] += g * hm * xh[k];
                gd[k] += g * hm;
                for tt in 0..nt {
                    ge[tt * n + k] += g * f[tt * n + k];
                }
            }
        }
        loss * norm
    }

    fn prepare<'a>(&self, data: TrainingSet<'a, OperatingState>) -> Result<Prepared<'a>> {
        if data.samples.is_empty() {
            return Err(Error::Mismatch("no training sample".into()));
        }
        let n = self.hot.len();
        let mut p = Prepared {
            scen: Vec::new(),
            h: Vec::new(),
            f: Vec::new(),
            y: Vec::new(),
            wt: Vec::new(),
        };
        for (i, s) in data.samples.iter().enumerate() {
            let scen = data.scenarios.get(s.snapshot).ok_or_else(|| {
                Error::Mismatch(format!(
                    "training sample {i} refers to snapshot {} of {}",
                    s.snapshot,
                    data.scenarios.len()
                ))
            })?;
            self.check_inputs(scen, &s.params)
                .map_err(|e| Error::Mismatch(format!("training sample {i}: {e}")))?;
            if s.outputs.len() != n || s.outputs.iter().any(|v| !v.is_finite()) {
                return Err(Error::Mismatch(format!(
                    "training sample {i}: needs {n} finite outputs, got {} values",
                    s.outputs.len()
                )));
            }
            p.h.push(self.heat_inputs(scen, &s.params));
            p.f.push(self.term_features(scen, &s.params));
            p.scen.push(scen);
            p.y.push(&s.outputs);
            if !(s.weight.is_finite() && s.weight >= 0.0) {
                return Err(Error::Mismatch(format!(
                    "training sample {i}: weight {} is not finite and >= 0",
                    s.weight
                )));
            }
            p.wt.push(s.weight);
        }
        let total: f64 = p.wt.iter().sum();
        if total <= 0.0 {
            return Err(Error::Mismatch("every training sample has weight 0".into()));
        }
        let scale = p.wt.len() as f64 / total;
        p.wt.iter_mut().for_each(|w| *w *= scale);
        Ok(p)
    }

    fn theta_len(&self) -> usize {
        let n = self.hot.len();
        let base = n * (4 + self.terms.len());
        if self.settings.trainable_adjacency {
            base + self.geometric.cs.nnz() + self.geometric.ss.nnz()
        } else {
            base
        }
    }

    /// The trainable weights as one vector: `[a, b, c, d, e, omega_cs, omega_ss]`
    /// (see the module docs; `omega` only with a trainable adjacency).
    pub fn weights_vector(&self) -> Vec<f64> {
        let w = &self.w;
        let mut t: Vec<f64> = [&w.a, &w.b, &w.c, &w.d, &w.e]
            .iter()
            .flat_map(|v| v.iter().copied())
            .collect();
        if self.settings.trainable_adjacency {
            for (cur, geo) in [
                (&self.adjacency.cs, &self.geometric.cs),
                (&self.adjacency.ss, &self.geometric.ss),
            ] {
                t.extend(cur.val.iter().zip(&geo.val).map(|(c, g)| c / g));
            }
        }
        t
    }

    /// Replaces the trainable weights (the layout of [`Self::weights_vector`]).
    pub fn set_weights_vector(&mut self, theta: &[f64]) -> Result<()> {
        if theta.len() != self.theta_len() {
            return Err(Error::Mismatch(format!(
                "{} weights for a thermal graph of {}",
                theta.len(),
                self.theta_len()
            )));
        }
        let n = self.hot.len();
        let w = &mut self.w;
        for (i, v) in [&mut w.a, &mut w.b, &mut w.c, &mut w.d]
            .into_iter()
            .enumerate()
        {
            v.copy_from_slice(&theta[i * n..(i + 1) * n]);
        }
        let e_end = 4 * n + w.e.len();
        w.e.copy_from_slice(&theta[4 * n..e_end]);
        if self.settings.trainable_adjacency {
            let (cs_val, ss_val) = self.edge_values(theta);
            self.adjacency.cs.val = cs_val;
            self.adjacency.ss.val = ss_val;
        }
        Ok(())
    }

    /// Edge values `W_geometric * omega` for a weight vector (geometric when fixed).
    fn edge_values(&self, theta: &[f64]) -> (Vec<f64>, Vec<f64>) {
        if !self.settings.trainable_adjacency {
            return (self.geometric.cs.val.clone(), self.geometric.ss.val.clone());
        }
        let start = self.hot.len() * (4 + self.terms.len());
        let ncs = self.geometric.cs.nnz();
        let scale = |geo: &[f64], om: &[f64]| geo.iter().zip(om).map(|(g, o)| g * o).collect();
        (
            scale(&self.geometric.cs.val, &theta[start..start + ncs]),
            scale(&self.geometric.ss.val, &theta[start + ncs..]),
        )
    }

    /// `L1` and its gradient with respect to [`Self::weights_vector`] at the current
    /// weights and standardisation, on `data`.
    pub fn training_loss_and_gradient(
        &self,
        data: TrainingSet<'_, OperatingState>,
    ) -> Result<(f64, Vec<f64>)> {
        let prep = self.prepare(data)?;
        let theta = self.weights_vector();
        let mut grad = vec![0.0; theta.len()];
        let loss = if self.settings.trainable_adjacency {
            self.loss_and_grad(&prep, &self.w, &theta, &mut grad)
        } else {
            let cache = self.hidden_all(&prep, &self.adjacency.cs.val, &self.adjacency.ss.val);
            let st = self.standardise(&prep, &cache, &self.w);
            self.loss_and_grad_fixed(&st, &prep.y, &prep.wt, &theta, &mut grad)
        };
        Ok((loss, grad))
    }

    /// Raw `X_cold`, `X_hot` of every sample with edge values `cs_val`, `ss_val`.
    fn hidden_all(
        &self,
        prep: &Prepared,
        cs_val: &[f64],
        ss_val: &[f64],
    ) -> Vec<(Vec<f64>, Vec<f64>)> {
        let n = self.hot.len();
        (0..prep.scen.len())
            .map(|s| {
                let (mut xc, mut xh) = (vec![0.0; n], vec![0.0; n]);
                self.cold_hidden(cs_val, prep.scen[s], &mut xc, None);
                self.hot_hidden(ss_val, &prep.h[s], &mut xh);
                (xc, xh)
            })
            .collect()
    }

    /// `L1` at `theta` (scaling from `scaling`), recomputing the hidden variables from the
    /// edges in `theta` (the trainable-adjacency path); its gradient is written into `grad`.
    fn loss_and_grad(
        &self,
        prep: &Prepared,
        scaling: &Weights,
        theta: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let n = self.hot.len();
        let nt = self.terms.len();
        let (a, rest) = theta.split_at(n);
        let (b, rest) = rest.split_at(n);
        let (c, rest) = rest.split_at(n);
        let (d, rest) = rest.split_at(n);
        let e = &rest[..n * nt];
        grad.iter_mut().for_each(|g| *g = 0.0);
        let trainable = self.settings.trainable_adjacency;
        let (cs_val, ss_val) = self.edge_values(theta);
        let ncs = cs_val.len();
        let wstart = n * (4 + nt);
        let samples = prep.scen.len();
        let norm = 1.0 / (samples * n) as f64;
        let (mut xc_buf, mut xh_buf) = (vec![0.0; n], vec![0.0; n]);
        let mut soft = vec![0.0; ncs];
        let mut loss = 0.0;
        for s in 0..samples {
            let scen = prep.scen[s];
            self.cold_hidden(&cs_val, scen, &mut xc_buf, Some(&mut soft));
            self.hot_hidden(&ss_val, &prep.h[s], &mut xh_buf);
            let (xc, xh) = (&xc_buf, &xh_buf);
            let f = &prep.f[s];
            for k in 0..n {
                let xcs = (xc[k] - scaling.cold_mean[k]) / scaling.cold_scale[k];
                let xhs = (xh[k] - scaling.hot_mean[k]) / scaling.hot_scale[k];
                let mut t = a[k] * xcs + b[k];
                if self.hot[k] {
                    t += c[k] * xhs + d[k];
                }
                for tt in 0..nt {
                    let i = tt * n + k;
                    t += e[i] * (f[i] - scaling.term_mean[i]) / scaling.term_scale[i];
                }
                let r = t - prep.y[s][k];
                loss += prep.wt[s] * r * r * norm;
                let g = 2.0 * prep.wt[s] * r * norm;
                grad[k] += g * xcs;
                grad[n + k] += g;
                if self.hot[k] {
                    grad[2 * n + k] += g * xhs;
                    grad[3 * n + k] += g;
                }
                for tt in 0..nt {
                    let i = tt * n + k;
                    grad[4 * n + i] += g * (f[i] - scaling.term_mean[i]) / scaling.term_scale[i];
                }
                if trainable {
                    // Through the softmax: dX/dz_ik = c_ik (Tc_i - X_k), dz/dW = V_i.
                    let gxc = g * a[k] / scaling.cold_scale[k];
                    let cs = &self.adjacency.cs;
                    for ed in cs.range(k) {
                        let i = cs.col[ed] as usize;
                        let dz = gxc * soft[ed] * (scen.setpoint_c[i] - xc[k]);
                        grad[wstart + ed] += dz * scen.fan_speed[i] * self.geometric.cs.val[ed];
                    }
                    if self.hot[k] {
                        let gxh = g * c[k] / scaling.hot_scale[k];
                        let ss = &self.adjacency.ss;
                        for ed in ss.range(k) {
                            let j = ss.col[ed] as usize;
                            grad[wstart + ncs + ed] +=
                                gxh * prep.h[s][j] * self.geometric.ss.val[ed];
                        }
                    }
                }
            }
        }
        loss
    }

    /// Fits the weights on every sample (see the module docs).
    pub(crate) fn fit_checked(
        &mut self,
        data: TrainingSet<'_, OperatingState>,
        deadline: Option<std::time::Instant>,
    ) -> Result<FitSummary> {
        let prep = self.prepare(data)?;
        let n = self.hot.len();
        let nt = self.terms.len();
        let samples = prep.scen.len();
        self.adjacency = self.geometric.clone();
        let cache = self.hidden_all(&prep, &self.geometric.cs.val, &self.geometric.ss.val);

        // Standardisation over samples.
        let mut w = Weights::unfitted(n, nt);
        for k in 0..n {
            let wt = &prep.wt;
            (w.cold_mean[k], w.cold_scale[k]) = mean_scale(cache.iter().map(|c| c.0[k]), wt);
            if self.hot[k] {
                (w.hot_mean[k], w.hot_scale[k]) = mean_scale(cache.iter().map(|c| c.1[k]), wt);
            }
            for (t, term) in self.terms.iter().enumerate() {
                let i = t * n + k;
                let (mean, scale) = mean_scale(prep.f.iter().map(|f| f[i]), wt);
                (w.term_mean[i], w.term_scale[i]) = (mean, scale.max(term.min_scale()));
            }
        }

        // Ridge least squares per sensor, toward the prior (a = physical slope one); the
        // weights of hall-wide terms with their own, stronger ridge.
        let lambda = self.settings.ridge.max(1e-12) * samples as f64;
        let term_ridge = self.term_ridges();
        let term_lambda: Vec<f64> = term_ridge
            .iter()
            .map(|r| r.max(1e-12) * samples as f64)
            .collect();
        for k in 0..n {
            let mut cols: Vec<(Vec<f64>, f64, usize)> = Vec::new(); // feature, prior, theta slot
            cols.push((
                cache
                    .iter()
                    .map(|c| (c.0[k] - w.cold_mean[k]) / w.cold_scale[k])
                    .collect(),
                w.cold_scale[k],
                0,
            ));
            if self.hot[k] {
                cols.push((
                    cache
                        .iter()
                        .map(|c| (c.1[k] - w.hot_mean[k]) / w.hot_scale[k])
                        .collect(),
                    0.0,
                    2,
                ));
            }
            for t in 0..nt {
                let i = t * n + k;
                let f = prep
                    .f
                    .iter()
                    .map(|f| (f[i] - w.term_mean[i]) / w.term_scale[i]);
                cols.push((f.collect(), 0.0, 4 + t));
            }
            // Weighted mean (weights average 1); the columns are centred with the same weights.
            let ybar = prep
                .y
                .iter()
                .zip(&prep.wt)
                .map(|(y, w)| w * y[k])
                .sum::<f64>()
                / samples as f64;
            let m = cols.len();
            let mut g = vec![0.0; m * m];
            let mut rhs = vec![0.0; m];
            for p in 0..m {
                for q in 0..m {
                    g[p * m + q] = wdot(&cols[p].0, &cols[q].0, &prep.wt)
                        + if p != q {
                            0.0
                        } else if cols[p].2 >= 4 {
                            term_lambda[cols[p].2 - 4]
                        } else {
                            lambda
                        };
                }
                let xy: f64 = cols[p]
                    .0
                    .iter()
                    .zip(&prep.y)
                    .zip(&prep.wt)
                    .map(|((x, y), w)| w * x * (y[k] - ybar))
                    .sum();
                rhs[p] = xy + lambda * cols[p].1;
            }
            let sol = solve_spd(&mut g, &mut rhs, m);
            w.b[k] = ybar; // features are centred, so the intercept is the mean
            for (p, col) in cols.iter().enumerate() {
                match col.2 {
                    0 => w.a[k] = sol[p],
                    2 => w.c[k] = sol[p],
                    slot => w.e[(slot - 4) * n + k] = sol[p],
                }
            }
        }
        self.w = w;
        let mut theta = self.weights_vector();
        if self.settings.trainable_adjacency {
            let start = n * (4 + nt);
            theta[start..].iter_mut().for_each(|o| *o = 1.0);
        }

        // Full-batch Adam with staircase decay; keep the best weights seen.
        let st = self.settings;
        let (b1, b2, eps): (f64, f64, f64) = (0.9, 0.999, 1e-8);
        let mut m1 = vec![0.0; theta.len()];
        let mut m2 = vec![0.0; theta.len()];
        let mut grad = vec![0.0; theta.len()];
        let scaling = self.w.clone();
        // (loss Adam minimises, training MSE, weights) of the best epoch.
        let mut best = (f64::INFINITY, f64::INFINITY, theta.clone());
        let omega_start = n * (4 + nt);
        let fixed = (!st.trainable_adjacency).then(|| self.standardise(&prep, &cache, &scaling));
        let mut epochs_run = st.epochs;
        for epoch in 0..=st.epochs {
            let mse = match &fixed {
                Some(f) => self.loss_and_grad_fixed(f, &prep.y, &prep.wt, &theta, &mut grad),
                None => self.loss_and_grad(&prep, &scaling, &theta, &mut grad),
            };
            let loss = if st.adam_ridge {
                mse + ridge_and_grad(
                    &scaling.cold_scale,
                    st.ridge,
                    &term_ridge,
                    &theta,
                    &mut grad,
                )
            } else {
                mse
            };
            if !loss.is_finite() {
                return Err(Error::Core(kalibre_core::Error::Fit(format!(
                    "training loss became {loss} at epoch {epoch}"
                ))));
            }
            if loss < best.0 {
                best = (loss, mse, theta.clone());
            }
            if epoch == st.epochs {
                break;
            }
            if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
                epochs_run = epoch;
                break;
            }
            let lr = st.learning_rate * st.decay_rate.powi((epoch / st.decay_every_epochs) as i32);
            let t = (epoch + 1) as i32;
            let (c1, c2) = (1.0 - b1.powi(t), 1.0 - b2.powi(t));
            for i in 0..theta.len() {
                m1[i] = b1 * m1[i] + (1.0 - b1) * grad[i];
                m2[i] = b2 * m2[i] + (1.0 - b2) * grad[i] * grad[i];
                theta[i] -= lr * (m1[i] / c1) / ((m2[i] / c2).sqrt() + eps);
            }
            if st.trainable_adjacency {
                theta[omega_start..]
                    .iter_mut()
                    .for_each(|o| *o = o.max(0.0));
            }
        }
        self.set_weights_vector(&best.2)?;
        self.fitted = true;
        Ok(FitSummary {
            train_mse: best.1,
            epochs: epochs_run,
            timed_out: epochs_run < st.epochs,
        })
    }
}
