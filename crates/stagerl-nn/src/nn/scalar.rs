//! The floating-point element type of the engine: [`Scalar`], implemented for `f32` and `f64`.
//!
//! Training runs in `f32`; the gradient checks run in `f64`. The trait is sealed: the matrix
//! products (`super::matmul`) run SIMD kernels for `f32` and portable loops for `f64`, and
//! know no other type.

use std::fmt::{Debug, Display};
use std::iter::Sum;
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::base::math::tanh_f32;

mod sealed {
    /// Only `f32` and `f64`; lets the matrix products find their `f32` kernels.
    pub trait Sealed: Sized {
        /// The slice as `f32` values, if `Self` is `f32`.
        #[doc(hidden)]
        fn as_f32(s: &[Self]) -> Option<&[f32]>;
        /// The slice as `f32` values, if `Self` is `f32`.
        #[doc(hidden)]
        fn as_f32_mut(s: &mut [Self]) -> Option<&mut [f32]>;
    }
    impl Sealed for f32 {
        #[inline]
        fn as_f32(s: &[f32]) -> Option<&[f32]> {
            Some(s)
        }
        #[inline]
        fn as_f32_mut(s: &mut [f32]) -> Option<&mut [f32]> {
            Some(s)
        }
    }
    impl Sealed for f64 {
        #[inline]
        fn as_f32(_: &[f64]) -> Option<&[f32]> {
            None
        }
        #[inline]
        fn as_f32_mut(_: &mut [f64]) -> Option<&mut [f32]> {
            None
        }
    }
}

/// A real floating-point type the engine computes in (`f32` or `f64`).
pub trait Scalar:
    sealed::Sealed
    + Copy
    + Debug
    + Display
    + Default
    + PartialEq
    + PartialOrd
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Sum
    + Serialize
    + DeserializeOwned
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;

    /// Nearest value of this type to `x`.
    fn from_f64(x: f64) -> Self;
    /// `self` widened (or kept) as `f64`.
    fn to_f64(self) -> f64;
    /// `n` as this type (exact below 2^24 for `f32`).
    #[inline]
    fn from_usize(n: usize) -> Self {
        Self::from_f64(n as f64)
    }
    /// e^self (for `f32` the vectorisable [`crate::base::math::exp_f32`], for `f64` the standard
    /// library's).
    fn exp(self) -> Self;
    /// e^self - 1, accurate near 0.
    fn exp_m1(self) -> Self;
    /// Natural logarithm (for `f32` the vectorisable [`crate::base::math::ln_f32`], for `f64` the
    /// standard library's).
    fn ln(self) -> Self;
    /// ln(1 + self), accurate near 0.
    fn ln_1p(self) -> Self;
    /// Hyperbolic tangent (for `f32` the vectorisable rational approximation [`tanh_f32`],
    /// for `f64` the standard library's).
    fn tanh(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Larger of the two (the other one if one is NaN, as `f64::max`).
    fn max(self, other: Self) -> Self;
    /// Smaller of the two (the other one if one is NaN, as `f64::min`).
    fn min(self, other: Self) -> Self;
    /// Neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// `self * a + b` rounded once (a fused multiply-add; computed in software, slowly, where
    /// the CPU or the build lacks the instruction).
    fn mul_add(self, a: Self, b: Self) -> Self;

    /// softplus(x) = ln(1 + e^x), computed as max(x, 0) + ln(1 + e^-|x|) so that it neither
    /// overflows for large x nor loses precision for very negative x.
    #[inline]
    fn softplus(self) -> Self {
        self.max(Self::ZERO) + (-self.abs()).exp().ln_1p()
    }

    /// The logistic sigmoid 1 / (1 + e^-x), computed without overflow for either sign.
    #[inline]
    fn sigmoid(self) -> Self {
        if self >= Self::ZERO {
            Self::ONE / (Self::ONE + (-self).exp())
        } else {
            let e = self.exp();
            e / (Self::ONE + e)
        }
    }
}

macro_rules! impl_scalar {
    ($t:ty, $tanh:expr, $exp:expr, $ln:expr) => {
        impl Scalar for $t {
            #[inline]
            fn tanh(self) -> Self {
                $tanh(self)
            }
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const EPSILON: Self = <$t>::EPSILON;

            #[inline]
            fn from_f64(x: f64) -> Self {
                x as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn exp(self) -> Self {
                $exp(self)
            }
            #[inline]
            fn exp_m1(self) -> Self {
                <$t>::exp_m1(self)
            }
            #[inline]
            fn ln(self) -> Self {
                $ln(self)
            }
            #[inline]
            fn ln_1p(self) -> Self {
                <$t>::ln_1p(self)
            }
            #[inline]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline]
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            #[inline]
            fn min(self, other: Self) -> Self {
                <$t>::min(self, other)
            }
            #[inline]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline]
            fn mul_add(self, a: Self, b: Self) -> Self {
                <$t>::mul_add(self, a, b)
            }
        }
    };
}

impl_scalar!(f32, tanh_f32, crate::base::math::exp_f32, crate::base::math::ln_f32);
impl_scalar!(f64, f64::tanh, f64::exp, f64::ln);

#[cfg(test)]
mod tests {
    use super::*;

    fn softplus_naive(x: f64) -> f64 {
        (1.0 + x.exp()).ln()
    }

    #[test]
    fn softplus_and_sigmoid_are_stable_and_correct() {
        for &x in &[-30.0, -5.0, -0.3, 0.0, 0.7, 4.0, 20.0] {
            assert!((Scalar::softplus(x) - softplus_naive(x)).abs() <= 1e-12 * (1.0 + x.abs()));
            let s = Scalar::sigmoid(x);
            assert!((s - 1.0 / (1.0 + (-x).exp())).abs() <= 1e-15);
        }
        // Where the naive forms overflow.
        assert_eq!(Scalar::softplus(1000.0f64), 1000.0);
        assert_eq!(Scalar::softplus(-1000.0f64), 0.0);
        assert_eq!(Scalar::sigmoid(-1000.0f64), 0.0);
        assert_eq!(Scalar::softplus(200.0f32), 200.0);
    }

    #[test]
    fn fast_f32_tanh_is_accurate() {
        // Dense grid on [-12, 12] plus a log grid of small magnitudes, both signs.
        let grid = (0..=2_000_000)
            .map(|i| -12.0 + 24.0 * i as f64 / 2e6)
            .chain((0..=90_000).map(|i| 10f64.powf(-8.0 + 9.0 * i as f64 / 9e4)));
        let mut max_rel = 0.0f64;
        for x in grid {
            for x in [x as f32, -x as f32] {
                let exact = (x as f64).tanh();
                let got = tanh_f32(x) as f64;
                let rel = (got - exact).abs() / exact.abs().max(1e-30);
                max_rel = max_rel.max(rel);
            }
        }
        assert!(max_rel < 4.0 * f32::EPSILON as f64, "max relative error {max_rel}");
        assert_eq!(tanh_f32(0.0), 0.0);
        assert_eq!(tanh_f32(100.0), 1.0);
        assert_eq!(tanh_f32(-100.0), -1.0);
        assert!(tanh_f32(f32::NAN).is_nan());
    }

    #[test]
    fn conversions_round_trip() {
        assert_eq!(<f32 as Scalar>::from_f64(0.5).to_f64(), 0.5);
        assert_eq!(<f64 as Scalar>::from_usize(7), 7.0);
    }
}
