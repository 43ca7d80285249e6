//! The engine's own small-matrix products, single-threaded, for the three patterns of
//! [`super::Linear`]: [`forward`] `y = x W^T`, [`backward_weight`] `dW += dy^T x` and
//! [`backward_input`] `dx = dy W[:, cols]`.
//!
//! # Exact semantics
//! Every output element is ONE sequential chain of fused multiply-adds over the depth index
//! `p = 0, 1, ..., k - 1` in increasing order, `acc = fma(lhs[i, p], rhs[p, j], acc)` (one
//! rounding each), starting from +0.0 (overwriting products) or from the element's current value
//! (`backward_weight`, which accumulates):
//!
//! - forward `y[b, o] = sum over i of x[b, i] W[o, i]`, chain over `i`;
//! - backward_weight `dW[o, i] += sum over b of dy[b, o] x[b, i]`, chain over `b` from `dW[o, i]`;
//! - backward_input `dx[b, j] = sum over o of dy[b, o] W[o, cols.start + j]`, chain over `o`.
//!
//! The one exception, [`forward`] with a single output column (`n == 1`, the critics' last
//! layer, where a chain a row would leave 15 of 16 lanes idle), is a dot product in another
//! fixed order: 16 chains `s[l]` over `p = l, l + 16, l + 32, ...` (each in increasing `p` from
//! +0.0), then the balanced tree `t[l] = s[l] + s[l + 8]`, `u[l] = t[l] + t[l + 4]`,
//! `v[l] = u[l] + u[l + 2]`, `v[0] + v[1]` (`portable::dot16`, tested against its own
//! reference). [`forward`]'s bias and activation come after, as [`Activation::add_bias_apply`].
//!
//! The results are therefore independent of tiling, of the depth blocks (an `f32` partial sum
//! stored and reloaded is exact), of the vector width and of the SIMD level: the AVX-512F
//! kernels, the AVX2 + FMA kernels and the portable loops ([`Scalar::mul_add`], a correctly
//! rounded fma even where the CPU lacks the instruction) give the same bits, which the tests
//! check against plain reference loops. The rounding is not `gemm`'s (nor a plain `a * b + c`
//! loop's), and a NaN's payload may differ between levels.
//!
//! # Kernels
//! `f32` at run time on x86-64 ([`crate::base::simd::simd_level`]; the build stays baseline x86-64),
//! in `kernel`: register tiles of outer products, which broadcast one left-hand scalar a row
//! and load the right-hand rows as vectors. AVX-512F: 6 rows x 64 columns (24 accumulators),
//! the last column panel as narrow as its columns allow (8 x 48, 12 x 32, 24 x 16, so outputs of
//! 1, 6, 12 or 22 columns waste at most one partial vector); AVX2 + FMA: 6 x 16 and 12 x 8.
//! Partial vectors are masked, the remaining rows one tile of their own. `forward` packs `W^T`
//! per call into a stack buffer of 8192 values (blocks of 128 x 64, depth x columns, or
//! 256 x 32 beyond depth 128; 8 x 8 transposes) and fuses the bias and `Identity` or `Relu`
//! into its stores; `backward_input` likewise fuses the previous layer's activation backward
//! pass and bias gradient ([`Deriv`]). `backward_weight` and `backward_input` read their
//! right-hand side in place (its rows are contiguous along the output columns) unless the rows
//! are 128 values apart or more and there are 32 output rows or more, where they copy it into
//! the same stack buffer (rows that far apart compete for the same cache sets). With AVX2 the
//! copies are made in BLIS's order instead (`kernel::panels`, tuned on a Zen 3 EPYC with a
//! 32 KiB L1 and a 512 KiB L2): a block of depth 256 and up to 256 columns is copied once into
//! a 256 KiB stack buffer as contiguous 16-column panels (16 KiB each, which stay in L1), and
//! every panel then runs over a block of 48 rows at a time (which stays in L2); full vectors
//! are loaded and stored with plain moves (AVX2's masked stores are slow on AMD's cores). The one-column
//! forward product runs one 16-lane dot product a row, four rows at a time. `f64` (the gradient
//! checks) and `f32` without AVX2 + FMA use the portable loops. Nothing allocates.
//! `benches/nn_matmul.rs` times the kernels against `gemm`.

use super::{Activation, Scalar};
use crate::base::simd::SimdLevel;

// The AVX-512 intrinsics and the `avx512f` target feature are stable since Rust 1.89, the
// workspace's `rust-version`.
#[cfg(target_arch = "x86_64")]
mod kernel;
#[cfg(target_arch = "x86_64")]
mod lanes;
mod portable;

#[cfg(test)]
mod tests;

/// `y (m x n) = x (m x k) * w^T`, overwriting `y`: `y[i*n + j] = sum over p of x[i*k + p] *
/// w[j*k + p]`, with `w` the row-major `n x k` weight (the exact order: see the module docs; a
/// dot product when `n == 1`); then, with `bias_act = Some((bias, f))`, `y[i*n + j] =
/// f(y[i*n + j] + bias[j])` exactly as [`Activation::add_bias_apply`] computes it (fused into
/// the kernels' stores for `Identity` and `Relu`).
///
/// # Panics
/// If `y`, `x`, `w` or `bias` holds fewer than `m * n`, `m * k`, `n * k` or `n` values.
#[inline]
pub(crate) fn forward<T: Scalar>(
    (m, n, k): (usize, usize, usize),
    y: &mut [T],
    x: &[T],
    w: &[T],
    bias_act: Option<(&[T], Activation)>,
) {
    forward_at(crate::base::simd::simd_level(), (m, n, k), y, x, w, bias_act);
}

/// [`forward`] at the given SIMD level (the portable loops where the CPU lacks it).
pub(crate) fn forward_at<T: Scalar>(
    level: SimdLevel,
    (m, n, k): (usize, usize, usize),
    y: &mut [T],
    x: &[T],
    w: &[T],
    bias_act: Option<(&[T], Activation)>,
) {
    let (y, x, w) = (&mut y[..m * n], &x[..m * k], &w[..n * k]);
    let bias_act = bias_act.map(|(b, f)| (&b[..n], f));
    if y.is_empty() || k == 0 {
        y.fill(T::ZERO);
    } else if forward_simd(level, (m, n, k), y, x, w, bias_act) {
        return;
    } else if n == 1 {
        portable::dot16(m, k, y, x, w);
    } else {
        portable::product((m, n, k), (y, n), false, (x, k, 1), (w, 1, k));
    }
    if let Some((bias, f)) = bias_act {
        f.add_bias_apply(y, bias);
    }
}

/// [`forward_at`] with the `f32` SIMD kernels, if `T` is `f32` and the level has them on this
/// CPU (`k > 0`, the slices cut to size); returns whether they ran.
fn forward_simd<T: Scalar>(
    level: SimdLevel,
    (m, n, k): (usize, usize, usize),
    y: &mut [T],
    x: &[T],
    w: &[T],
    bias_act: Option<(&[T], Activation)>,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    if let Some((simd, y, x, w)) = f32_simd(level, y, x, w) {
        use kernel::Fuse;
        let bias_act = bias_act.and_then(|(b, f)| Some((T::as_f32(b)?, f)));
        let (fuse, bias) = match bias_act {
            Some((b, Activation::Identity)) => (Fuse::Bias, b.as_ptr()),
            Some((b, Activation::Relu)) => (Fuse::BiasRelu, b.as_ptr()),
            _ => (Fuse::None, std::ptr::null()),
        };
        let r = kernel::Raw::forward((m, n, k), y.as_mut_ptr(), x.as_ptr(), (fuse, bias));
        // SAFETY: the slices hold exactly `m * n`, `m * k`, `n * k` values, the bias `n`, and
        // `k > 0`; the token proves that the CPU has the kernel's instructions.
        unsafe {
            match simd {
                Simd::Avx512(s) => kernel::forward_avx512(s, r, w.as_ptr()),
                Simd::Avx2(s) => kernel::forward_avx2(s, r, w.as_ptr()),
            }
        }
        if let (Some((b, f)), Fuse::None) = (bias_act, fuse) {
            f.add_bias_apply(y, b);
        }
        return true;
    }
    let _ = (level, (m, n, k), y, x, w, bias_act);
    false
}

/// `dw (m x n) += dy^T x` with `dy` row-major `k x m` and `x` row-major `k x n`:
/// `dw[i*n + j] += sum over p of dy[p*m + i] * x[p*n + j]` (one chain from the old value, in
/// increasing `p`).
///
/// # Panics
/// If `dw`, `dy` or `x` holds fewer than `m * n`, `k * m` or `k * n` values.
#[inline]
pub(crate) fn backward_weight<T: Scalar>((m, n, k): (usize, usize, usize), dw: &mut [T], dy: &[T], x: &[T]) {
    backward_weight_at(crate::base::simd::simd_level(), (m, n, k), dw, dy, x);
}

/// [`backward_weight`] at the given SIMD level.
pub(crate) fn backward_weight_at<T: Scalar>(
    level: SimdLevel,
    (m, n, k): (usize, usize, usize),
    dw: &mut [T],
    dy: &[T],
    x: &[T],
) {
    let (dw, dy, x) = (&mut dw[..m * n], &dy[..k * m], &x[..k * n]);
    if dw.is_empty() || k == 0 {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if let Some((simd, c, a, b)) = f32_simd(level, dw, dy, x) {
        let (c, a, b) = (c.as_mut_ptr(), a.as_ptr(), b.as_ptr());
        let r = kernel::Raw::plain((m, n, k), (a, 1, m), (b, n), (c, n), true);
        // SAFETY: the slices hold exactly the values `r` addresses; the token proves that the
        // CPU has the kernel's instructions.
        unsafe { simd.run(r, pack_rhs(m, n)) };
        return;
    }
    let _ = level;
    portable::product((m, n, k), (dw, n), true, (dy, 1, m), (x, n, 1));
}

/// The backward pass of the previous layer's activation `f`, fused into [`backward_input`]:
/// `dx` becomes dL/dz as [`Activation::backward`] computes it from that layer's outputs `ys`
/// (`m x n`), and with `bias_grad` (`n` values) the column sums of the result are added to it
/// as [`Activation::backward_sum`] adds them.
#[derive(Debug)]
pub(crate) struct Deriv<'a, T> {
    pub ys: &'a [T],
    pub f: Activation,
    pub bias_grad: Option<&'a mut [T]>,
}

impl<T: Scalar> Deriv<'_, T> {
    /// The separate loops (for the portable product).
    fn apply(self, (m, n): (usize, usize), dx: &mut [T]) {
        match self.bias_grad {
            Some(bias_grad) => self.f.backward_sum(&self.ys[..m * n], dx, &mut bias_grad[..n]),
            None => self.f.backward(&self.ys[..m * n], dx),
        }
    }
}

/// `dx (m x n) = dy (m x k) * w`, overwriting `dx`, where `w` has rows of stride `w_rs >= n`:
/// `dx[i*n + j] = sum over p of dy[i*k + p] * w[p*w_rs + j]` (e.g. the columns `cols` of a
/// row-major weight `k x in`: `w = &weight[cols.start..]`, `w_rs = in`); then `deriv`.
///
/// # Panics
/// If `n > w_rs`, or `dx`, `dy` or `w` holds fewer than `m * n`, `m * k` or
/// `(k - 1) * w_rs + n` values, or `deriv`'s slices fewer than `m * n` and `n`.
#[inline]
pub(crate) fn backward_input<T: Scalar>(
    (m, n, k): (usize, usize, usize),
    dx: &mut [T],
    dy: &[T],
    w: (&[T], usize),
    deriv: Option<Deriv<'_, T>>,
) {
    backward_input_at(crate::base::simd::simd_level(), (m, n, k), dx, dy, w, deriv);
}

/// [`backward_input`] at the given SIMD level.
pub(crate) fn backward_input_at<T: Scalar>(
    level: SimdLevel,
    (m, n, k): (usize, usize, usize),
    dx: &mut [T],
    dy: &[T],
    (w, w_rs): (&[T], usize),
    deriv: Option<Deriv<'_, T>>,
) {
    assert!(n <= w_rs, "backward_input: {n} columns in rows of stride {w_rs}");
    let extent = if k == 0 || n == 0 { 0 } else { (k - 1) * w_rs + n };
    let (dx, dy, w) = (&mut dx[..m * n], &dy[..m * k], &w[..extent]);
    let mut deriv =
        deriv.map(|d| Deriv { ys: &d.ys[..m * n], bias_grad: d.bias_grad.map(|g| &mut g[..n]), ..d });
    if dx.is_empty() || k == 0 {
        dx.fill(T::ZERO);
    } else {
        match backward_input_simd(level, (m, n, k), dx, dy, (w, w_rs), deriv) {
            None => return,
            Some(d) => deriv = d,
        }
        portable::product((m, n, k), (dx, n), false, (dy, k, 1), (w, w_rs, 1));
    }
    if let Some(d) = deriv {
        d.apply((m, n), dx);
    }
}

/// [`backward_input_at`] with the `f32` SIMD kernels (`k > 0`, the slices cut to size), if `T`
/// is `f32` and the level has them on this CPU: `None` if they ran, otherwise `Some(deriv)`
/// back.
fn backward_input_simd<'a, T: Scalar>(
    level: SimdLevel,
    (m, n, k): (usize, usize, usize),
    dx: &mut [T],
    dy: &[T],
    (w, w_rs): (&[T], usize),
    deriv: Option<Deriv<'a, T>>,
) -> Option<Option<Deriv<'a, T>>> {
    #[cfg(target_arch = "x86_64")]
    if let Some((simd, c, a, b)) = f32_simd(level, dx, dy, w) {
        let (c, a, b) = (c.as_mut_ptr(), a.as_ptr(), b.as_ptr());
        let mut r = kernel::Raw::plain((m, n, k), (a, k, 1), (b, w_rs), (c, n), false);
        if let Some(d) = deriv {
            let ys = T::as_f32(d.ys).map_or(std::ptr::null(), <[f32]>::as_ptr);
            let bias_grad = d.bias_grad.and_then(T::as_f32_mut).map(<[f32]>::as_mut_ptr);
            let fuse = kernel::Fuse::Deriv(d.f, bias_grad.is_some());
            r = kernel::Raw { fuse, ys, bias_grad: bias_grad.unwrap_or(std::ptr::null_mut()), ..r };
        }
        // SAFETY: the slices hold exactly the values `r` addresses (`w` its `extent`, `ys`
        // `m * n`, `bias_grad` `n`); the token proves that the CPU has the kernel's instructions.
        unsafe { simd.run(r, pack_rhs(m, w_rs)) };
        return None;
    }
    let _ = (level, (m, n, k), dx, dy, (w, w_rs));
    Some(deriv)
}

/// Whether the outer-product kernels should read their right-hand side (rows of stride `b_rs`)
/// from a packed copy: for strides of 128 values and more, where the rows would compete for the
/// same cache sets, and at least 32 output rows to amortise the copy (measured with
/// `benches/nn_matmul.rs`: 1.1x at 256 x 256 x 256, a loss for 64-wide rows or a few rows).
fn pack_rhs(m: usize, b_rs: usize) -> bool {
    m >= 32 && b_rs >= 128
}

/// The SIMD kernels of a level, with the token proving the CPU has them.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
enum Simd {
    Avx512(lanes::Avx512),
    Avx2(lanes::Avx2),
}

#[cfg(target_arch = "x86_64")]
impl Simd {
    /// The kernels of `level`, as [`crate::base::simd`]'s functions choose them: `None` (the portable
    /// loops) for the baseline or where the CPU lacks the level.
    fn at(level: SimdLevel) -> Option<Simd> {
        let detected = crate::base::simd::simd_level();
        match level {
            SimdLevel::Avx512 if detected == SimdLevel::Avx512 => lanes::Avx512::new().map(Simd::Avx512),
            SimdLevel::Avx2 if detected != SimdLevel::Baseline => lanes::Avx2::new().map(Simd::Avx2),
            _ => None,
        }
    }

    /// Runs the outer-product kernels on `r`, reading its right-hand side from a packed copy
    /// if `pack` (see [`pack_rhs`]).
    ///
    /// # Safety
    /// `r` must lie inside its operands.
    unsafe fn run(self, r: kernel::Raw, pack: bool) {
        let rhs = kernel::Rhs { b: r.b, rs: r.b_rs, cs: 1 };
        // SAFETY: the caller's guarantee; the token proves the instructions.
        unsafe {
            match (self, pack) {
                (Simd::Avx512(s), true) => kernel::packed_avx512(s, r, rhs),
                (Simd::Avx512(s), false) => kernel::product_avx512(s, r),
                (Simd::Avx2(s), true) => kernel::packed_avx2(s, r, rhs),
                (Simd::Avx2(s), false) => kernel::product_avx2(s, r),
            }
        }
    }
}

/// The `f32` views of the operands and the kernels of `level`, if `T` is `f32` and the level has
/// SIMD kernels on this CPU.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::type_complexity)]
fn f32_simd<'a, T: Scalar>(
    level: SimdLevel,
    c: &'a mut [T],
    a: &'a [T],
    b: &'a [T],
) -> Option<(Simd, &'a mut [f32], &'a [f32], &'a [f32])> {
    let simd = Simd::at(level)?;
    Some((simd, T::as_f32_mut(c)?, T::as_f32(a)?, T::as_f32(b)?))
}
