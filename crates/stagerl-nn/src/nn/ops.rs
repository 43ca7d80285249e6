//! Small element-wise and slice helpers: Polyak averaging, gradient norms and clipping, the
//! non-finite guard, column concatenation and extraction for critic inputs.
//!
//! All of them are single passes over slices and allocate nothing.

use super::Scalar;
use stagerl_base::multiversion;

/// Lanes of the independent partial sums in reductions, so that the loops vectorise.
const LANES: usize = 16;

/// Grows `buf` to at least `n` elements (never shrinks, so its allocation is reused).
#[inline]
pub(crate) fn grow<T: Scalar>(buf: &mut Vec<T>, n: usize) {
    if buf.len() < n {
        buf.resize(n, T::ZERO);
    }
}

/// Polyak (soft) update: `target[i] = (1 - tau) * target[i] + tau * source[i]`.
///
/// # Panics
/// If the lengths differ.
pub fn polyak_update<T: Scalar>(target: &mut [T], source: &[T], tau: T) {
    assert_eq!(target.len(), source.len(), "polyak_update: lengths differ");
    polyak_kernel(target, source, T::ONE - tau, tau);
}

multiversion! {
    /// `target[i] = keep * target[i] + tau * source[i]`.
    fn polyak_kernel / polyak_kernel_at<T: Scalar>(target: &mut [T], source: &[T], keep: T, tau: T) {
        target.iter_mut().zip(source).for_each(|(t, &s)| *t = keep * *t + tau * s);
    }
}

/// Index of the first NaN or infinite value, if any.
pub fn first_non_finite<T: Scalar>(x: &[T]) -> Option<usize> {
    // Chunks scanned without early exit (vectorisable); only a flagged chunk is searched.
    const CHUNK: usize = 256;
    for (c, chunk) in x.chunks(CHUNK).enumerate() {
        let bad = chunk.iter().fold(false, |acc, v| acc | !v.is_finite());
        if bad {
            return chunk.iter().position(|v| !v.is_finite()).map(|i| c * CHUNK + i);
        }
    }
    None
}

multiversion! {
    /// Sum of squares `sum_i x[i]^2` (in a fixed order, so deterministic).
    pub fn sum_of_squares / sum_of_squares_at<T: Scalar>(x: &[T]) -> T {
    let mut acc = [T::ZERO; LANES];
    let mut chunks = x.chunks_exact(LANES);
    for c in &mut chunks {
        for (a, &v) in acc.iter_mut().zip(c) {
            *a += v * v;
        }
    }
    for (a, &v) in acc.iter_mut().zip(chunks.remainder()) {
        *a += v * v;
    }
    acc.iter().copied().sum()
}
}

/// Euclidean norm of `x`.
pub fn l2_norm<T: Scalar>(x: &[T]) -> T {
    sum_of_squares(x).sqrt()
}

/// Clips the gradient by its global norm as `torch.nn.utils.clip_grad_norm_`: with
/// `n = ||g||_2`, if `max_norm / (n + 1e-6) < 1` then `g *= max_norm / (n + 1e-6)`.
/// Returns `n`, the norm before clipping.
pub fn clip_grad_norm<T: Scalar>(grads: &mut [T], max_norm: T) -> T {
    let norm = l2_norm(grads);
    let coef = max_norm / (norm + T::from_f64(1e-6));
    if coef < T::ONE {
        scale(grads, coef);
    }
    norm
}

multiversion! {
    /// `x[i] *= alpha`.
    pub fn scale / scale_at<T: Scalar>(x: &mut [T], alpha: T) {
        x.iter_mut().for_each(|v| *v *= alpha);
    }
}

/// `y[i] += x[i]`.
///
/// # Panics
/// If the lengths differ.
pub fn add_assign<T: Scalar>(y: &mut [T], x: &[T]) {
    assert_eq!(y.len(), x.len(), "add_assign: lengths differ");
    y.iter_mut().zip(x).for_each(|(y, &x)| *y += x);
}

/// `y[i] += alpha * x[i]`.
///
/// # Panics
/// If the lengths differ.
pub fn axpy<T: Scalar>(alpha: T, x: &[T], y: &mut [T]) {
    assert_eq!(y.len(), x.len(), "axpy: lengths differ");
    y.iter_mut().zip(x).for_each(|(y, &x)| *y += alpha * x);
}

/// `dst.copy_from_slice(src)` for the short rows of replay samples and critic inputs (a few
/// dozen bytes): fixed-size blocks copied inline, where a call into the C library's `memcpy`
/// would cost more than the copy.
///
/// # Panics
/// If the lengths differ.
#[inline]
pub fn copy_row<T: Copy>(dst: &mut [T], src: &[T]) {
    #[inline(always)]
    fn block<T: Copy, const N: usize>(dst: &mut [T], src: &[T], at: usize) {
        let s: &[T; N] = src[at..at + N].try_into().expect("block inside the row");
        let d: &mut [T; N] = (&mut dst[at..at + N]).try_into().expect("block inside the row");
        *d = *s;
    }
    let n = src.len();
    assert_eq!(dst.len(), n, "copy_row: lengths differ");
    if n >= 8 {
        // Whole blocks of 8, then one block of 8 ending at the row's end (overlapping).
        for at in (0..n - 7).step_by(8) {
            block::<T, 8>(dst, src, at);
        }
        block::<T, 8>(dst, src, n - 8);
    } else if n >= 4 {
        block::<T, 4>(dst, src, 0);
        block::<T, 4>(dst, src, n - 4);
    } else {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = s;
        }
    }
}

/// Row-wise concatenation `out = [a | b]`: `a` is `batch x a_cols`, `b` is `batch x b_cols`,
/// `out` is `batch x (a_cols + b_cols)` (e.g. a critic input concat(obs, action)).
///
/// # Panics
/// If a slice has the wrong length.
pub fn concat_cols<T: Scalar>(a: &[T], a_cols: usize, b: &[T], b_cols: usize, batch: usize, out: &mut [T]) {
    let cols = a_cols + b_cols;
    assert_eq!(a.len(), batch * a_cols, "concat_cols: a size");
    assert_eq!(b.len(), batch * b_cols, "concat_cols: b size");
    assert_eq!(out.len(), batch * cols, "concat_cols: out size");
    if cols == 0 {
        return;
    }
    for (r, row) in out.chunks_exact_mut(cols).enumerate() {
        let (ra, rb) = row.split_at_mut(a_cols);
        copy_row(ra, &a[r * a_cols..(r + 1) * a_cols]);
        copy_row(rb, &b[r * b_cols..(r + 1) * b_cols]);
    }
}

/// Column block extraction `out = src[:, start..start + len]`: `src` is `batch x src_cols`,
/// `out` is `batch x len` (e.g. dQ/da out of a critic's input gradient).
///
/// # Panics
/// If the block is outside `src` or a slice has the wrong length.
pub fn copy_cols<T: Scalar>(
    src: &[T],
    src_cols: usize,
    start: usize,
    len: usize,
    batch: usize,
    out: &mut [T],
) {
    assert!(start + len <= src_cols, "copy_cols: block outside the source");
    assert_eq!(src.len(), batch * src_cols, "copy_cols: src size");
    assert_eq!(out.len(), batch * len, "copy_cols: out size");
    if len == 0 {
        return;
    }
    for (row, o) in src.chunks_exact(src_cols).zip(out.chunks_exact_mut(len)) {
        copy_row(o, &row[start..start + len]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polyak_exact_values() {
        let mut target = vec![1.0f64, 2.0, -4.0, 0.0];
        let source = vec![5.0f64, -2.0, 4.0, 8.0];
        polyak_update(&mut target, &source, 0.25);
        assert_eq!(target, vec![2.0, 1.0, -2.0, 2.0]);
        // tau = 1 copies, tau = 0 keeps.
        polyak_update(&mut target, &source, 1.0);
        assert_eq!(target, source);
        let mut t32 = vec![3.0f32, -1.0];
        polyak_update(&mut t32, &[1.0, 1.0], 0.0);
        assert_eq!(t32, vec![3.0, -1.0]);
        let mut t = vec![0.0f32; 3];
        polyak_update(&mut t, &[1.0, 2.0, 4.0], 0.005);
        assert_eq!(t, vec![0.005, 0.01, 0.02]);
    }

    #[test]
    fn first_non_finite_finds_the_first() {
        let mut x = vec![0.5f32; 1000];
        assert_eq!(first_non_finite(&x), None);
        x[700] = f32::INFINITY;
        x[900] = f32::NAN;
        assert_eq!(first_non_finite(&x), Some(700));
        x[3] = f32::NEG_INFINITY;
        assert_eq!(first_non_finite(&x), Some(3));
        assert_eq!(first_non_finite(&[1.0f64, f64::NAN]), Some(1));
        assert_eq!(first_non_finite::<f64>(&[]), None);
    }

    #[test]
    fn norm_and_clipping() {
        let x: Vec<f64> = (0..37).map(|i| i as f64 - 10.0).collect();
        let expect: f64 = x.iter().map(|v| v * v).sum();
        assert_eq!(sum_of_squares(&x), expect);
        let mut g = vec![3.0f64, 4.0];
        let n = clip_grad_norm(&mut g, 1.0);
        assert_eq!(n, 5.0);
        let c = 1.0 / (5.0 + 1e-6);
        assert_eq!(g, vec![3.0 * c, 4.0 * c]);
        let mut g = vec![0.3f64, 0.4];
        assert_eq!(clip_grad_norm(&mut g, 1.0), 0.5);
        assert_eq!(g, vec![0.3, 0.4]);
    }

    #[test]
    fn elementwise_helpers() {
        let mut y = vec![1.0f64, 2.0, 3.0];
        add_assign(&mut y, &[1.0, 1.0, 1.0]);
        axpy(2.0, &[1.0, 0.0, -1.0], &mut y);
        scale(&mut y, 0.5);
        assert_eq!(y, vec![2.0, 1.5, 1.0]);
    }

    #[test]
    fn copy_row_every_length() {
        for n in 0..40 {
            let src: Vec<u32> = (0..n as u32).map(|i| i * 7 + 1).collect();
            let mut dst = vec![0u32; n];
            copy_row(&mut dst, &src);
            assert_eq!(dst, src, "length {n}");
        }
    }

    #[test]
    fn concat_and_copy_columns() {
        let a = [1.0f64, 2.0, 3.0, 4.0]; // 2 x 2
        let b = [5.0f64, 6.0]; // 2 x 1
        let mut out = [0.0; 6];
        concat_cols(&a, 2, &b, 1, 2, &mut out);
        assert_eq!(out, [1.0, 2.0, 5.0, 3.0, 4.0, 6.0]);
        let mut block = [0.0; 4];
        copy_cols(&out, 3, 1, 2, 2, &mut block);
        assert_eq!(block, [2.0, 5.0, 4.0, 6.0]);
    }
}
