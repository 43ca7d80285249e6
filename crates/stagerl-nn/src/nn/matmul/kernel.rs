//! The `f32` SIMD kernels: register-blocked outer products (every level of [`Lanes`]), the
//! forward pass's packing of `W^T` into a stack buffer, and the one-column dot kernel.
//!
//! Each output element is computed as the module docs of [`super`] say; nothing here depends
//! on the order in which tiles, columns or depth blocks are visited.

use std::arch::x86_64::*;
use std::mem::MaybeUninit;

use super::lanes::{tree8, Avx2, Avx512, Lanes};
use crate::nn::Activation;

/// Values in the stack buffer of a packed right-hand side block (32 KiB: two thirds of this
/// CPU's L1 data cache, with room for the left-hand side's lines and the tile's outputs).
const BUF: usize = 8192;
/// Columns of a block of a copied right-hand side: blocks of 128 x 64 (depth x columns;
/// measured best for `backward_weight` and `backward_input` at 256 x 256 x 256, and for the
/// forward pass up to depth 128).
const COPY_NB: usize = 64;

/// Columns of a block of `W^T` in the forward pass of depth `k`: blocks of 256 x 32 beyond depth
/// 128, so that depths up to 256 need no second pass over the outputs (measured: 1.02x gemm at
/// 256 x 256 x 256 against 0.97x with 128 x 64 blocks), otherwise 128 x 64.
fn forward_nb(k: usize) -> usize {
    if k > BUF / COPY_NB {
        32
    } else {
        COPY_NB
    }
}

/// Columns of a block of a copied right-hand side with AVX2: one panel of the 6 x 16 tiles, so
/// that a panel's rows are contiguous in the buffer. Wider blocks (the AVX-512 kernels' 64
/// columns) leave a 16-column panel's rows 256 bytes apart, in a quarter of the L1 cache's sets,
/// where the left-hand side's lines evict them (a 32 KiB L1 on AMD's Zen 3).
const AVX2_NB: usize = 16;

/// Depth of a block of a copied right-hand side with AVX2 (with [`AVX2_NB`] columns, 16 KiB of a
/// 32 KiB L1): 256, or 128 where the left-hand side is read down its columns (`dW += dy^T x`,
/// one cache line of `dy` a depth step, so that those lines fit beside the block).
fn avx2_kb(r: Raw) -> usize {
    if r.a_cs == 1 {
        256
    } else {
        128
    }
}

/// What a tile does to its sums `v` before storing them (after the last depth block), each
/// the same instructions as the separate loop in `Activation`, so the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Fuse {
    /// Nothing.
    None,
    /// `v + bias[j]` (`Activation::Identity.add_bias_apply`).
    Bias,
    /// `max(v + bias[j], 0)` as `maxps` computes it (`Activation::Relu.add_bias_apply`).
    BiasRelu,
    /// `g = v * f'`, the derivative of the activation `f` from its outputs `ys[i, j]` (laid out
    /// as `c`) as `Activation::backward` computes it; with `true`, the column sums of `g` are
    /// added to `bias_grad[j]` row after row, as `Activation::backward_sum` does.
    Deriv(Activation, bool),
}

/// `c[i*c_rs + j] (= | +=) sum over p of a[i*a_rs + p*a_cs] * b[p*b_rs + j]` for `i < m`,
/// `j < n`, `p < k` (`+=` with `accumulate`), then `fuse` with `bias[j]`: the right-hand side's
/// rows are contiguous, so the kernel loads them as vectors and broadcasts the left-hand side's
/// scalars.
#[derive(Clone, Copy, Debug)]
pub(super) struct Raw {
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub a: *const f32,
    pub a_rs: usize,
    pub a_cs: usize,
    pub b: *const f32,
    pub b_rs: usize,
    pub c: *mut f32,
    pub c_rs: usize,
    pub accumulate: bool,
    pub fuse: Fuse,
    /// `n` values for `Fuse::Bias` and `Fuse::BiasRelu`.
    pub bias: *const f32,
    /// `m x n` values with row stride `c_rs` for `Fuse::Deriv`.
    pub ys: *const f32,
    /// `n` values for `Fuse::Deriv(_, true)`.
    pub bias_grad: *mut f32,
}

impl Raw {
    /// The same product restricted to rows `i..` (pointer arithmetic only; the caller keeps it
    /// inside the operands).
    #[inline(always)]
    fn rows_from(self, i: usize) -> Raw {
        let (a, c, ys) = (
            self.a.wrapping_add(i * self.a_rs),
            self.c.wrapping_add(i * self.c_rs),
            self.ys.wrapping_add(i * self.c_rs),
        );
        Raw { a, c, ys, ..self }
    }

    /// The same product restricted to columns `j..`.
    #[inline(always)]
    fn cols_from(self, j: usize) -> Raw {
        let (b, c, bias) = (self.b.wrapping_add(j), self.c.wrapping_add(j), self.bias.wrapping_add(j));
        let (ys, bias_grad) = (self.ys.wrapping_add(j), self.bias_grad.wrapping_add(j));
        Raw { b, c, bias, ys, bias_grad, ..self }
    }
}

/// One register tile: rows `0..MR` of `r`, columns `0..NV * W` of which the last vector's lanes
/// outside `last` are neither read nor written (`FULL`: `last` is all lanes, so that vector is
/// read and written with plain moves). Accumulators: `MR x NV` registers.
///
/// # Safety
/// The tile's elements (rows `0..MR`, the columns of the full vectors and of `last`, depth
/// `0..r.k`) must lie inside the operands; the CPU must have `S`'s instructions.
#[inline(always)]
unsafe fn tile<S: Lanes, const MR: usize, const NV: usize, const FULL: bool>(s: S, r: Raw, last: S::M) {
    let w = S::W;
    let mut acc = [[s.zero(); NV]; MR];
    // SAFETY: every pointer below addresses an element of the tile (the caller's guarantee).
    unsafe {
        if r.accumulate {
            for (i, row) in acc.iter_mut().enumerate() {
                let c = r.c.add(i * r.c_rs);
                for v in 0..NV {
                    row[v] = s.load_part(c.add(v * w), v + 1 < NV || FULL, last);
                }
            }
        }
        if r.a_cs == 1 {
            // Rows of the left-hand side contiguous: one pointer a row, indexed by `p`.
            let rows: [*const f32; MR] = std::array::from_fn(|i| r.a.add(i * r.a_rs));
            for p in 0..r.k {
                step::<S, MR, NV, FULL>(s, &mut acc, (r.b.add(p * r.b_rs), last), |i| *rows[i].add(p));
            }
        } else {
            for p in 0..r.k {
                let a = r.a.add(p * r.a_cs);
                step::<S, MR, NV, FULL>(s, &mut acc, (r.b.add(p * r.b_rs), last), |i| *a.add(i * r.a_rs));
            }
        }
        store::<S, MR, NV, FULL>(s, r, &acc, last);
    }
}

/// Stores a tile's sums `acc` (rows `0..MR`, columns `0..NV * W`, the last vector under `last`)
/// after `r.fuse`. Each kind of epilogue is its own loop, small enough to be unrolled, so that
/// the accumulators stay in registers.
///
/// # Safety
/// As [`tile`], for `c` and, as `r.fuse` needs them, `bias`, `ys` and `bias_grad`.
#[inline(always)]
unsafe fn store<S: Lanes, const MR: usize, const NV: usize, const FULL: bool>(
    s: S,
    r: Raw,
    acc: &[[S::V; NV]; MR],
    last: S::M,
) {
    // SAFETY: the caller's guarantee.
    unsafe {
        match r.fuse {
            Fuse::None => each::<S, MR, NV, FULL>(s, r, acc, last, |_, _, x| x),
            Fuse::Bias | Fuse::BiasRelu => {
                let mut bias = [s.zero(); NV];
                for (v, b) in bias.iter_mut().enumerate() {
                    *b = s.load_part(r.bias.add(v * S::W), v + 1 < NV || FULL, last);
                }
                if r.fuse == Fuse::Bias {
                    each::<S, MR, NV, FULL>(s, r, acc, last, |_, v, x| s.add(x, bias[v]));
                } else {
                    each::<S, MR, NV, FULL>(s, r, acc, last, |_, v, x| s.max(s.add(x, bias[v]), s.zero()));
                }
            }
            Fuse::Deriv(Activation::Identity, sum) => {
                deriv::<S, MR, NV, FULL>(s, r, acc, last, sum, |g, _| g)
            }
            Fuse::Deriv(Activation::Relu, sum) => {
                deriv::<S, MR, NV, FULL>(s, r, acc, last, sum, |g, y| s.where_positive(y, g))
            }
            Fuse::Deriv(Activation::Tanh, sum) => deriv::<S, MR, NV, FULL>(s, r, acc, last, sum, |g, y| {
                s.mul(g, s.sub(s.splat(1.0), s.mul(y, y)))
            }),
        }
    }
}

/// Stores `out(i, v, acc[i][v])` for every register of a tile.
///
/// # Safety
/// As [`store`].
#[inline(always)]
unsafe fn each<S: Lanes, const MR: usize, const NV: usize, const FULL: bool>(
    s: S,
    r: Raw,
    acc: &[[S::V; NV]; MR],
    last: S::M,
    mut out: impl FnMut(usize, usize, S::V) -> S::V,
) {
    for (i, row) in acc.iter().enumerate() {
        for v in 0..NV {
            let x = out(i, v, row[v]);
            // SAFETY: row `i`, vector `v` of the tile's `c` (the caller's guarantee).
            unsafe { s.store_part(r.c.add(i * r.c_rs + v * S::W), v + 1 < NV || FULL, last, x) };
        }
    }
}

/// The `Fuse::Deriv` epilogue: `g = d(acc, y)` with `y` the tile's element of `r.ys`, stored,
/// and with `sum` added to `r.bias_grad` row after row.
///
/// # Safety
/// As [`store`].
#[inline(always)]
unsafe fn deriv<S: Lanes, const MR: usize, const NV: usize, const FULL: bool>(
    s: S,
    r: Raw,
    acc: &[[S::V; NV]; MR],
    last: S::M,
    sum: bool,
    d: impl Fn(S::V, S::V) -> S::V,
) {
    let full = |v: usize| v + 1 < NV || FULL;
    let mut sums = [s.zero(); NV];
    // SAFETY: the tile's elements of `ys` and columns of `bias_grad` (the caller's guarantee).
    unsafe {
        if sum {
            for (v, t) in sums.iter_mut().enumerate() {
                *t = s.load_part(r.bias_grad.add(v * S::W), full(v), last);
            }
        }
        each::<S, MR, NV, FULL>(s, r, acc, last, |i, v, x| {
            let g = d(x, s.load_part(r.ys.add(i * r.c_rs + v * S::W), full(v), last));
            sums[v] = s.add(sums[v], g);
            g
        });
        if sum {
            for (v, t) in sums.iter().enumerate() {
                s.store_part(r.bias_grad.add(v * S::W), full(v), last, *t);
            }
        }
    }
}

/// One depth step of a tile: `acc[i][v] = fma(a(i), b[v], acc[i][v])`, the vectors `b[v]` loaded
/// from `b` (the last one under `last`).
///
/// # Safety
/// As [`tile`]: `b`'s lanes and the values `a` reads must lie inside the operands.
#[inline(always)]
unsafe fn step<S: Lanes, const MR: usize, const NV: usize, const FULL: bool>(
    s: S,
    acc: &mut [[S::V; NV]; MR],
    (b, last): (*const f32, S::M),
    a: impl Fn(usize) -> f32,
) {
    let w = S::W;
    let mut bv = [s.zero(); NV];
    // SAFETY: the caller's guarantee.
    unsafe {
        for v in 0..NV {
            bv[v] = s.load_part(b.add(v * w), v + 1 < NV || FULL, last);
        }
    }
    for (i, row) in acc.iter_mut().enumerate() {
        let ai = s.splat(a(i));
        for v in 0..NV {
            row[v] = s.fma(ai, bv[v], row[v]);
        }
    }
}

/// `$name::<FULL>(s, r, last)`: all rows of one column panel of `r` (`$nv` vectors of `$s`
/// wide, the last one masked by `last`): tiles of `$mr` rows, then one tile of the remaining
/// rows (one of `$rem`, the sizes below `$mr`). One function per panel width and level, so that
/// only the tiles a level uses are compiled.
macro_rules! panel_fn {
    ($name:ident, $s:ty, $nv:literal, $mr:literal, [$($rem:literal)*]) => {
        /// See `panel_fn`.
        ///
        /// # Safety
        /// As [`tile`], for all `r.m` rows.
        #[inline(always)]
        unsafe fn $name<const FULL: bool>(s: $s, r: Raw, last: <$s as Lanes>::M) {
            let mut i = 0;
            // SAFETY (every call): rows `i..i + rows` lie inside `0..r.m`, so inside the operands.
            unsafe {
                while i + $mr <= r.m {
                    tile::<$s, $mr, $nv, FULL>(s, r.rows_from(i), last);
                    i += $mr;
                }
                let t = r.rows_from(i);
                match r.m - i {
                    $($rem => tile::<$s, $rem, $nv, FULL>(s, t, last),)*
                    _ => {}
                }
            }
        }
    };
}

panel_fn!(avx512_panel1, Avx512, 1, 24, [1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23]);
panel_fn!(avx512_panel2, Avx512, 2, 12, [1 2 3 4 5 6 7 8 9 10 11]);
panel_fn!(avx512_panel3, Avx512, 3, 8, [1 2 3 4 5 6 7]);
panel_fn!(avx512_panel4, Avx512, 4, 6, [1 2 3 4 5]);
panel_fn!(avx2_panel1, Avx2, 1, 12, [1 2 3 4 5 6 7 8 9 10 11]);
panel_fn!(avx2_panel2, Avx2, 2, 6, [1 2 3 4 5]);

/// The whole product `r` in column panels of up to `NV_MAX` vectors (the last panel as narrow
/// as its columns allow), each run by `panel(nv, full, sub, last)`: `nv` vectors, the last
/// masked by `last`, `full` if that mask is all lanes.
///
/// # Safety
/// `r` must lie inside its operands; the CPU must have `S`'s instructions; `panel` must run
/// the panel it is given as [`tile`] would (within its operands).
#[inline(always)]
unsafe fn product<S: Lanes, const NV_MAX: usize>(s: S, r: Raw, panel: impl Fn(usize, bool, Raw, S::M)) {
    let mut j = 0;
    while j < r.n {
        let cols = (r.n - j).min(NV_MAX * S::W);
        let nv = cols.div_ceil(S::W);
        let (sub, last) = (r.cols_from(j), s.mask(cols - (nv - 1) * S::W));
        // Columns `j..j + cols` lie inside `0..r.n`; the masks cover exactly them.
        panel(nv, cols == nv * S::W, sub, last);
        j += cols;
    }
}

/// A right-hand side in memory: element `(p, j)` at `b[p * rs + j * cs]`, with `cs == 1`
/// (rows contiguous, e.g. `x` in `dW += dy^T x`) or `rs == 1` (columns contiguous, e.g. `W^T`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Rhs {
    pub b: *const f32,
    pub rs: usize,
    pub cs: usize,
}

/// Copies the block `(p0 + p, j0 + j)`, `p < kb`, `j < nb`, of `src` to `buf[p * nb + j]`: rows
/// of `nb` contiguous columns. Contiguous rows are copied 8 values at a time, contiguous columns
/// transposed 8 x 8 in AVX registers; the edges value by value.
///
/// # Safety
/// The block must lie inside `src`'s matrix; `buf` must hold `kb * nb` values; the CPU must have
/// AVX.
#[inline(always)]
unsafe fn pack(src: Rhs, (j0, nb): (usize, usize), (p0, kb): (usize, usize), buf: *mut f32) {
    let (nb8, kb8) = (nb - nb % 8, kb - kb % 8);
    let at = |p: usize, j: usize| src.b.wrapping_add((p0 + p) * src.rs + (j0 + j) * src.cs);
    // SAFETY: every access is an element `(p, j)`, `p < kb`, `j < nb`, of the block or of
    // `buf`, all inside (the caller's guarantee).
    unsafe {
        if src.cs == 1 {
            for p in 0..kb {
                for j in (0..nb8).step_by(8) {
                    _mm256_storeu_ps(buf.add(p * nb + j), _mm256_loadu_ps(at(p, j)));
                }
                for j in nb8..nb {
                    *buf.add(p * nb + j) = *at(p, j);
                }
            }
            return;
        }
        debug_assert_eq!(src.rs, 1);
        for j in (0..nb8).step_by(8) {
            for p in (0..kb8).step_by(8) {
                let mut rows = [_mm256_setzero_ps(); 8];
                for (r, row) in rows.iter_mut().enumerate() {
                    *row = _mm256_loadu_ps(at(p, j + r));
                }
                for (q, row) in transpose8(rows).iter().enumerate() {
                    _mm256_storeu_ps(buf.add((p + q) * nb + j), *row);
                }
            }
        }
        for j in 0..nb {
            for p in if j < nb8 { kb8 } else { 0 }..kb {
                *buf.add(p * nb + j) = *at(p, j);
            }
        }
    }
}

/// The transpose of the 8 x 8 matrix whose rows are `r`.
///
/// # Safety
/// The CPU must have AVX.
#[inline(always)]
unsafe fn transpose8(r: [__m256; 8]) -> [__m256; 8] {
    // SAFETY: the caller guarantees AVX.
    unsafe {
        // Rows 2i and 2i + 1 interleaved, low and high pairs.
        let (t0, t1) = (_mm256_unpacklo_ps(r[0], r[1]), _mm256_unpackhi_ps(r[0], r[1]));
        let (t2, t3) = (_mm256_unpacklo_ps(r[2], r[3]), _mm256_unpackhi_ps(r[2], r[3]));
        let (t4, t5) = (_mm256_unpacklo_ps(r[4], r[5]), _mm256_unpackhi_ps(r[4], r[5]));
        let (t6, t7) = (_mm256_unpacklo_ps(r[6], r[7]), _mm256_unpackhi_ps(r[6], r[7]));
        // Columns c and c + 4 of four rows.
        let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
        let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
        let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
        let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
        let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
        let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
        let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
        let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
        [
            _mm256_permute2f128_ps::<0x20>(u0, u4),
            _mm256_permute2f128_ps::<0x20>(u1, u5),
            _mm256_permute2f128_ps::<0x20>(u2, u6),
            _mm256_permute2f128_ps::<0x20>(u3, u7),
            _mm256_permute2f128_ps::<0x31>(u0, u4),
            _mm256_permute2f128_ps::<0x31>(u1, u5),
            _mm256_permute2f128_ps::<0x31>(u2, u6),
            _mm256_permute2f128_ps::<0x31>(u3, u7),
        ]
    }
}

/// The product `r` with its right-hand side read from `rhs` (not `r.b`), copied block by block
/// (at most `nb_max` columns and `kb_max` rows, `nb_max * kb_max <= BUF` values) into a stack
/// buffer with [`pack`]: contiguous,
/// so that its rows do not compete for the same cache sets whatever the stride. Each depth
/// block's product accumulates onto the previous one's stored result (lossless: the same
/// unbroken chains); the epilogue (`r.fuse`) runs after the last.
///
/// # Safety
/// `r` (with `rhs`) must lie inside its operands; the CPU must have `S`'s instructions and AVX,
/// and `product` must compute a [`Raw`] inside its operands.
#[inline(always)]
unsafe fn blocked<S: Lanes>(
    (s, product): (S, unsafe fn(S, Raw)),
    r: Raw,
    (rhs, nb_max, kb_max): (Rhs, usize, usize),
) {
    debug_assert!(nb_max * kb_max <= BUF);
    let mut buf = MaybeUninit::<[f32; BUF]>::uninit();
    let bp = buf.as_mut_ptr().cast::<f32>();
    for j0 in (0..r.n).step_by(nb_max) {
        let nb = (r.n - j0).min(nb_max);
        for p0 in (0..r.k).step_by(kb_max) {
            let kb = (r.k - p0).min(kb_max);
            // SAFETY: the block lies inside `rhs` and fits the buffer (`kb * nb <= BUF`);
            // the product reads only the packed `kb x nb` values, depth `p0..p0 + kb` of `r.a`,
            // and columns `j0..j0 + nb` of `r.c`.
            unsafe {
                pack(rhs, (j0, nb), (p0, kb), bp);
                let (a, c, accumulate) = (r.a.add(p0 * r.a_cs), r.c.add(j0), r.accumulate || p0 > 0);
                // The bias and activation once, after the last depth block.
                let fuse = if p0 + kb == r.k { r.fuse } else { Fuse::None };
                let (bias, ys, bias_grad) =
                    (r.bias.wrapping_add(j0), r.ys.wrapping_add(j0), r.bias_grad.wrapping_add(j0));
                product(
                    s,
                    Raw { n: nb, k: kb, a, b: bp, b_rs: nb, c, accumulate, fuse, bias, ys, bias_grad, ..r },
                );
            }
        }
    }
}

/// Values in the stack buffer of [`panels`] (256 KiB: half of Zen 3's L2 cache, the rest for
/// a block of the left-hand side's rows and their outputs).
const BIG: usize = 65536;
/// Rows of a block of the left-hand side in [`panels`] (eight 6-row tiles: at depth 256,
/// 48 KiB, which stays in L2 while every panel of the packed right-hand side passes over it).
const AVX2_MC: usize = 48;

/// The product `r` with its right-hand side read from `rhs`, for AVX2's 16-column panels, in
/// the order of BLIS: a block of depth `kb` ([`avx2_kb`]) and up to [`BIG`]` / kb` columns is
/// copied once into a stack buffer, panel after panel (each `kb x 16` panel contiguous, 16 KiB
/// at most, so that it stays in L1 while the tiles of a row block pass over it); then for each
/// block of [`AVX2_MC`] rows, every panel. The rows of the left-hand side are read once from
/// memory and then from L2, rather than once a panel. Each element is still one chain in
/// increasing depth (a depth block accumulates onto the previous one's stored result), and the
/// rows of a column are visited in increasing order (the bias gradient's sums), so the bits are
/// those of [`blocked`].
///
/// # Safety
/// As [`blocked`], with AVX2.
#[inline(always)]
unsafe fn panels<S: Lanes>((s, product): (S, unsafe fn(S, Raw)), r: Raw, rhs: Rhs) {
    let mut buf = MaybeUninit::<[f32; BIG]>::uninit();
    let bp = buf.as_mut_ptr().cast::<f32>();
    let kb_max = avx2_kb(r);
    let nb_max = BIG / kb_max;
    for j0 in (0..r.n).step_by(nb_max) {
        let nb = (r.n - j0).min(nb_max);
        for p0 in (0..r.k).step_by(kb_max) {
            let kb = (r.k - p0).min(kb_max);
            // SAFETY: each panel lies inside `rhs` (columns `j0 + q..`, depth `p0..p0 + kb`) and
            // inside the buffer (`kb * nb <= BIG`); the products read the packed panels, depth
            // `p0..p0 + kb` of rows `i0..i0 + mc` of `r.a` and write those rows' columns
            // `j0 + q..j0 + q + w` of `r.c`.
            unsafe {
                for q in (0..nb).step_by(AVX2_NB) {
                    let w = (nb - q).min(AVX2_NB);
                    pack(rhs, (j0 + q, w), (p0, kb), bp.add(q * kb));
                }
                let accumulate = r.accumulate || p0 > 0;
                let fuse = if p0 + kb == r.k { r.fuse } else { Fuse::None };
                for i0 in (0..r.m).step_by(AVX2_MC) {
                    let mc = (r.m - i0).min(AVX2_MC);
                    let rows = r.rows_from(i0);
                    for q in (0..nb).step_by(AVX2_NB) {
                        let w = (nb - q).min(AVX2_NB);
                        let sub = rows.cols_from(j0 + q);
                        let (a, b) = (sub.a.add(p0 * r.a_cs), bp.add(q * kb));
                        product(s, Raw { m: mc, n: w, k: kb, a, b, b_rs: w, accumulate, fuse, ..sub });
                    }
                }
            }
        }
    }
}

/// [`Raw`] with AVX-512F: tiles of 6 rows x 64 columns (24 accumulators), 8 x 48, 12 x 32 and
/// 24 x 16 for narrower panels.
///
/// # Safety
/// `r` must lie inside its operands (the token proves the CPU has AVX-512F).
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn product_avx512(s: Avx512, r: Raw) {
    // Masked moves are cheap with AVX-512, so the last vector is always masked (`FULL` false).
    // SAFETY: the caller's guarantee; each panel lies inside `r`.
    unsafe {
        product::<Avx512, 4>(s, r, |nv, _, sub, last| match nv {
            1 => avx512_panel1::<false>(s, sub, last),
            2 => avx512_panel2::<false>(s, sub, last),
            3 => avx512_panel3::<false>(s, sub, last),
            _ => avx512_panel4::<false>(s, sub, last),
        })
    }
}

/// [`Raw`] with AVX2 and FMA: tiles of 6 rows x 16 columns (12 accumulators), 12 x 8 for one
/// vector.
///
/// # Safety
/// As [`product_avx512`].
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn product_avx2(s: Avx2, r: Raw) {
    // SAFETY: the caller's guarantee; each panel lies inside `r`.
    unsafe {
        product::<Avx2, 2>(s, r, |nv, full, sub, last| match (nv, full) {
            (1, true) => avx2_panel1::<true>(s, sub, last),
            (1, false) => avx2_panel1::<false>(s, sub, last),
            (2, true) => avx2_panel2::<true>(s, sub, last),
            _ => avx2_panel2::<false>(s, sub, last),
        })
    }
}

impl Raw {
    /// `c (m x n) (= | +=) a (m x k) b (k x n)` with the given strides, nothing fused.
    pub fn plain(
        (m, n, k): (usize, usize, usize),
        (a, a_rs, a_cs): (*const f32, usize, usize),
        (b, b_rs): (*const f32, usize),
        (c, c_rs): (*mut f32, usize),
        accumulate: bool,
    ) -> Raw {
        let (fuse, bias, ys, bias_grad) =
            (Fuse::None, std::ptr::null(), std::ptr::null(), std::ptr::null_mut());
        Raw { m, n, k, a, a_rs, a_cs, b, b_rs, c, c_rs, accumulate, fuse, bias, ys, bias_grad }
    }

    /// The forward product `y (m x n) = x (m x k) w^T`, then `fuse` with `bias`, without its
    /// right-hand side (`w`, packed by [`forward_avx512`] or [`forward_avx2`]).
    pub fn forward(
        (m, n, k): (usize, usize, usize),
        y: *mut f32,
        x: *const f32,
        (fuse, bias): (Fuse, *const f32),
    ) -> Raw {
        Raw { fuse, bias, ..Raw::plain((m, n, k), (x, k, 1), (std::ptr::null(), 0), (y, n), false) }
    }
}

/// [`Raw`] with its right-hand side copied into a stack buffer block by block ([`blocked`]),
/// with AVX-512F.
///
/// # Safety
/// `r` with `rhs` must lie inside its operands.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn packed_avx512(s: Avx512, r: Raw, rhs: Rhs) {
    // SAFETY: the caller's guarantee.
    unsafe { blocked((s, product_avx512), r, (rhs, COPY_NB, BUF / COPY_NB)) }
}

/// As [`packed_avx512`] with AVX2 and FMA.
///
/// # Safety
/// As [`packed_avx512`].
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn packed_avx2(s: Avx2, r: Raw, rhs: Rhs) {
    // SAFETY: the caller's guarantee.
    unsafe { panels((s, product_avx2), r, rhs) }
}

/// The forward product `r` (see [`Raw::forward`]) with the row-major `n x k` weight `w`, with
/// AVX-512F (the dot kernel for `n == 1`).
///
/// # Safety
/// `r`'s operands and `w` must hold the values they address, `k > 0`.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn forward_avx512(s: Avx512, r: Raw, w: *const f32) {
    // SAFETY: the caller's guarantee.
    unsafe {
        if r.n == 1 {
            dot_avx512(r, w);
        } else {
            let nb = forward_nb(r.k);
            blocked((s, product_avx512), r, (Rhs { b: w, rs: 1, cs: r.k }, nb, BUF / nb));
        }
    }
}

/// As [`forward_avx512`] with AVX2 and FMA.
///
/// # Safety
/// As [`forward_avx512`].
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn forward_avx2(s: Avx2, r: Raw, w: *const f32) {
    // SAFETY: the caller's guarantee.
    unsafe {
        if r.n == 1 {
            dot_avx2(s, r, w);
        } else {
            panels((s, product_avx2), r, Rhs { b: w, rs: 1, cs: r.k });
        }
    }
}

/// `fuse` applied to one sum (the scalar form of the tile's epilogue, same instructions).
///
/// # Safety
/// `bias` must be readable unless `fuse` is `Fuse::None`.
#[inline(always)]
unsafe fn fuse1(v: f32, fuse: Fuse, bias: *const f32) -> f32 {
    // SAFETY: the caller's guarantee; SSE is baseline on x86-64.
    unsafe {
        match fuse {
            // `Fuse::Deriv` belongs to `backward_input`, never a one-column forward product.
            Fuse::None | Fuse::Deriv(..) => v,
            Fuse::Bias => v + *bias,
            Fuse::BiasRelu => _mm_cvtss_f32(_mm_max_ss(_mm_set_ss(v + *bias), _mm_setzero_ps())),
        }
    }
}

/// The forward product `r` with one column: `y[i] = fuse(dot16(x[i, ..], w))` for `i < m` (see
/// `super::portable::dot16`): 16-lane registers of chains, the tail merged under a mask, then
/// the fixed tree; rows four at a time.
///
/// # Safety
/// `r.c`, `r.a`, `w` must hold `m`, `m * k`, `k` values; the CPU must have AVX-512F.
#[target_feature(enable = "avx512f")]
unsafe fn dot_avx512(r: Raw, w: *const f32) {
    let mut i = 0;
    // SAFETY: rows `i..i + R` lie inside `0..m` (the caller's guarantee covers them).
    unsafe {
        while i + 4 <= r.m {
            dot_rows_avx512::<4>(r.rows_from(i), w);
            i += 4;
        }
        while i < r.m {
            dot_rows_avx512::<1>(r.rows_from(i), w);
            i += 1;
        }
    }
}

/// Rows `0..R` of [`dot_avx512`].
///
/// # Safety
/// As [`dot_avx512`] with `m = R`; the CPU must have AVX-512F.
#[inline(always)]
unsafe fn dot_rows_avx512<const R: usize>(r: Raw, w: *const f32) {
    let (k, x, y) = (r.k, r.a, r.c);
    let (full, tail) = (k - k % 16, k % 16);
    let mask = ((1u32 << tail) - 1) as u16;
    // SAFETY: rows `0..R` of `x` (`k` values each), `w` (`k` values) and `y[..R]` are inside
    // (the caller's guarantee); the masked loads read only lanes below `k`.
    unsafe {
        let mut s = [_mm512_setzero_ps(); R];
        let mut p = 0;
        while p < full {
            let wv = _mm512_loadu_ps(w.add(p));
            for (i, s) in s.iter_mut().enumerate() {
                *s = _mm512_fmadd_ps(_mm512_loadu_ps(x.add(i * k + p)), wv, *s);
            }
            p += 16;
        }
        if tail != 0 {
            let wv = _mm512_maskz_loadu_ps(mask, w.add(p));
            for (i, s) in s.iter_mut().enumerate() {
                *s = _mm512_mask3_fmadd_ps(_mm512_maskz_loadu_ps(mask, x.add(i * k + p)), wv, *s, mask);
            }
        }
        for (i, s) in s.iter().enumerate() {
            let hi = _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(*s)));
            *y.add(i) = fuse1(tree8(_mm256_add_ps(_mm512_castps512_ps256(*s), hi)), r.fuse, r.bias);
        }
    }
}

/// As [`dot_avx512`] with AVX2 and FMA: lanes 0-7 and 8-15 of the 16 chains in two registers,
/// the tail merged with a blend.
///
/// # Safety
/// As [`dot_avx512`], with AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
unsafe fn dot_avx2(s: Avx2, r: Raw, w: *const f32) {
    let mut i = 0;
    // SAFETY: rows `i..i + R` lie inside `0..m` (the caller's guarantee covers them).
    unsafe {
        while i + 4 <= r.m {
            dot_rows_avx2::<4>(s, r.rows_from(i), w);
            i += 4;
        }
        while i < r.m {
            dot_rows_avx2::<1>(s, r.rows_from(i), w);
            i += 1;
        }
    }
}

/// Rows `0..R` of [`dot_avx2`].
///
/// # Safety
/// As [`dot_avx512`] with `m = R`; the CPU must have AVX2 and FMA.
#[inline(always)]
unsafe fn dot_rows_avx2<const R: usize>(s: Avx2, r: Raw, w: *const f32) {
    let (k, x, y) = (r.k, r.a, r.c);
    let (full, tail) = (k - k % 16, k % 16);
    let (m0, m1) = (s.mask(tail.min(8)), s.mask(tail.saturating_sub(8)));
    // SAFETY: as in `dot_rows_avx512`.
    unsafe {
        let mut lo = [_mm256_setzero_ps(); R];
        let mut hi = [_mm256_setzero_ps(); R];
        let mut p = 0;
        while p < full {
            let (w0, w1) = (_mm256_loadu_ps(w.add(p)), _mm256_loadu_ps(w.add(p + 8)));
            for i in 0..R {
                lo[i] = _mm256_fmadd_ps(_mm256_loadu_ps(x.add(i * k + p)), w0, lo[i]);
                hi[i] = _mm256_fmadd_ps(_mm256_loadu_ps(x.add(i * k + p + 8)), w1, hi[i]);
            }
            p += 16;
        }
        if tail != 0 {
            // Past the end when `tail <= 8`, but then `m1` is empty and nothing is read.
            let (w0, w1) = (_mm256_maskload_ps(w.add(p), m0), _mm256_maskload_ps(w.wrapping_add(p + 8), m1));
            for i in 0..R {
                let xr = x.add(i * k + p);
                let f0 = _mm256_fmadd_ps(_mm256_maskload_ps(xr, m0), w0, lo[i]);
                lo[i] = _mm256_blendv_ps(lo[i], f0, _mm256_castsi256_ps(m0));
                let f1 = _mm256_fmadd_ps(_mm256_maskload_ps(xr.wrapping_add(8), m1), w1, hi[i]);
                hi[i] = _mm256_blendv_ps(hi[i], f1, _mm256_castsi256_ps(m1));
            }
        }
        for i in 0..R {
            *y.add(i) = fuse1(tree8(_mm256_add_ps(lo[i], hi[i])), r.fuse, r.bias);
        }
    }
}
