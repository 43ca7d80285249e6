//! Run-time SIMD dispatch for the engine's element-wise loops.
//!
//! The release build targets baseline x86-64 (SSE2) so that it runs on any x86-64 CPU. The
//! matrix products dispatch at run time inside `gemm`; the element-wise loops (bias and
//! activation, their backward passes, Adam, Polyak averaging, norms) do the same through
//! [`multiversion!`]: the loop is written once and compiled three times, for AVX-512F, for
//! AVX2 + FMA and for the baseline, and the widest version the CPU supports runs.
//!
//! Results are bit-identical whichever version runs: each element's arithmetic is the same
//! sequence of IEEE-754 operations (Rust never contracts `a * b + c` into a fused multiply-add,
//! whatever the target features), and reductions keep their explicit order. A test compares the
//! versions bit for bit.

/// Which instruction-set level the element-wise loops run at on this CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimdLevel {
    /// AVX-512F (16 f32 lanes).
    Avx512,
    /// AVX2 with FMA (8 f32 lanes).
    Avx2,
    /// The build's baseline (SSE2 on x86-64).
    Baseline,
}

/// The level [`multiversion!`] functions run at on this CPU (detected once, then cached by the
/// standard library).
#[inline]
pub fn simd_level() -> SimdLevel {
    #[cfg(target_arch = "x86_64")]
    {
        let avx2 = std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma");
        if avx2 && std::arch::is_x86_feature_detected!("avx512f") {
            return SimdLevel::Avx512;
        }
        if avx2 {
            return SimdLevel::Avx2;
        }
    }
    SimdLevel::Baseline
}

/// Defines `fn name<T: Scalar>(args) body` (or a function without a type parameter) so that `body` is compiled for AVX-512F, for AVX2 +
/// FMA and for the baseline, and the widest version the CPU supports runs (see the module docs).
///
/// Written `fn name / name_at<T: Bound>(args) -> Ret { body }`: `name_at(level, args)` is the
/// same function at a given level (the baseline where the CPU lacks it), for the tests that
/// compare the versions.
macro_rules! multiversion {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident / $name_at:ident $(<$T:ident : $bound:path>)? ($($arg:ident : $ty:ty),* $(,)?) $(-> $ret:ty)?
        $body:block
    ) => {
        $(#[$meta])*
        #[inline]
        $vis fn $name $(<$T: $bound>)? ($($arg: $ty),*) $(-> $ret)? {
            $name_at $(::<$T>)? ($crate::nn::simd::simd_level(), $($arg),*)
        }

        /// The same function at a given SIMD level (the baseline where the CPU lacks it).
        #[allow(dead_code)]
        #[inline]
        pub(crate) fn $name_at $(<$T: $bound>)? (level: $crate::nn::simd::SimdLevel, $($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn body $(<$T: $bound>)? ($($arg: $ty),*) $(-> $ret)? $body

            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f")]
                unsafe fn avx512 $(<$T: $bound>)? ($($arg: $ty),*) $(-> $ret)? {
                    body $(::<$T>)? ($($arg),*)
                }
                #[target_feature(enable = "avx2,fma")]
                unsafe fn avx2 $(<$T: $bound>)? ($($arg: $ty),*) $(-> $ret)? {
                    body $(::<$T>)? ($($arg),*)
                }
                let detected = $crate::nn::simd::simd_level();
                match level {
                    // SAFETY: the CPU supports AVX-512F (detected at run time).
                    $crate::nn::simd::SimdLevel::Avx512 if detected == $crate::nn::simd::SimdLevel::Avx512 => {
                        return unsafe { avx512 $(::<$T>)? ($($arg),*) }
                    }
                    // SAFETY: the CPU supports AVX2 and FMA (the Avx512 level implies both).
                    $crate::nn::simd::SimdLevel::Avx2 if detected != $crate::nn::simd::SimdLevel::Baseline => {
                        return unsafe { avx2 $(::<$T>)? ($($arg),*) }
                    }
                    _ => {}
                }
            }
            body $(::<$T>)? ($($arg),*)
        }
    };
}

pub(crate) use multiversion;

#[cfg(test)]
mod tests {
    use super::SimdLevel;
    use crate::nn::activation::{backward_kernel_at, backward_sum_kernel_at, bias_apply_kernel_at};
    use crate::nn::adam::{adam_kernel_at, Coefs};
    use crate::nn::ops::{polyak_kernel_at, scale_at, sum_of_squares_at};
    use crate::nn::Activation;
    use crate::rng::Rng;

    const LEVELS: [SimdLevel; 3] = [SimdLevel::Avx512, SimdLevel::Avx2, SimdLevel::Baseline];

    /// Values of every magnitude, both signs, zeros, subnormals and a lane-count-unfriendly length.
    fn values(rng: &mut Rng, n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| match i % 7 {
                0 => 0.0,
                1 => -(f32::MIN_POSITIVE / 3.0) * rng.uniform() as f32,
                2 => (rng.normal() * 1e-20) as f32,
                3 => (rng.normal() * 1e6) as f32,
                _ => rng.normal() as f32,
            })
            .collect()
    }

    fn bits(x: &[f32]) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// Every multiversioned loop gives the same bits at every level (where the CPU has it).
    #[test]
    fn every_level_is_bit_identical() {
        let mut rng = Rng::new(11);
        let (rows, cols) = (37, 29);
        let n = rows * cols;
        let (y0, g0, b0, p0, m0) = (
            values(&mut rng, n),
            values(&mut rng, n),
            values(&mut rng, cols),
            values(&mut rng, n),
            values(&mut rng, n),
        );
        let v0: Vec<f32> = values(&mut rng, n).iter().map(|v| v * v).collect();
        let mut outs: Vec<Vec<Vec<u32>>> = Vec::new();
        for level in LEVELS {
            let mut out = Vec::new();
            for act in [Activation::Identity, Activation::Relu, Activation::Tanh] {
                let mut y = y0.clone();
                bias_apply_kernel_at(level, act, &mut y, &b0);
                let (mut g, mut gb) = (g0.clone(), b0.clone());
                backward_sum_kernel_at(level, act, &y, &mut g, &mut gb);
                let mut g2 = g0.clone();
                backward_kernel_at(level, act, &y, &mut g2);
                out.extend([bits(&y), bits(&g), bits(&gb), bits(&g2)]);
            }
            let (mut p, mut m, mut v) = (p0.clone(), m0.clone(), v0.clone());
            let c = Coefs {
                b1: 0.9,
                b2: 0.999,
                c1: 0.1,
                c2: 1e-3,
                step_size: 1e-3,
                inv_sqrt_bias2: 3.7,
                eps: 1e-8,
            };
            adam_kernel_at(level, &mut p, &g0, &mut m, &mut v, c);
            out.extend([bits(&p), bits(&m), bits(&v)]);
            let mut t = p0.clone();
            polyak_kernel_at(level, &mut t, &y0, 0.995, 0.005);
            scale_at(level, &mut t, 0.37);
            out.push(bits(&t));
            out.push(vec![sum_of_squares_at(level, &g0).to_bits()]);
            outs.push(out);
        }
        assert_eq!(outs[0], outs[2], "AVX-512 (or its fallback) differs from the baseline");
        assert_eq!(outs[1], outs[2], "AVX2 (or its fallback) differs from the baseline");
    }
}
