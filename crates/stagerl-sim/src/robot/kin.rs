//! The compiled chain and its hot loops: forward kinematics and the geometric Jacobian.
//!
//! A chain `T = O_1 J_1(q_1) O_2 J_2(q_2) ... J_n(q_n) O_tip` (URDF origins `O`, joint motions `J`
//! about or along a unit axis `a`, fixed joints multiplied into the neighbouring origins) is
//! rewritten with a constant rotation `A` per joint, `A z = a`, so that `J(q) = A Z(q) A^T` with
//! `Z` a rotation about (or translation along) the local z axis. `A` and `A^T` are folded into the
//! constants on either side, so evaluating the chain is `base`, then for each joint a cheap `Z(q)`
//! on two columns (revolute) or one (prismatic) fused with one constant 3x4 product.
//!
//! Speed (UR5, ~140 ns per FK on the development machine, where `k` takes ~320 ns): the
//! transform is held by columns with the rows as SIMD lanes (no shuffles), the constants are
//! pre-broadcast, and the sines and cosines of up to [`CHUNK`] joints are computed first by a
//! branch-free kernel the compiler vectorises, so they overlap instead of forming one latency
//! chain with the matrix products. No heap allocation.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::Pose;

/// A rigid transform `[R | t]` as a row-major 3x4 matrix: `m[4 * r + c]`, column 3 = translation.
pub(crate) type Tf = [f64; 12];

/// The identity transform.
pub(crate) const IDENTITY: Tf = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// `a * b` for rigid transforms.
#[inline(always)]
pub(crate) fn mul(a: &Tf, b: &Tf) -> Tf {
    let mut o = [0.0; 12];
    mul_columns(a, b, 0, &mut o);
    o
}

/// Columns `from..4` of [`mul`]`(a, b)` into `o` (the others left as they are), with the same
/// products in the same order, so the same bits: `from = 2` gives the product's z axis and
/// translation, all a capsule's or a sphere's placement reads.
#[inline(always)]
pub(crate) fn mul_columns(a: &Tf, b: &Tf, from: usize, o: &mut Tf) {
    for r in 0..3 {
        let (a0, a1, a2, a3) = (a[4 * r], a[4 * r + 1], a[4 * r + 2], a[4 * r + 3]);
        for c in from..4 {
            o[4 * r + c] = a0 * b[c] + a1 * b[4 + c] + a2 * b[8 + c];
        }
        o[4 * r + 3] += a3;
    }
}

/// `Trans(xyz) * Rz(yaw) * Ry(pitch) * Rx(roll)`: a URDF `<origin>` with `rpy = (roll, pitch, yaw)`.
pub(crate) fn origin(xyz: [f64; 3], rpy: [f64; 3]) -> Tf {
    let (sr, cr) = rpy[0].sin_cos();
    let (sp, cp) = rpy[1].sin_cos();
    let (sy, cy) = rpy[2].sin_cos();
    [
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        xyz[0],
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        xyz[1],
        -sp,
        cp * sr,
        cp * cr,
        xyz[2],
    ]
}

/// A rotation `A` (as a transform with zero translation) whose third column is the unit vector `n`,
/// so `A z = n`; exact for `n = +-z` (Duff et al., "Building an orthonormal basis, revisited").
pub(crate) fn basis_for_axis(n: [f64; 3]) -> Tf {
    let [x, y, z] = n;
    let sign = 1.0f64.copysign(z);
    let a = -1.0 / (sign + z);
    let b = x * y * a;
    let b1 = [1.0 + sign * x * x * a, sign * b, -sign * x];
    let b2 = [b, sign + y * y * a, -y];
    [
        b1[0], b2[0], n[0], 0.0, //
        b1[1], b2[1], n[1], 0.0, //
        b1[2], b2[2], n[2], 0.0,
    ]
}

/// The transpose of the rotation part (translation left zero): the inverse of a pure rotation.
pub(crate) fn rotation_transpose(a: &Tf) -> Tf {
    [
        a[0], a[4], a[8], 0.0, //
        a[1], a[5], a[9], 0.0, //
        a[2], a[6], a[10], 0.0,
    ]
}

/// One actuated joint of a compiled chain.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Step {
    /// Translation along local z (`true`) or rotation about it.
    pub prismatic: bool,
    /// Constant from this joint's (z-aligned) frame to the next joint's frame, or to the tip.
    pub after: Tf,
}

/// Two lanes, the unit of the hot loops (one SSE2 register on x86-64).
type V2 = [f64; 2];

#[inline(always)]
fn splat(v: f64) -> V2 {
    [v, v]
}
#[inline(always)]
fn vadd(a: V2, b: V2) -> V2 {
    [a[0] + b[0], a[1] + b[1]]
}
#[inline(always)]
fn vsub(a: V2, b: V2) -> V2 {
    [a[0] - b[0], a[1] - b[1]]
}
#[inline(always)]
fn vmul(a: V2, b: V2) -> V2 {
    [a[0] * b[0], a[1] * b[1]]
}

/// A 3x4 transform by columns for the hot loops: `cols[c] = [[m0c, m1c], [m2c, 0]]`. The lanes
/// are rows, so every operation is lane-wise and needs no shuffles.
type Cols = [[V2; 2]; 4];

/// [`Step`] in hot-loop form: each constant element broadcast to both lanes.
#[derive(Clone, Debug)]
struct LaneStep {
    prismatic: bool,
    /// `after[4 * r + c]` is element `(r, c)` of [`Step::after`], in both lanes.
    after: [V2; 12],
}

/// A chain compiled to `base * Z(q_1) * after_1 * ... * Z(q_n) * after_n`.
#[derive(Clone, Debug)]
pub(crate) struct Kinematics {
    /// From the root link to the first joint's z-aligned frame.
    base: Cols,
    steps: Vec<LaneStep>,
}

// fdlibm's minimax kernels for sin and cos on [-pi/4, pi/4] (Sun Microsystems, freely usable;
// the same coefficients as musl's `__sin` / `__cos`), each within 1 ulp, and the pi/2 constants of
// its argument reduction. Written with fdlibm's digits so they can be checked against it.
#[allow(clippy::excessive_precision)]
mod fdlibm {
    pub(super) const S1: f64 = -1.666_666_666_666_663_243_48e-1;
    pub(super) const S2: f64 = 8.333_333_333_322_489_461_24e-3;
    pub(super) const S3: f64 = -1.984_126_982_985_794_931_34e-4;
    pub(super) const S4: f64 = 2.755_731_370_707_006_767_89e-6;
    pub(super) const S5: f64 = -2.505_076_025_340_686_341_95e-8;
    pub(super) const S6: f64 = 1.589_690_995_211_550_102_21e-10;
    pub(super) const C1: f64 = 4.166_666_666_666_660_190_37e-2;
    pub(super) const C2: f64 = -1.388_888_888_887_410_957_49e-3;
    pub(super) const C3: f64 = 2.480_158_728_947_672_941_78e-5;
    pub(super) const C4: f64 = -2.755_731_435_139_066_330_35e-7;
    pub(super) const C5: f64 = 2.087_572_321_298_174_827_90e-9;
    pub(super) const C6: f64 = -1.135_964_755_778_819_482_65e-11;
    /// The first 33 bits of pi / 2 (so `n * PIO2_1` is exact for `|n| < 2^20`), and the rest.
    pub(super) const PIO2_1: f64 = 1.570_796_326_734_125_614_17;
    pub(super) const PIO2_1T: f64 = 6.077_100_506_506_192_249_32e-11;
}
use fdlibm::*;
/// 2 / pi.
const INV_PIO2: f64 = std::f64::consts::FRAC_2_PI;

/// Adding and subtracting 1.5 * 2^52 rounds to the nearest integer (for `|x| < 2^51`).
const TO_INT: f64 = 6_755_399_441_055_744.0;
/// Beyond this `|x|` (or for a non-finite `x`) [`sin_cos`] defers to `f64::sin_cos`.
const FAST_SIN_COS_MAX: f64 = 1.0e5;

/// `(sin x, cos x)` sharing one argument reduction: Cody-Waite reduction by pi/2 (two-part
/// constant; the reduced argument's absolute error is below `|x| * 2e-21` for `|x| <= 1e5`), the
/// fdlibm kernels, and a branch-free quadrant fix-up. Within 2 ulp of `f64::sin_cos`.
#[inline(always)]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    // NaN fails the comparison and takes the standard library's path too.
    if x.abs() <= FAST_SIN_COS_MAX {
        sin_cos_kernel(x)
    } else {
        sin_cos_std(x)
    }
}

/// [`sin_cos`] for `|x| <= FAST_SIN_COS_MAX`, without a branch (so loops of it vectorise).
#[inline(always)]
fn sin_cos_kernel(x: f64) -> (f64, f64) {
    // big = 1.5 * 2^52 + n with n = round(2x / pi): n's low bits are big's low mantissa bits.
    let big = x * INV_PIO2 + TO_INT;
    let n = big.to_bits();
    let nf = big - TO_INT;
    let r = (x - nf * PIO2_1) - nf * PIO2_1T;
    let z = r * r;
    let w = z * z;
    let ps = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
    let s = r + z * r * (S1 + z * ps);
    let pc = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
    let hz = 0.5 * z;
    let one_minus_hz = 1.0 - hz;
    let c = one_minus_hz + (((1.0 - one_minus_hz) - hz) + z * pc);
    // Quadrant n mod 4: (s, c), (c, -s), (-s, -c), (-c, s).
    let swap = (n & 1).wrapping_neg();
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let a = (sb & !swap) | (cb & swap);
    let b = (cb & !swap) | (sb & swap);
    let sin = f64::from_bits(a ^ ((n & 2) << 62));
    let cos = f64::from_bits(b ^ ((n.wrapping_add(1) & 2) << 62));
    (sin, cos)
}

/// The rare path of [`sin_cos`], kept out of line so it does not shape the hot loop.
#[cold]
#[inline(never)]
fn sin_cos_std(x: f64) -> (f64, f64) {
    x.sin_cos()
}

/// `m * Z(q) * after`, where `Z(q)` is `Rz(q)` (revolute, `sc = sin_cos(q)`) or `Tz(q)`
/// (prismatic, `sc` unused), applied to the first two columns (or the translation) on the fly.
#[inline(always)]
fn advance(m: &Cols, prismatic: bool, q: f64, sc: (f64, f64), k: &[V2; 12]) -> Cols {
    times_after(&moved(m, prismatic, q, sc), k)
}

/// `m * Z(q)`: the first half of [`advance`].
#[inline(always)]
fn moved(m: &Cols, prismatic: bool, q: f64, sc: (f64, f64)) -> Cols {
    let [c0, c1, c2, mut t] = *m;
    if prismatic {
        let vq = splat(q);
        for h in 0..2 {
            t[h] = vadd(t[h], vmul(vq, c2[h]));
        }
        return [c0, c1, c2, t];
    }
    let (vs, vc) = (splat(sc.0), splat(sc.1));
    let mut x = [[0.0; 2]; 2];
    let mut y = [[0.0; 2]; 2];
    for h in 0..2 {
        x[h] = vadd(vmul(vc, c0[h]), vmul(vs, c1[h]));
        y[h] = vsub(vmul(vc, c1[h]), vmul(vs, c0[h]));
    }
    [x, y, c2, t]
}

/// `f * after`: the second half of [`advance`].
#[inline(always)]
fn times_after(f: &Cols, k: &[V2; 12]) -> Cols {
    let [x, y, c2, t] = *f;
    let mut o = [[[0.0; 2]; 2]; 4];
    for (j, oj) in o.iter_mut().enumerate() {
        for h in 0..2 {
            oj[h] = vadd(vadd(vmul(x[h], k[j]), vmul(y[h], k[4 + j])), vmul(c2[h], k[8 + j]));
        }
    }
    for h in 0..2 {
        o[3][h] = vadd(o[3][h], t[h]);
    }
    o
}

/// Joints per pass of the hot loops: the sines and cosines of a chunk are computed first, as
/// independent work the CPU overlaps, instead of one long latency chain per joint.
pub(crate) const CHUNK: usize = 8;

/// `sin_cos` of up to [`CHUNK`] values (the rest of the array is `(0, 1)`). Computed for every
/// joint, prismatic ones included (unused there), in one branch-free loop the compiler vectorises.
#[inline(always)]
pub(crate) fn sin_cos_chunk(q: &[f64]) -> [(f64, f64); CHUNK] {
    let mut x = [0.0; CHUNK];
    x[..q.len()].copy_from_slice(q);
    let mut sc = [(0.0, 1.0); CHUNK];
    if x.iter().all(|v| v.abs() <= FAST_SIN_COS_MAX) {
        for (o, &xi) in sc.iter_mut().zip(&x) {
            *o = sin_cos_kernel(xi);
        }
    } else {
        for (o, &xi) in sc.iter_mut().zip(&x) {
            *o = sin_cos(xi);
        }
    }
    sc
}

fn to_cols(m: &Tf) -> Cols {
    let mut c = [[[0.0; 2]; 2]; 4];
    for (j, cj) in c.iter_mut().enumerate() {
        *cj = [[m[j], m[4 + j]], [m[8 + j], 0.0]];
    }
    c
}

#[inline(always)]
fn from_cols(c: &Cols) -> Tf {
    let mut m = [0.0; 12];
    for (j, cj) in c.iter().enumerate() {
        m[j] = cj[0][0];
        m[4 + j] = cj[0][1];
        m[8 + j] = cj[1][0];
    }
    m
}

impl Kinematics {
    /// The chain `base * Z(q_1) * steps[0].after * ... * Z(q_n) * steps[n-1].after`.
    pub fn new(base: &Tf, steps: &[Step]) -> Self {
        let steps =
            steps.iter().map(|s| LaneStep { prismatic: s.prismatic, after: s.after.map(splat) }).collect();
        Kinematics { base: to_cols(base), steps }
    }

    /// The first joint's origin in the root frame, metres.
    pub fn first_joint_origin(&self) -> [f64; 3] {
        let t = self.base[3];
        [t[0][0], t[0][1], t[1][0]]
    }

    /// The lengths of the constant links after each joint (to the next joint or the tip), metres.
    pub fn link_lengths(&self) -> impl Iterator<Item = f64> + '_ {
        self.steps.iter().map(|s| {
            let (x, y, z) = (s.after[3][0], s.after[7][0], s.after[11][0]);
            (x * x + y * y + z * z).sqrt()
        })
    }

    /// The tip transform in the root frame. Joint values past `steps.len()` are ignored; missing
    /// ones leave the remaining joints out (callers check the length).
    #[inline]
    pub fn fk_tf(&self, q: &[f64]) -> Tf {
        #[cfg(target_arch = "x86_64")]
        if crate::base::simd::avx2_enabled() {
            // SAFETY: the CPU has AVX2 (`avx2_enabled` checked it).
            return unsafe { self.fk_tf_avx2(q) };
        }
        self.fk_tf_body(q)
    }

    /// [`Kinematics::fk_tf`] compiled for AVX2 (the same operations, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn fk_tf_avx2(&self, q: &[f64]) -> Tf {
        self.fk_tf_body(q)
    }

    #[inline(always)]
    fn fk_tf_body(&self, q: &[f64]) -> Tf {
        let mut m = self.base;
        for (steps, q) in self.steps.chunks(CHUNK).zip(q.chunks(CHUNK)) {
            let sc = sin_cos_chunk(q);
            for ((s, &qi), &sc) in steps.iter().zip(q).zip(&sc) {
                m = advance(&m, s.prismatic, qi, sc, &s.after);
            }
        }
        from_cols(&m)
    }

    /// The frames along the chain: `at(i, z_i, p_i)` for each joint `i` (its axis and origin in
    /// the root frame, before its motion), then the tip transform.
    #[inline(always)]
    fn walk(&self, q: &[f64], mut at: impl FnMut(usize, [f64; 3], [f64; 3])) -> Cols {
        let mut m = self.base;
        let mut sc = [(0.0, 1.0); CHUNK];
        for (i, (s, &qi)) in self.steps.iter().zip(q).enumerate() {
            if i % CHUNK == 0 {
                sc = sin_cos_chunk(&q[i..q.len().min(i + CHUNK)]);
            }
            let (z, p) = (m[2], m[3]);
            at(i, [z[0][0], z[0][1], z[1][0]], [p[0][0], p[0][1], p[1][0]]);
            m = advance(&m, s.prismatic, qi, sc[i % CHUNK], &s.after);
        }
        m
    }

    /// Each joint's z-aligned frame after its motion, in the root frame (the first `out.len()`
    /// when it is shorter than `n`): [`Kinematics::fk_tf`]'s pass with each frame kept between
    /// the joint's motion and the constant after it (the same products in the same order).
    pub fn segment_frames(&self, q: &[f64], out: &mut [Tf]) {
        #[cfg(target_arch = "x86_64")]
        if crate::base::simd::avx2_enabled() {
            // SAFETY: the CPU has AVX2 (`avx2_enabled` checked it).
            return unsafe { self.segment_frames_avx2(q, out) };
        }
        self.segment_frames_body(q, out)
    }

    /// [`Kinematics::segment_frames`] compiled for AVX2 (the same operations, so the same bits:
    /// no fused multiply-adds).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn segment_frames_avx2(&self, q: &[f64], out: &mut [Tf]) {
        self.segment_frames_body(q, out)
    }

    #[inline(always)]
    fn segment_frames_body(&self, q: &[f64], out: &mut [Tf]) {
        let mut m = self.base;
        let mut sc = [(0.0, 1.0); CHUNK];
        for (i, ((s, &qi), o)) in self.steps.iter().zip(q).zip(out.iter_mut()).enumerate() {
            if i % CHUNK == 0 {
                sc = sin_cos_chunk(&q[i..q.len().min(i + CHUNK)]);
            }
            let f = moved(&m, s.prismatic, qi, sc[i % CHUNK]);
            *o = from_cols(&f);
            m = times_after(&f, &s.after);
        }
    }

    /// The tip transform from the last of [`Kinematics::segment_frames`]: the same product in
    /// the same order as [`Kinematics::fk_tf`], so the same transform to the bit (`None` for
    /// a chain without joints).
    pub fn tip_from_last_frame(&self, last: &Tf) -> Option<Tf> {
        self.steps.last().map(|s| from_cols(&times_after(&to_cols(last), &s.after)))
    }

    /// The origin of every joint frame (in the root frame, metres), then the tip's: `n + 1`
    /// points, the arm's skeleton.
    pub fn joint_origins(&self, q: &[f64]) -> Vec<[f64; 3]> {
        let mut points = Vec::with_capacity(self.steps.len() + 1);
        let m = self.walk(q, |_, _, p| points.push(p));
        points.push([m[3][0][0], m[3][0][1], m[3][1][0]]);
        points
    }

    /// Geometric Jacobian, row-major `6 x n` into `jac` (`jac.len() >= 6 n`), and the tip transform.
    #[inline]
    pub fn jacobian_tf(&self, q: &[f64], jac: &mut [f64]) -> Tf {
        let n = self.steps.len();
        let jac = &mut jac[..6 * n];
        // First pass: joint origins p_i into rows 0..3, joint axes z_i into rows 3..6.
        let m = self.walk(q, |i, z, p| {
            for r in 0..3 {
                jac[r * n + i] = p[r];
                jac[(r + 3) * n + i] = z[r];
            }
        });
        let tip = [m[3][0][0], m[3][0][1], m[3][1][0]];
        // Second pass: revolute [z x (p_tip - p); z], prismatic [z; 0].
        for (i, s) in self.steps.iter().enumerate() {
            let z = [jac[3 * n + i], jac[4 * n + i], jac[5 * n + i]];
            if s.prismatic {
                for r in 0..3 {
                    jac[r * n + i] = z[r];
                    jac[(r + 3) * n + i] = 0.0;
                }
            } else {
                let d = [tip[0] - jac[i], tip[1] - jac[n + i], tip[2] - jac[2 * n + i]];
                jac[i] = z[1] * d[2] - z[2] * d[1];
                jac[n + i] = z[2] * d[0] - z[0] * d[2];
                jac[2 * n + i] = z[0] * d[1] - z[1] * d[0];
            }
        }
        from_cols(&m)
    }
}

/// Unit quaternion `[w, x, y, z]` with `w >= 0` of the rotation part of `m` (Shepperd's method:
/// the largest of `4w^2, 4x^2, 4y^2, 4z^2` is taken from the diagonal, so no cancellation).
#[inline]
pub(crate) fn quaternion_wxyz(m: &Tf) -> [f64; 4] {
    let (r00, r01, r02) = (m[0], m[1], m[2]);
    let (r10, r11, r12) = (m[4], m[5], m[6]);
    let (r20, r21, r22) = (m[8], m[9], m[10]);
    let tr = r00 + r11 + r22;
    let mut q = if tr >= r00 && tr >= r11 && tr >= r22 {
        let s = 2.0 * (1.0 + tr).sqrt();
        [0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s]
    } else if r00 >= r11 && r00 >= r22 {
        let s = 2.0 * (1.0 + r00 - r11 - r22).sqrt();
        [(r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s]
    } else if r11 >= r22 {
        let s = 2.0 * (1.0 + r11 - r00 - r22).sqrt();
        [(r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s]
    } else {
        let s = 2.0 * (1.0 + r22 - r00 - r11).sqrt();
        [(r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s]
    };
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let k = if q[0] < 0.0 { -1.0 / norm } else { 1.0 / norm };
    for v in &mut q {
        *v *= k;
    }
    q
}

/// The [`Pose`] of a transform.
#[inline]
pub(crate) fn pose_of(m: &Tf) -> Pose {
    let [w, x, y, z] = quaternion_wxyz(m);
    Pose {
        position: Vector3::new(m[3], m[7], m[11]),
        orientation: UnitQuaternion::new_unchecked(Quaternion::new(w, x, y, z)),
    }
}

#[cfg(test)]
mod tests {
    use crate::base::rng::Rng;

    /// The AVX2 builds of the forward kinematics give the bits of the baseline build (the
    /// same operations: no fused multiply-adds), on the bundled arms at random joint values,
    /// some beyond the fast sine's range.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_avx2_builds_give_the_baseline_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("skipped: this CPU has no AVX2, so no AVX2 build runs here");
            return;
        }
        let mut rng = Rng::new(5);
        for chain in ["ur5", "panda"].map(|r| crate::robot::Chain::load(r, None).unwrap()) {
            let (kin, n) = (&chain.kin, chain.dof());
            let (mut a, mut b) = (vec![[0.0; 12]; n], vec![[0.0; 12]; n]);
            for i in 0..2000 {
                let scale = if i % 100 == 0 { 3e5 } else { 7.0 };
                let q: Vec<f64> = (0..n).map(|_| rng.uniform_range(-scale, scale)).collect();
                // SAFETY: the CPU has AVX2 (checked above).
                let (fa, fb) = (unsafe { kin.fk_tf_avx2(&q) }, kin.fk_tf_body(&q));
                assert_eq!(fa.map(f64::to_bits), fb.map(f64::to_bits), "q = {q:?}");
                // SAFETY: as above.
                unsafe { kin.segment_frames_avx2(&q, &mut a) };
                kin.segment_frames_body(&q, &mut b);
                assert_eq!(a, b, "q = {q:?}");
            }
        }
    }
}
