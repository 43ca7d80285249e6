//! One SIMD register of `f32` lanes and the few operations the kernels need, for AVX-512F
//! ([`Avx512`], 16 lanes) and AVX2 + FMA ([`Avx2`], 8 lanes).
//!
//! A value of either type is a token: it can only be made by [`Avx512::new`] or [`Avx2::new`],
//! which check at run time that the CPU has the instructions, so its methods may execute them.
//! The methods are `#[inline(always)]`: the kernels are generic over [`Lanes`] and run inside a
//! `#[target_feature]` function, where the intrinsics inline into plain instructions.

use std::arch::x86_64::*;

/// A SIMD register of `f32` lanes (see the module docs).
pub(super) trait Lanes: Copy {
    /// Number of lanes.
    const W: usize;
    /// The register.
    type V: Copy;
    /// A lane mask, lanes `0..n` set.
    type M: Copy;

    /// All lanes +0.0.
    fn zero(self) -> Self::V;
    /// All lanes `x`.
    fn splat(self, x: f32) -> Self::V;
    /// `a * b + c` per lane, rounded once.
    fn fma(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `a + b` per lane.
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    /// `max(a, b)` per lane as `maxps` computes it: `b` where either is NaN or both are zeros.
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a - b` per lane.
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a * b` per lane.
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// `if y > 0 { g } else { +0.0 }` per lane (NaN `y` gives +0.0).
    fn where_positive(self, y: Self::V, g: Self::V) -> Self::V;
    /// The mask of lanes `0..n` (`n <= W`).
    fn mask(self, n: usize) -> Self::M;
    /// Loads `W` values.
    ///
    /// # Safety
    /// `p .. p + W` must be readable.
    unsafe fn load(self, p: *const f32) -> Self::V;
    /// Loads the lanes of `m` (the others are +0.0 and not read).
    ///
    /// # Safety
    /// The lanes of `m` must be readable.
    unsafe fn load_masked(self, p: *const f32, m: Self::M) -> Self::V;
    /// Stores the lanes of `m` (the others are not written).
    ///
    /// # Safety
    /// The lanes of `m` must be writable.
    unsafe fn store_masked(self, p: *mut f32, m: Self::M, v: Self::V);
    /// Stores `W` values.
    ///
    /// # Safety
    /// `p .. p + W` must be writable.
    unsafe fn store(self, p: *mut f32, v: Self::V);

    /// [`Lanes::load`] if `full`, otherwise [`Lanes::load_masked`] under `m` (AVX2's masked
    /// moves are slow on AMD's cores, the stores especially, so full vectors avoid them).
    ///
    /// # Safety
    /// As the load it makes.
    #[inline(always)]
    unsafe fn load_part(self, p: *const f32, full: bool, m: Self::M) -> Self::V {
        // SAFETY: the caller's guarantee.
        unsafe {
            if full {
                self.load(p)
            } else {
                self.load_masked(p, m)
            }
        }
    }
    /// [`Lanes::store`] if `full`, otherwise [`Lanes::store_masked`] under `m`.
    ///
    /// # Safety
    /// As the store it makes.
    #[inline(always)]
    unsafe fn store_part(self, p: *mut f32, full: bool, m: Self::M, v: Self::V) {
        // SAFETY: the caller's guarantee.
        unsafe {
            if full {
                self.store(p, v)
            } else {
                self.store_masked(p, m, v)
            }
        }
    }
}

/// AVX-512F: 16 lanes (`__m512`, `__mmask16`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Avx512(());

impl Avx512 {
    /// The token, if the CPU has AVX-512F.
    #[inline]
    pub fn new() -> Option<Self> {
        std::arch::is_x86_feature_detected!("avx512f").then_some(Avx512(()))
    }
}

impl Lanes for Avx512 {
    const W: usize = 16;
    type V = __m512;
    type M = __mmask16;

    #[inline(always)]
    fn zero(self) -> __m512 {
        // SAFETY (all methods): the token exists, so the CPU has AVX-512F.
        unsafe { _mm512_setzero_ps() }
    }
    #[inline(always)]
    fn splat(self, x: f32) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    fn fma(self, a: __m512, b: __m512, c: __m512) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn add(self, a: __m512, b: __m512) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_add_ps(a, b) }
    }
    #[inline(always)]
    fn max(self, a: __m512, b: __m512) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_max_ps(a, b) }
    }
    #[inline(always)]
    fn sub(self, a: __m512, b: __m512) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(self, a: __m512, b: __m512) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    fn where_positive(self, y: __m512, g: __m512) -> __m512 {
        // SAFETY: as above.
        unsafe { _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(y, _mm512_setzero_ps()), g) }
    }
    #[inline(always)]
    fn mask(self, n: usize) -> __mmask16 {
        debug_assert!(n <= 16);
        ((1u32 << n) - 1) as u16
    }
    #[inline(always)]
    unsafe fn load(self, p: *const f32) -> __m512 {
        // SAFETY: the CPU has AVX-512F; the caller guarantees the 16 values are readable.
        unsafe { _mm512_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn load_masked(self, p: *const f32, m: __mmask16) -> __m512 {
        // SAFETY: the CPU has AVX-512F; masked-off lanes are not accessed (no fault), the
        // others are readable (the caller's guarantee).
        unsafe { _mm512_maskz_loadu_ps(m, p) }
    }
    #[inline(always)]
    unsafe fn store_masked(self, p: *mut f32, m: __mmask16, v: __m512) {
        // SAFETY: as `load_masked`, for writing.
        unsafe { _mm512_mask_storeu_ps(p, m, v) }
    }
    #[inline(always)]
    unsafe fn store(self, p: *mut f32, v: __m512) {
        // SAFETY: the CPU has AVX-512F; the caller guarantees the 16 values are writable.
        unsafe { _mm512_storeu_ps(p, v) }
    }
}

/// AVX2 with FMA: 8 lanes (`__m256`, the mask as `__m256i`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Avx2(());

impl Avx2 {
    /// The token, if the CPU has AVX2 and FMA.
    #[inline]
    pub fn new() -> Option<Self> {
        let ok = std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma");
        ok.then_some(Avx2(()))
    }
}

impl Lanes for Avx2 {
    const W: usize = 8;
    type V = __m256;
    type M = __m256i;

    #[inline(always)]
    fn zero(self) -> __m256 {
        // SAFETY (all methods): the token exists, so the CPU has AVX2 and FMA.
        unsafe { _mm256_setzero_ps() }
    }
    #[inline(always)]
    fn splat(self, x: f32) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    fn fma(self, a: __m256, b: __m256, c: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn add(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_add_ps(a, b) }
    }
    #[inline(always)]
    fn max(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_max_ps(a, b) }
    }
    #[inline(always)]
    fn sub(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(self, a: __m256, b: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    fn where_positive(self, y: __m256, g: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(y, _mm256_setzero_ps()), g) }
    }
    #[inline(always)]
    fn mask(self, n: usize) -> __m256i {
        debug_assert!(n <= 8);
        // SAFETY: as above.
        unsafe { _mm256_cmpgt_epi32(_mm256_set1_epi32(n as i32), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7)) }
    }
    #[inline(always)]
    unsafe fn load(self, p: *const f32) -> __m256 {
        // SAFETY: the CPU has AVX; the caller guarantees the 8 values are readable.
        unsafe { _mm256_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn load_masked(self, p: *const f32, m: __m256i) -> __m256 {
        // SAFETY: the CPU has AVX; masked-off lanes are not accessed (no fault), the others are
        // readable (the caller's guarantee).
        unsafe { _mm256_maskload_ps(p, m) }
    }
    #[inline(always)]
    unsafe fn store_masked(self, p: *mut f32, m: __m256i, v: __m256) {
        // SAFETY: as `load_masked`, for writing.
        unsafe { _mm256_maskstore_ps(p, m, v) }
    }
    #[inline(always)]
    unsafe fn store(self, p: *mut f32, v: __m256) {
        // SAFETY: the CPU has AVX; the caller guarantees the 8 values are writable.
        unsafe { _mm256_storeu_ps(p, v) }
    }
}

/// The 16-lane tree sum of the dot kernel from its 8-lane half sum `t[l] = s[l] + s[l + 8]`:
/// `((t[0] + t[4]) + (t[2] + t[6])) + ((t[1] + t[5]) + (t[3] + t[7]))`, i.e. lanes `l` and
/// `l + 4` first, then `l` and `l + 2`, then 0 and 1 (see `super::portable::tree16`).
///
/// # Safety
/// The CPU must have AVX (implied by both tokens).
#[inline(always)]
pub(super) unsafe fn tree8(t: __m256) -> f32 {
    // SAFETY: the caller guarantees AVX; SSE is baseline.
    unsafe {
        let q = _mm_add_ps(_mm256_castps256_ps128(t), _mm256_extractf128_ps::<1>(t));
        let h = _mm_add_ps(q, _mm_movehl_ps(q, q));
        _mm_cvtss_f32(_mm_add_ss(h, _mm_shuffle_ps::<0b01>(h, h)))
    }
}
