//! What DroQ (Hiraoka et al., ICLR 2022) puts between a hidden layer's product and its
//! activation: dropout, then layer normalisation, `y = f(LN(drop(x W^T + b)))`.
//!
//! 1. Dropout (training passes only): each value is kept with probability `1 - p` and scaled by
//!    `1 / (1 - p)`, or zeroed; the mask is drawn from the caller's random stream, one uniform per
//!    value in row-major order (`u < p`: dropped).
//! 2. Layer normalisation per row of `h` values: `mu = mean(z)`, `var = mean((z - mu)^2)`,
//!    `xhat = (z - mu) / sqrt(var + eps)`, `y = scale * xhat + bias` (learned `scale`, `bias`,
//!    initialised to 1 and 0; `eps` = 1e-6, flax's).
//!
//! Backward, with `g = dL/dy`: `dscale += sum_rows g xhat`, `dbias += sum_rows g`,
//! `dL/dz = (1 / sqrt(var + eps)) (g scale - mean(g scale) - xhat mean(g scale xhat))`, then times
//! the dropout mask.

use super::Scalar;
use crate::base::rng::Rng;

/// Layer normalisation's epsilon (flax's `nn.LayerNorm` default).
pub const LN_EPS: f64 = 1e-6;

/// Dropout and layer normalisation after every hidden layer of an [`super::Mlp`] (DroQ's critic).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HiddenNorm {
    /// Probability of dropping a value in training passes, in [0, 1).
    pub dropout: f64,
    /// Layer normalisation with a learned scale and bias.
    pub layer_norm: bool,
}

/// Step 1: draws the mask (`0` or `1 / (1 - p)`) into `mask` and applies it to `z`, in place.
pub fn dropout_forward<T: Scalar>(z: &mut [T], mask: &mut [T], p: f64, rng: &mut Rng) {
    let keep = T::from_f64(1.0 / (1.0 - p));
    for (v, m) in z.iter_mut().zip(mask.iter_mut()) {
        *m = if rng.uniform() < p { T::ZERO } else { keep };
        *v *= *m;
    }
}

/// Step 2, in place on `z` (`rows x h`): keeps `xhat` (`rows x h`) and `1 / sqrt(var + eps)` per
/// row (`inv_std`, `rows`) for the backward pass when given.
pub fn layer_norm_forward<T: Scalar>(
    z: &mut [T],
    h: usize,
    scale: &[T],
    bias: &[T],
    mut cache: Option<(&mut [T], &mut [T])>,
) {
    let inv_h = T::from_f64(1.0 / h as f64);
    let eps = T::from_f64(LN_EPS);
    for (r, row) in z.chunks_exact_mut(h).enumerate() {
        let mut mu = T::ZERO;
        for &v in row.iter() {
            mu += v;
        }
        mu *= inv_h;
        let mut var = T::ZERO;
        for &v in row.iter() {
            var += (v - mu) * (v - mu);
        }
        let inv = T::ONE / (var * inv_h + eps).sqrt();
        if let Some((xhat, inv_std)) = cache.as_mut() {
            inv_std[r] = inv;
            for (x, &v) in xhat[r * h..(r + 1) * h].iter_mut().zip(row.iter()) {
                *x = (v - mu) * inv;
            }
        }
        for ((v, &s), &b) in row.iter_mut().zip(scale).zip(bias) {
            *v = s * ((*v - mu) * inv) + b;
        }
    }
}

/// Step 2 backward, in place: `g` (`rows x h`) from dL/dy to dL/dz; with `param_grads`, adds
/// `sum_rows g xhat` to `dscale` and `sum_rows g` to `dbias`.
pub fn layer_norm_backward<T: Scalar>(
    g: &mut [T],
    h: usize,
    (xhat, inv_std): (&[T], &[T]),
    scale: &[T],
    param_grads: Option<(&mut [T], &mut [T])>,
) {
    if let Some((dscale, dbias)) = param_grads {
        for (row, xrow) in g.chunks_exact(h).zip(xhat.chunks_exact(h)) {
            for j in 0..h {
                dscale[j] += row[j] * xrow[j];
                dbias[j] += row[j];
            }
        }
    }
    let inv_h = T::from_f64(1.0 / h as f64);
    for ((row, xrow), &inv) in g.chunks_exact_mut(h).zip(xhat.chunks_exact(h)).zip(inv_std) {
        let (mut m1, mut m2) = (T::ZERO, T::ZERO);
        for j in 0..h {
            let d = row[j] * scale[j];
            m1 += d;
            m2 += d * xrow[j];
        }
        (m1, m2) = (m1 * inv_h, m2 * inv_h);
        for j in 0..h {
            row[j] = inv * (row[j] * scale[j] - m1 - xrow[j] * m2);
        }
    }
}

/// `out[j] += sum over rows of g[r][j]` (`g` is `rows x out.len()`).
pub fn add_column_sums<T: Scalar>(g: &[T], out: &mut [T]) {
    for row in g.chunks_exact(out.len()) {
        for (o, &v) in out.iter_mut().zip(row) {
            *o += v;
        }
    }
}
