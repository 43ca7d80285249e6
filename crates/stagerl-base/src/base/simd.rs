//! Run-time SIMD dispatch for the element-wise loops of the training hot path.
//!
//! The release build targets baseline x86-64 (SSE2) so that it runs on any x86-64 CPU. The
//! matrix products (`nn::matmul`) have their own AVX-512F and AVX2 + FMA kernels, chosen at
//! run time by [`simd_level`] as well; the element-wise loops (bias and
//! activation, their backward passes, Adam, Polyak averaging, norms, the squashed Gaussian head,
//! the Box-Muller sampler) do the same through
//! [`multiversion!`](crate::multiversion!): the loop is written once and compiled three times, for AVX-512F, for
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

/// The environment variable that caps the SIMD level (`avx512`, `avx2` or `baseline`; unset: the
/// widest the CPU has), for measuring and checking a narrower instruction set on a wider CPU.
/// Results are the same bits at every level (see the module docs); only the speed changes.
pub const SIMD_ENV: &str = "STAGERL_SIMD";

impl SimdLevel {
    /// The level's name, as [`SIMD_ENV`] takes it.
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Avx512 => "avx512",
            SimdLevel::Avx2 => "avx2",
            SimdLevel::Baseline => "baseline",
        }
    }

    fn rank(self) -> u8 {
        match self {
            SimdLevel::Baseline => 0,
            SimdLevel::Avx2 => 1,
            SimdLevel::Avx512 => 2,
        }
    }
}

/// The widest level this CPU has.
fn detected_level() -> SimdLevel {
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

/// The cap [`SIMD_ENV`] sets (`None`: unset or empty). Errors: a value that is not a level's
/// name (the command line and the Python module refuse it at start; [`simd_level`] ignores it).
pub fn simd_cap() -> crate::Result<Option<SimdLevel>> {
    let Some(value) = std::env::var_os(SIMD_ENV) else { return Ok(None) };
    let text = value.to_string_lossy();
    let levels = [SimdLevel::Avx512, SimdLevel::Avx2, SimdLevel::Baseline];
    match levels.into_iter().find(|l| l.name().eq_ignore_ascii_case(text.trim())) {
        Some(level) => Ok(Some(level)),
        None if text.trim().is_empty() => Ok(None),
        None => Err(crate::Error::config(
            SIMD_ENV,
            format!("{text:?}"),
            "one of avx512, avx2, baseline (a cap on the instruction set; unset: the widest the CPU has)",
        )),
    }
}

/// Whether code compiled for AVX2 (without FMA) may run: the CPU has AVX2 and [`simd_level`]
/// (capped by [`SIMD_ENV`]) is not the baseline. For the kinematics and the contact checks, whose
/// AVX2 builds give the baseline's bits.
#[inline]
pub fn avx2_enabled() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && simd_level() != SimdLevel::Baseline
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The level [`multiversion!`](crate::multiversion!) functions, the matrix products and the
/// kinematics run at: the widest this CPU has, capped by [`SIMD_ENV`] (read once).
#[inline]
pub fn simd_level() -> SimdLevel {
    static LEVEL: std::sync::OnceLock<SimdLevel> = std::sync::OnceLock::new();
    *LEVEL.get_or_init(|| {
        let hardware = detected_level();
        match simd_cap() {
            Ok(Some(cap)) if cap.rank() < hardware.rank() => cap,
            _ => hardware,
        }
    })
}

/// Defines `fn name<T: Scalar>(args) body` (or a function without a type parameter) so that `body` is compiled for AVX-512F, for AVX2 +
/// FMA and for the baseline, and the widest version the CPU supports runs (see the module docs).
///
/// Written `fn name / name_at<T: Bound>(args) -> Ret { body }`: `name_at(level, args)` is the
/// same function at a given level (the baseline where the CPU lacks it), for the tests that
/// compare the versions.
///
/// Exported at the crate's root (`stagerl_base::multiversion`) for the network engine's crate.
#[macro_export]
macro_rules! multiversion {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident / $name_at:ident $(<$T:ident : $bound:path>)? ($($arg:ident : $ty:ty),* $(,)?) $(-> $ret:ty)?
        $body:block
    ) => {
        $(#[$meta])*
        #[inline]
        $vis fn $name $(<$T: $bound>)? ($($arg: $ty),*) $(-> $ret)? {
            $name_at $(::<$T>)? ($crate::base::simd::simd_level(), $($arg),*)
        }

        /// The same function at a given SIMD level (the baseline where the CPU lacks it).
        #[allow(dead_code)]
        #[inline]
        pub(crate) fn $name_at $(<$T: $bound>)? (level: $crate::base::simd::SimdLevel, $($arg: $ty),*) $(-> $ret)? {
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
                let detected = $crate::base::simd::simd_level();
                match level {
                    // SAFETY: the CPU supports AVX-512F (detected at run time).
                    $crate::base::simd::SimdLevel::Avx512 if detected == $crate::base::simd::SimdLevel::Avx512 => {
                        return unsafe { avx512 $(::<$T>)? ($($arg),*) }
                    }
                    // SAFETY: the CPU supports AVX2 and FMA (the Avx512 level implies both).
                    $crate::base::simd::SimdLevel::Avx2 if detected != $crate::base::simd::SimdLevel::Baseline => {
                        return unsafe { avx2 $(::<$T>)? ($($arg),*) }
                    }
                    _ => {}
                }
            }
            body $(::<$T>)? ($($arg),*)
        }
    };
}
