//! The portable versions: the semantics of [`super`] written as plain loops over
//! [`Scalar::mul_add`] (a correctly rounded fused multiply-add; without the FMA instruction the
//! standard library computes it in software, slowly). They serve `f64` and `f32` on CPUs without
//! AVX2 + FMA.

use super::Scalar;

/// `c[i*c_rs + j] (= | +=) sum over p of a[i*a_rs + p*a_cs] * b[p*b_rs + j*b_cs]` for `i < m`,
/// `j < n`, `p < k`, each element one chain `acc = fma(a, b, acc)` in increasing `p` from +0.0
/// (or from `c` with `accumulate`).
///
/// Panics (index out of bounds) if an operand is too short.
pub(super) fn product<T: Scalar>(
    (m, n, k): (usize, usize, usize),
    (c, c_rs): (&mut [T], usize),
    accumulate: bool,
    (a, a_rs, a_cs): (&[T], usize, usize),
    (b, b_rs, b_cs): (&[T], usize, usize),
) {
    for i in 0..m {
        for j in 0..n {
            let dst = &mut c[i * c_rs + j];
            let mut acc = if accumulate { *dst } else { T::ZERO };
            for p in 0..k {
                acc = a[i * a_rs + p * a_cs].mul_add(b[p * b_rs + j * b_cs], acc);
            }
            *dst = acc;
        }
    }
}

/// The one-column forward product `y[i] = dot16(x[i*k .. i*k + k], w)` for `i < m`, where
/// `dot16(x, w)` runs 16 chains `s[l] = fma(x[p], w[p], s[l])` over `p = l, l + 16, l + 32, ...`
/// (in increasing `p`, each from +0.0) and sums them with [`tree16`].
pub(super) fn dot16<T: Scalar>(m: usize, k: usize, y: &mut [T], x: &[T], w: &[T]) {
    let w = &w[..k];
    for (yi, xi) in y[..m].iter_mut().zip(x.chunks_exact(k.max(1))) {
        let mut s = [T::ZERO; 16];
        for (p, (&xp, &wp)) in xi.iter().zip(w).enumerate() {
            s[p % 16] = xp.mul_add(wp, s[p % 16]);
        }
        *yi = tree16(s);
    }
}

/// The fixed sum of 16 lane values: `t[l] = s[l] + s[l + 8]`, then `u[l] = t[l] + t[l + 4]`,
/// then `v[l] = u[l] + u[l + 2]`, then `v[0] + v[1]` (a balanced tree, halving the lanes at
/// each level, as the SIMD registers do).
pub(super) fn tree16<T: Scalar>(s: [T; 16]) -> T {
    let t: [T; 8] = std::array::from_fn(|l| s[l] + s[l + 8]);
    let u: [T; 4] = std::array::from_fn(|l| t[l] + t[l + 4]);
    let v: [T; 2] = std::array::from_fn(|l| u[l] + u[l + 2]);
    v[0] + v[1]
}
