//! Elementary functions written in plain IEEE-754 arithmetic, for the training hot paths.
//!
//! - [`exp_f32`], [`ln_f32`], [`tanh_f32`]: the activations and the squashed Gaussian head of
//!   SAC (`nn::SquashedGaussian`).
//! - [`ln_f64`], [`sin_cos_f64`]: the Box-Muller transform of [`crate::base::rng::Rng::normal`].
//!
//! Why not the C library's: (1) these are branch-free (selects, bit operations, polynomials),
//! so loops of them vectorise, where a call into libm runs one value at a time: they were 18 %
//! of a SAC update at hidden 64; (2) they use only `+ - * /` and `sqrt`, which IEEE-754 rounds
//! exactly, and Rust never fuses a multiply and an add on its own, so their results are the same
//! bits on every CPU, every SIMD level and every C library (glibc picks a different `expf` on
//! CPUs with FMA, and libm versions differ), which makes the agents' updates portable (the
//! environment's kinematics and reward still use the standard library's f64 functions).
//!
//! Accuracy (tested against the standard library over their domains): `exp_f32` and `ln_f32`
//! within 2 ulp, `ln_f64` and `sin_cos_f64` within 2 ulp (`sin_cos_f64` for |x| <= 1e5 rad).
//! The polynomials are Cephes' (`expf`, `logf`) and fdlibm's (`__ieee754_log`,
//! `__kernel_sin`, `__kernel_cos`).

/// 1.5 * 2^23: adding and subtracting it rounds an f32 of magnitude below 2^22 to an integer.
const ROUND_F32: f32 = 12_582_912.0;
/// 1.5 * 2^52: the same for f64 below 2^51.
const ROUND_F64: f64 = 6_755_399_441_055_744.0;

/// e^x for `f32`, within 2 ulp.
///
/// Below -87.33 (where e^x leaves the normal range) the result is 0; above 88.72 it is
/// infinity; NaN gives NaN.
#[inline(always)]
#[allow(clippy::excessive_precision)] // Cephes' published coefficients
pub fn exp_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_375;
    const LN2_LO: f32 = -2.121_944_4e-4;
    const MIN: f32 = -87.336_55;
    const MAX: f32 = 88.722_84;
    let xc = x.clamp(MIN, MAX);
    // n = round(x / ln 2), r = x - n ln 2 in [-ln2 / 2, ln2 / 2].
    let n = (LOG2E * xc + ROUND_F32) - ROUND_F32;
    let r = (xc - n * LN2_HI) - n * LN2_LO;
    let p = ((((1.987_569_150_0e-4 * r + 1.398_199_950_7e-3) * r + 8.333_451_907_3e-3) * r
        + 4.166_579_589_4e-2)
        * r
        + 1.666_666_545_9e-1)
        * r
        + 5.000_000_120_1e-1;
    let y = p * (r * r) + r + 1.0;
    // 2^n for n in [-126, 128]: n = 128 (x near MAX) is 2^127 * 2.
    let ni = n as i32;
    let half = ni >> 1;
    let s1 = f32::from_bits(((half + 127) as u32) << 23);
    let s2 = f32::from_bits(((ni - half + 127) as u32) << 23);
    let v = y * s1 * s2;
    if x < MIN {
        0.0
    } else if x > MAX {
        f32::INFINITY
    } else {
        v
    }
}

/// tanh for `f32` as a [13/6] odd/even rational function on [-7.905, 7.905] (the approximation of
/// Eigen's `generic_fast_tanh_float`), `x` itself below 4e-4 and +-1 beyond the clamp.
///
/// Branch-free, so loops of it auto-vectorise (glibc's `tanhf` is a scalar call through
/// `expm1f`); its error is a few ulp (checked against `f64::tanh` in the tests).
#[inline]
#[allow(clippy::excessive_precision)] // Eigen's published coefficients, rounded by the compiler
pub fn tanh_f32(x: f32) -> f32 {
    const CLAMP: f32 = 7.90531110763549805;
    const A1: f32 = 4.89352455891786e-03;
    const A3: f32 = 6.37261928875436e-04;
    const A5: f32 = 1.48572235717979e-05;
    const A7: f32 = 5.12229709037114e-08;
    const A9: f32 = -8.60467152213735e-11;
    const A11: f32 = 2.00018790482477e-13;
    const A13: f32 = -2.76076847742355e-16;
    const B0: f32 = 4.89352518554385e-03;
    const B2: f32 = 2.26843463243900e-03;
    const B4: f32 = 1.18534705686654e-04;
    const B6: f32 = 1.19825839466702e-06;
    let c = x.clamp(-CLAMP, CLAMP);
    let x2 = c * c;
    let p = ((((((A13 * x2 + A11) * x2 + A9) * x2 + A7) * x2 + A5) * x2 + A3) * x2 + A1) * c;
    let q = ((B6 * x2 + B4) * x2 + B2) * x2 + B0;
    if x.abs() < 4e-4 {
        x
    } else {
        p / q
    }
}

/// ln(x) for `f32`, within 2 ulp: -inf at 0, NaN below 0 and for NaN, inf at inf.
#[inline(always)]
#[allow(clippy::excessive_precision)] // Cephes' published coefficients
pub fn ln_f32(x: f32) -> f32 {
    const SQRT_HALF: f32 = std::f32::consts::FRAC_1_SQRT_2;
    // Subnormals are scaled into the normal range first.
    let tiny = x < f32::MIN_POSITIVE;
    let xs = if tiny { x * 8_388_608.0 } else { x };
    let bits = xs.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 126 - if tiny { 23 } else { 0 };
    // m in [0.5, 1); then m - 1 in [sqrt(1/2) - 1, sqrt(2) - 1) after the shift below.
    let m = f32::from_bits((bits & 0x807f_ffff) | 0x3f00_0000);
    let small = m < SQRT_HALF;
    e -= i32::from(small);
    let f = if small { m + m - 1.0 } else { m - 1.0 };
    let z = f * f;
    let mut y = ((((((((7.037_683_629_2e-2 * f - 1.151_461_031_0e-1) * f + 1.167_699_874_0e-1) * f
        - 1.242_014_084_6e-1)
        * f
        + 1.424_932_278_7e-1)
        * f
        - 1.666_805_766_5e-1)
        * f
        + 2.000_071_476_5e-1)
        * f
        - 2.499_999_399_3e-1)
        * f
        + 3.333_333_117_4e-1)
        * f
        * z;
    let fe = e as f32;
    y += -2.121_944_4e-4 * fe;
    y += -0.5 * z;
    let v = (f + y) + 0.693_359_375 * fe;
    if x == 0.0 {
        f32::NEG_INFINITY
    } else if x.is_nan() || x < 0.0 {
        f32::NAN
    } else if x == f32::INFINITY {
        f32::INFINITY
    } else {
        v
    }
}

/// ln(x) for `f64`, within 2 ulp (fdlibm's method): -inf at 0, NaN below 0 and for NaN, inf at
/// inf.
#[inline(always)]
#[allow(clippy::excessive_precision)] // fdlibm's published coefficients
pub fn ln_f64(x: f64) -> f64 {
    const LN2_HI: f64 = 6.931_471_803_691_238_164_90e-01;
    const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;
    const LG1: f64 = 6.666_666_666_666_735_130e-01;
    const LG2: f64 = 3.999_999_999_940_941_908e-01;
    const LG3: f64 = 2.857_142_874_366_239_149e-01;
    const LG4: f64 = 2.222_219_843_214_978_396e-01;
    const LG5: f64 = 1.818_357_216_161_805_012e-01;
    const LG6: f64 = 1.531_383_769_920_937_332e-01;
    const LG7: f64 = 1.479_819_860_511_658_591e-01;
    let tiny = x < f64::MIN_POSITIVE;
    let xs = if tiny { x * 18_014_398_509_481_984.0 } else { x }; // 2^54
    let bits = xs.to_bits();
    let mut k = ((bits >> 52) & 0x7ff) as i64 - 1023 - if tiny { 54 } else { 0 };
    // m in [1, 2), halved when above sqrt(2) so that f = m - 1 lies in [sqrt(1/2) - 1, sqrt(2) - 1].
    let m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    let big = m > std::f64::consts::SQRT_2;
    k += i64::from(big);
    let f = if big { 0.5 * m - 1.0 } else { m - 1.0 };
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (LG2 + w * (LG4 + w * LG6));
    let t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)));
    let r = t2 + t1;
    let hfsq = 0.5 * f * f;
    let dk = k as f64;
    let v = dk * LN2_HI - ((hfsq - (s * (hfsq + r) + dk * LN2_LO)) - f);
    if x == 0.0 {
        f64::NEG_INFINITY
    } else if x.is_nan() || x < 0.0 {
        f64::NAN
    } else if x == f64::INFINITY {
        f64::INFINITY
    } else {
        v
    }
}

/// `(sin x, cos x)` for `f64`, within 2 ulp for |x| <= 1e5 rad (fdlibm's kernels after a
/// two-part Cody-Waite reduction by pi/2; beyond 1e5 rad the reduction loses accuracy).
#[inline(always)]
#[allow(clippy::excessive_precision)] // fdlibm's published coefficients
pub fn sin_cos_f64(x: f64) -> (f64, f64) {
    const TWO_OVER_PI: f64 = std::f64::consts::FRAC_2_PI;
    const PIO2_1: f64 = 1.570_796_326_734_125_614_17e+00; // first 33 bits of pi/2
    const PIO2_1T: f64 = 6.077_100_506_506_192_249_32e-11; // pi/2 - PIO2_1
    const S1: f64 = -1.666_666_666_666_663_243_48e-01;
    const S2: f64 = 8.333_333_333_322_489_461_24e-03;
    const S3: f64 = -1.984_126_982_985_794_931_34e-04;
    const S4: f64 = 2.755_731_370_707_006_767_89e-06;
    const S5: f64 = -2.505_076_025_340_686_341_95e-08;
    const S6: f64 = 1.589_690_995_211_550_102_21e-10;
    const C1: f64 = 4.166_666_666_666_660_190_37e-02;
    const C2: f64 = -1.388_888_888_887_410_957_49e-03;
    const C3: f64 = 2.480_158_728_947_672_941_78e-05;
    const C4: f64 = -2.755_731_435_139_066_330_35e-07;
    const C5: f64 = 2.087_572_321_298_174_827_90e-09;
    const C6: f64 = -1.135_964_755_778_819_482_65e-11;
    // x = q pi/2 + r, |r| <= pi/4 (q * PIO2_1 is exact for |q| < 2^20).
    let q = (x * TWO_OVER_PI + ROUND_F64) - ROUND_F64;
    let r = (x - q * PIO2_1) - q * PIO2_1T;
    let z = r * r;
    let sin_r = r + z * r * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))));
    let rr = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let cos_r = w + (((1.0 - w) - hz) + z * rr);
    // sin(r + q pi/2) and cos(r + q pi/2) by the quadrant q mod 4.
    let quadrant = (q as i64) & 3;
    let (s, c) = if quadrant & 1 == 1 { (cos_r, sin_r) } else { (sin_r, cos_r) };
    let s = if quadrant & 2 == 2 { -s } else { s };
    let c = if (quadrant + 1) & 2 == 2 { -c } else { c };
    if x.is_finite() {
        (s, c)
    } else {
        (f64::NAN, f64::NAN)
    }
}

/// Arithmetic mean; `None` for no values.
pub fn mean(xs: &[f64]) -> Option<f64> {
    (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64)
}

/// Sample standard deviation `sqrt(sum (x - mean)^2 / (n - 1))`; `None` for fewer than two values.
pub fn sample_std(xs: &[f64]) -> Option<f64> {
    if xs.len() < 2 {
        return None;
    }
    let m = mean(xs)?;
    Some((xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (xs.len() - 1) as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small generator of its own (xorshift64*), so that these tests need no other module.
    struct Rng(u64);

    impl Rng {
        fn new(seed: u64) -> Self {
            Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }
        fn next_u64(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
        fn uniform(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
        }
        fn uniform_range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.uniform()
        }
    }

    /// Distance in units in the last place between two finite f32 of the same sign.
    fn ulp32(a: f32, b: f32) -> u32 {
        if a == b {
            return 0;
        }
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs() as u32
    }

    fn ulp64(a: f64, b: f64) -> u64 {
        if a == b {
            return 0;
        }
        (a.to_bits() as i128 - b.to_bits() as i128).unsigned_abs() as u64
    }

    #[test]
    fn exp_f32_within_two_ulp() {
        let mut rng = Rng::new(1);
        let mut worst = 0;
        for i in 0..400_000 {
            let x = if i < 200_000 { rng.uniform_range(-87.3, 88.7) } else { rng.uniform_range(-12.0, 3.0) }
                as f32;
            let want = (x as f64).exp() as f32;
            worst = worst.max(ulp32(exp_f32(x), want));
        }
        assert!(worst <= 2, "worst error {worst} ulp");
        assert_eq!(exp_f32(0.0), 1.0);
        assert_eq!(exp_f32(-100.0), 0.0);
        assert_eq!(exp_f32(100.0), f32::INFINITY);
        assert!(exp_f32(f32::NAN).is_nan());
        assert_eq!(exp_f32(f32::NEG_INFINITY), 0.0);
    }

    #[test]
    fn ln_f32_within_two_ulp() {
        let mut rng = Rng::new(2);
        let mut worst = 0;
        for i in 0..400_000 {
            let x = match i % 3 {
                0 => rng.uniform_range(1.0, 2.0) as f32,
                1 => (rng.uniform_range(-80.0, 80.0)).exp() as f32,
                _ => f32::from_bits((rng.next_u64() as u32) & 0x7fff_ffff),
            };
            if !x.is_finite() || x == 0.0 {
                continue;
            }
            let want = (x as f64).ln() as f32;
            worst = worst.max(ulp32(ln_f32(x), want));
        }
        assert!(worst <= 2, "worst error {worst} ulp");
        assert_eq!(ln_f32(1.0), 0.0);
        assert_eq!(ln_f32(0.0), f32::NEG_INFINITY);
        assert!(ln_f32(-1.0).is_nan() && ln_f32(f32::NAN).is_nan());
        assert_eq!(ln_f32(f32::INFINITY), f32::INFINITY);
    }

    #[test]
    fn ln_f64_within_two_ulp() {
        let mut rng = Rng::new(3);
        let mut worst = 0;
        for i in 0..400_000 {
            let x = match i % 3 {
                0 => 1.0 - rng.uniform(),
                1 => rng.uniform_range(-700.0, 700.0).exp(),
                _ => f64::from_bits(rng.next_u64() & 0x7fff_ffff_ffff_ffff),
            };
            if !x.is_finite() || x == 0.0 {
                continue;
            }
            worst = worst.max(ulp64(ln_f64(x), x.ln()));
        }
        assert!(worst <= 2, "worst error {worst} ulp");
        assert_eq!(ln_f64(1.0), 0.0);
        assert_eq!(ln_f64(0.0), f64::NEG_INFINITY);
        assert!(ln_f64(-1.0).is_nan() && ln_f64(f64::NAN).is_nan());
        assert_eq!(ln_f64(f64::INFINITY), f64::INFINITY);
    }

    #[test]
    fn sin_cos_f64_within_two_ulp() {
        let mut rng = Rng::new(4);
        let (mut worst_s, mut worst_c) = (0u64, 0u64);
        let mut worst_abs = 0.0f64;
        for i in 0..400_000 {
            let x =
                if i % 2 == 0 { std::f64::consts::TAU * rng.uniform() } else { rng.uniform_range(-1e5, 1e5) };
            let (s, c) = sin_cos_f64(x);
            let (ws, wc) = x.sin_cos();
            // Near a zero of sin or cos the result is tiny and ulps are meaningless: compare
            // those absolutely (to 2^-53 of the function's range).
            if ws.abs() > 1e-3 {
                worst_s = worst_s.max(ulp64(s, ws));
            } else {
                worst_abs = worst_abs.max((s - ws).abs());
            }
            if wc.abs() > 1e-3 {
                worst_c = worst_c.max(ulp64(c, wc));
            } else {
                worst_abs = worst_abs.max((c - wc).abs());
            }
        }
        assert!(worst_s <= 2 && worst_c <= 2, "worst error sin {worst_s} cos {worst_c} ulp");
        assert!(worst_abs < 1e-15, "worst absolute error near zeros {worst_abs}");
        assert_eq!(sin_cos_f64(0.0), (0.0, 1.0));
        let (s, c) = sin_cos_f64(f64::NAN);
        assert!(s.is_nan() && c.is_nan());
    }
}
