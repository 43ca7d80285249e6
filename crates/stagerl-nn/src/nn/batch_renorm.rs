//! Batch renormalisation (Ioffe 2017), as CrossQ (Bhatt et al., ICLR 2024) uses it in its
//! critics, with the formulas of sbx's `BatchRenorm` (its defaults: momentum 0.99, epsilon
//! 0.001, r_max 3, d_max 5, warm-up 100 000 training passes).
//!
//! Per feature `j` of a batch `x` (`B x n`, row-major):
//! 1. batch statistics `mu = mean_b x_b`, `var = mean_b (x_b - mu)^2`;
//! 2. after the warm-up (this layer's training passes so far >= `warmup_steps`), the correction
//!    `r = clip(sqrt(var + eps) / sqrt(ra_var + eps), 1 / r_max, r_max)`,
//!    `d = clip((mu - ra_mean) / sqrt(ra_var + eps), -d_max, d_max)`, both held constant in the
//!    backward pass, and the statistics used `m = mu - d sqrt(var) / r`, `v = var / r^2`; during
//!    the warm-up `m = mu`, `v = var` (batch normalisation);
//! 3. `y_b = scale (x_b - m) / sqrt(v + eps) + bias`;
//! 4. the running statistics `ra_mean <- momentum ra_mean + (1 - momentum) mu`, the same for
//!    `ra_var` with `var` (started at 0 and 1), and the pass count, after steps 2-3;
//! 5. inference (the actor's critic, evaluation): `y = scale (x - ra_mean) / sqrt(ra_var + eps)
//!    + bias`, nothing updated.
//!
//! Backward of a training pass, `g = dL/dy`, `gn = g scale`, `inv = 1 / sqrt(v + eps)`:
//! `dL/dm = -inv sum_b gn_b`, `dL/dv = -inv^3 / 2 sum_b gn_b (x_b - m)`; through step 2,
//! `dL/dmu = dL/dm`, `dL/dvar = dL/dm dm/dvar + dL/dv dv/dvar` (after the warm-up `dm/dvar =
//! -d / (2 r sqrt(var))`, `dv/dvar = 1 / r^2`; during it 0 and 1); then
//! `dL/dx_b = gn_b inv + dL/dmu / B + dL/dvar 2 (x_b - mu) / B`, and `dscale += sum_b g_b xn_b`,
//! `dbias += sum_b g_b` with `xn_b = (x_b - m) inv`.

use serde::{Deserialize, Serialize};

use super::Scalar;

/// Settings of a [`BatchRenorm`] layer (sbx's defaults: [`BatchRenormSettings::default`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BatchRenormSettings {
    /// Decay of the running statistics per training pass, in [0, 1).
    pub momentum: f64,
    /// Added to the variances, > 0.
    pub eps: f64,
    /// Bound of the standard-deviation correction `r`, >= 1.
    pub r_max: f64,
    /// Bound of the mean correction `d`, >= 0.
    pub d_max: f64,
    /// Training passes of plain batch normalisation before the corrections apply.
    pub warmup_steps: u64,
}

impl Default for BatchRenormSettings {
    fn default() -> Self {
        BatchRenormSettings { momentum: 0.99, eps: 1e-3, r_max: 3.0, d_max: 5.0, warmup_steps: 100_000 }
    }
}

/// The running statistics of a layer (its state: saved with the networks).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningStats {
    pub mean: Vec<f64>,
    pub var: Vec<f64>,
    /// Training passes so far.
    pub steps: u64,
}

/// A batch renormalisation layer over `n` features: settings, running statistics and what the
/// last training pass keeps for the backward pass (per feature: `mu`, `sqrt(var)`, `m`, `inv`,
/// the corrections, and whether they applied). Its scale and bias live with the caller (a
/// network's flat parameters). After the first pass at a batch, passes allocate nothing.
#[derive(Clone, Debug)]
pub struct BatchRenorm<T> {
    pub settings: BatchRenormSettings,
    pub stats: RunningStats,
    mu: Vec<T>,
    sd: Vec<T>,
    m: Vec<T>,
    inv: Vec<T>,
    r: Vec<T>,
    d: Vec<T>,
    warmed: bool,
    ready: bool,
    /// Per feature: the batch's sums (f64) of the forward pass, and of the backward pass.
    acc: [Vec<f64>; 2],
    sums: [Vec<T>; 4],
}

impl<T: Scalar> BatchRenorm<T> {
    /// A layer over `n` features, its running statistics at mean 0 and variance 1.
    pub fn new(n: usize, settings: BatchRenormSettings) -> Self {
        let z = vec![T::ZERO; n];
        BatchRenorm {
            settings,
            stats: RunningStats { mean: vec![0.0; n], var: vec![1.0; n], steps: 0 },
            mu: z.clone(),
            sd: z.clone(),
            m: z.clone(),
            inv: z.clone(),
            r: z.clone(),
            sums: [z.clone(), z.clone(), z.clone(), z.clone()],
            d: z,
            acc: [vec![0.0; n], vec![0.0; n]],
            warmed: false,
            ready: false,
        }
    }

    /// Features.
    pub fn len(&self) -> usize {
        self.mu.len()
    }

    /// Whether it has no feature.
    pub fn is_empty(&self) -> bool {
        self.mu.is_empty()
    }

    /// Steps 1-4 on `x` (`batch x n`) into `y`, with `scale` and `bias` (`n` each). Every pass
    /// runs over the rows in order (each feature's sums in increasing row, in f64).
    pub fn forward_train(&mut self, x: &[T], batch: usize, (scale, bias): (&[T], &[T]), y: &mut [T]) {
        let n = self.len();
        assert!(batch > 0 && x.len() == batch * n && y.len() >= batch * n, "BatchRenorm: sizes");
        let s = self.settings;
        let inv_b = 1.0 / batch as f64;
        self.warmed = self.stats.steps >= s.warmup_steps;
        // 1. Batch statistics (two passes, in f64).
        let [sum, sq] = &mut self.acc;
        sum.fill(0.0);
        sq.fill(0.0);
        for row in x.chunks_exact(n) {
            for (a, v) in sum.iter_mut().zip(row) {
                *a += v.to_f64();
            }
        }
        for a in sum.iter_mut() {
            *a *= inv_b;
        }
        for row in x.chunks_exact(n) {
            for ((a, v), mu) in sq.iter_mut().zip(row).zip(sum.iter()) {
                let dev = v.to_f64() - mu;
                *a += dev * dev;
            }
        }
        for j in 0..n {
            let (mu, var) = (self.acc[0][j], self.acc[1][j] * inv_b);
            // 2. The corrections, from the running statistics before this pass.
            let ra_sd = (self.stats.var[j] + s.eps).sqrt();
            let r = ((var + s.eps).sqrt() / ra_sd).clamp(1.0 / s.r_max, s.r_max);
            let d = ((mu - self.stats.mean[j]) / ra_sd).clamp(-s.d_max, s.d_max);
            let (m, v) = if self.warmed { (mu - d * var.sqrt() / r, var / (r * r)) } else { (mu, var) };
            let inv = 1.0 / (v + s.eps).sqrt();
            (self.mu[j], self.sd[j], self.m[j], self.inv[j]) =
                (T::from_f64(mu), T::from_f64(var.sqrt()), T::from_f64(m), T::from_f64(inv));
            (self.r[j], self.d[j]) = (T::from_f64(r), T::from_f64(d));
            // 4. Running statistics.
            self.stats.mean[j] = s.momentum * self.stats.mean[j] + (1.0 - s.momentum) * mu;
            self.stats.var[j] = s.momentum * self.stats.var[j] + (1.0 - s.momentum) * var;
        }
        // 3. Normalise.
        for (yr, xr) in y.chunks_exact_mut(n).zip(x.chunks_exact(n)) {
            for j in 0..n {
                yr[j] = scale[j] * ((xr[j] - self.m[j]) * self.inv[j]) + bias[j];
            }
        }
        self.stats.steps += 1;
        self.ready = true;
    }

    /// Step 5: inference with the running statistics.
    pub fn forward_eval(&self, x: &[T], batch: usize, (scale, bias): (&[T], &[T]), y: &mut [T]) {
        let n = self.len();
        assert!(x.len() == batch * n && y.len() >= batch * n, "BatchRenorm: sizes");
        for j in 0..n {
            let m = T::from_f64(self.stats.mean[j]);
            let inv = T::from_f64(1.0 / (self.stats.var[j] + self.settings.eps).sqrt());
            for b in 0..batch {
                y[b * n + j] = scale[j] * ((x[b * n + j] - m) * inv) + bias[j];
            }
        }
    }

    /// The backward pass of the last [`BatchRenorm::forward_train`] on `x`: `dx` from `g` =
    /// dL/dy (`batch x n` each); with `param_grads`, adds to the scale's and bias's gradients.
    /// Rows in order (each feature's sums in increasing row).
    pub fn backward(
        &mut self,
        (x, g): (&[T], &[T]),
        batch: usize,
        scale: &[T],
        dx: &mut [T],
        mut param_grads: Option<(&mut [T], &mut [T])>,
    ) {
        assert!(self.ready, "BatchRenorm backward without a training pass");
        let n = self.len();
        let inv_b = T::from_f64(1.0 / batch as f64);
        let half = T::from_f64(0.5);
        let [sum_gn, sum_gnx, sum_g, sum_gxn] = &mut self.sums;
        for v in [&mut *sum_gn, &mut *sum_gnx, &mut *sum_g, &mut *sum_gxn] {
            v.fill(T::ZERO);
        }
        for (gr, xr) in g[..batch * n].chunks_exact(n).zip(x.chunks_exact(n)) {
            for j in 0..n {
                let (gb, xc) = (gr[j], xr[j] - self.m[j]);
                let gn = gb * scale[j];
                sum_gn[j] += gn;
                sum_gnx[j] += gn * xc;
                sum_g[j] += gb;
                sum_gxn[j] += gb * xc * self.inv[j];
            }
        }
        for j in 0..n {
            let inv = self.inv[j];
            if let Some((ds, db)) = param_grads.as_mut() {
                ds[j] += sum_gxn[j];
                db[j] += sum_g[j];
            }
            let dm = -inv * sum_gn[j];
            let dv = -half * inv * inv * inv * sum_gnx[j];
            let dvar = if self.warmed {
                let (r, d, sd) = (self.r[j], self.d[j], self.sd[j]);
                // dm/dvar = -d / (2 r sqrt(var)): 0 for a constant feature (sqrt is not
                // differentiable there; its coefficient d is then 0 or clipped anyway).
                let dm_dvar = if sd > T::ZERO { -d / (T::from_f64(2.0) * r * sd) } else { T::ZERO };
                dm * dm_dvar + dv / (r * r)
            } else {
                dv
            };
            // Kept for the last pass: 2 dL/dvar / B and dL/dmu / B.
            sum_gn[j] = T::from_f64(2.0) * dvar * inv_b;
            sum_gnx[j] = dm * inv_b;
        }
        for ((dr, gr), xr) in
            dx[..batch * n].chunks_exact_mut(n).zip(g.chunks_exact(n)).zip(x.chunks_exact(n))
        {
            for j in 0..n {
                let gn = gr[j] * scale[j];
                dr[j] = gn * self.inv[j] + sum_gnx[j] + sum_gn[j] * (xr[j] - self.mu[j]);
            }
        }
    }
}
