//! Safe wrapper over `gemm::gemm` for strided matrix products, single-threaded.
//!
//! Every product of the engine goes through [`matmul`], with `Parallelism::None` so that results
//! are deterministic and the two cores stay free for the environments.

use super::Scalar;

/// A strided view description: element `(i, j)` lives at `i * rs + j * cs`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Strides {
    /// Row stride (elements).
    pub rs: usize,
    /// Column stride (elements).
    pub cs: usize,
}

impl Strides {
    /// Row-major storage with `cols` columns.
    #[inline]
    pub fn row_major(cols: usize) -> Self {
        Strides { rs: cols, cs: 1 }
    }
    /// The transpose of a row-major matrix with `cols` columns (column-major view).
    #[inline]
    pub fn transposed(cols: usize) -> Self {
        Strides { rs: 1, cs: cols }
    }
    /// Number of elements a `rows x cols` view must cover.
    #[inline]
    fn extent(self, rows: usize, cols: usize) -> usize {
        if rows == 0 || cols == 0 {
            0
        } else {
            (rows - 1) * self.rs + (cols - 1) * self.cs + 1
        }
    }
}

/// `dst (m x n) = [dst +] lhs (m x k) * rhs (k x n)`, with the given strides.
///
/// With `accumulate` the product is added to `dst`, otherwise `dst` is overwritten (its previous
/// contents, even NaN, are not read).
///
/// # Panics
/// If a slice is too short for its view.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn matmul<T: Scalar>(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [T],
    dst_s: Strides,
    accumulate: bool,
    lhs: &[T],
    lhs_s: Strides,
    rhs: &[T],
    rhs_s: Strides,
) {
    assert!(dst.len() >= dst_s.extent(m, n), "matmul: dst too short");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst.iter_mut().take(dst_s.extent(m, n)).for_each(|d| *d = T::ZERO);
        }
        return;
    }
    assert!(lhs.len() >= lhs_s.extent(m, k), "matmul: lhs too short");
    assert!(rhs.len() >= rhs_s.extent(k, n), "matmul: rhs too short");
    // SAFETY: the three views were checked to lie inside their slices; `dst` is borrowed mutably
    // so it cannot alias `lhs` or `rhs`; `T` is f32 or f64 (the trait is sealed), both of which
    // gemm supports.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            dst_s.cs as isize,
            dst_s.rs as isize,
            accumulate,
            lhs.as_ptr(),
            lhs_s.cs as isize,
            lhs_s.rs as isize,
            rhs.as_ptr(),
            rhs_s.cs as isize,
            rhs_s.rs as isize,
            T::ONE,
            T::ONE,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(m: usize, n: usize, k: usize, a: &[f64], sa: Strides, b: &[f64], sb: Strides) -> Vec<f64> {
        let mut c = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                for p in 0..k {
                    c[i * n + j] += a[i * sa.rs + p * sa.cs] * b[p * sb.rs + j * sb.cs];
                }
            }
        }
        c
    }

    #[test]
    fn matches_naive_product_for_all_layouts() {
        let (m, n, k) = (5, 7, 3);
        let a: Vec<f64> = (0..m * k).map(|i| (i as f64 * 0.37).sin()).collect();
        let b: Vec<f64> = (0..k * n).map(|i| (i as f64 * 0.91).cos()).collect();
        for (sa, sb) in [
            (Strides::row_major(k), Strides::row_major(n)),
            (Strides::transposed(m), Strides::transposed(k)),
            (Strides::row_major(k), Strides::transposed(k)),
        ] {
            let expect = naive(m, n, k, &a, sa, &b, sb);
            let mut c = vec![f64::NAN; m * n];
            matmul(m, n, k, &mut c, Strides::row_major(n), false, &a, sa, &b, sb);
            for (x, y) in c.iter().zip(&expect) {
                assert!((x - y).abs() < 1e-14);
            }
            // Accumulate adds on top.
            matmul(m, n, k, &mut c, Strides::row_major(n), true, &a, sa, &b, sb);
            for (x, y) in c.iter().zip(&expect) {
                assert!((x - 2.0 * y).abs() < 1e-14);
            }
        }
    }
}
