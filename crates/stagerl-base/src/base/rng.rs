//! The seeded random generator used by every stochastic part of stagerl.
//!
//! xoshiro256++ (Blackman and Vigna), seeded through SplitMix64. It is written out here rather than
//! taken from `rand` so that a seed gives the same stream whatever crate versions are resolved, and
//! so that its whole state (four words and a cached normal) can be saved in a checkpoint.

use serde::{Deserialize, Serialize};

use crate::multiversion;

/// xoshiro256++ with a Box-Muller normal sampler.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rng {
    s: [u64; 4],
    /// The second value of the last Box-Muller pair, if not yet used.
    spare_normal: Option<f64>,
}

/// One step of SplitMix64, used to expand a seed.
fn splitmix64(x: &mut u64) -> u64 {
    *x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// A generator seeded from `seed`; distinct seeds give unrelated streams.
    pub fn new(seed: u64) -> Self {
        let mut x = seed;
        let s = [splitmix64(&mut x), splitmix64(&mut x), splitmix64(&mut x), splitmix64(&mut x)];
        Rng { s, spare_normal: None }
    }

    /// A generator for stream `index` derived from `seed` (e.g. one per vectorised environment).
    pub fn derived(seed: u64, index: u64) -> Self {
        let mut x = seed ^ 0xD1B5_4A32_D192_ED03u64.wrapping_mul(index.wrapping_add(1));
        Rng::new(splitmix64(&mut x))
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1), 53 bits of precision.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    #[inline]
    pub fn uniform_range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Uniform integer in [0, n); `n` must be positive.
    #[inline]
    pub fn below(&mut self, n: u64) -> u64 {
        debug_assert!(n > 0);
        // Lemire's multiply-shift; the bias is below 2^-64 * n, irrelevant here.
        ((self.next_u64() as u128 * n as u128) >> 64) as u64
    }

    /// Standard normal sample (Box-Muller, both values used):
    /// `r = sqrt(-2 ln u1)`, `(r cos(2 pi u2), r sin(2 pi u2))` with `u1` in (0, 1], `u2` in
    /// [0, 1), the logarithm and sine/cosine of [`crate::base::math`] (the same bits on every CPU).
    #[inline]
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        let (u1, u2) = self.box_muller_uniforms();
        let (c, s) = box_muller(u1, u2);
        self.spare_normal = Some(s);
        c
    }

    /// Fills `out` with standard normal samples, as `normal() as f32` called `out.len()` times
    /// would (the same values, the same state afterwards), but with the transforms of whole
    /// blocks computed together so that they vectorise.
    pub fn fill_normal_f32(&mut self, out: &mut [f32]) {
        self.fill_normal_with(out, |z| z as f32);
    }

    /// As [`Rng::fill_normal_f32`], in `f64`: the values of `normal()` called `out.len()` times.
    pub fn fill_normal(&mut self, out: &mut [f64]) {
        self.fill_normal_with(out, |z| z);
    }

    fn fill_normal_with<T>(&mut self, out: &mut [T], convert: impl Fn(f64) -> T) {
        const PAIRS: usize = 32;
        let mut rest = out;
        if let Some(z) = self.spare_normal {
            let Some((first, tail)) = rest.split_first_mut() else { return };
            *first = convert(z);
            self.spare_normal = None;
            rest = tail;
        }
        let (mut u1, mut u2) = ([0.0f64; PAIRS], [0.0f64; PAIRS]);
        let (mut c, mut s) = ([0.0f64; PAIRS], [0.0f64; PAIRS]);
        while !rest.is_empty() {
            let pairs = rest.len().div_ceil(2).min(PAIRS);
            for i in 0..pairs {
                (u1[i], u2[i]) = self.box_muller_uniforms();
            }
            box_muller_block(&u1[..pairs], &u2[..pairs], &mut c[..pairs], &mut s[..pairs]);
            let n = rest.len().min(2 * pairs);
            let (block, tail) = rest.split_at_mut(n);
            for (i, pair) in block.chunks_mut(2).enumerate() {
                pair[0] = convert(c[i]);
                match pair.get_mut(1) {
                    Some(second) => *second = convert(s[i]),
                    None => self.spare_normal = Some(s[i]),
                }
            }
            rest = tail;
        }
    }

    /// The two uniforms of one Box-Muller pair: `u1` in (0, 1] (so that ln(u1) is finite), `u2`
    /// in [0, 1).
    #[inline]
    fn box_muller_uniforms(&mut self) -> (f64, f64) {
        let u1 = 1.0 - self.uniform();
        (u1, self.uniform())
    }
}

/// The Box-Muller pair `(r cos t, r sin t)`, `r = sqrt(-2 ln u1)`, `t = 2 pi u2`.
#[inline(always)]
fn box_muller(u1: f64, u2: f64) -> (f64, f64) {
    let r = (-2.0 * crate::base::math::ln_f64(u1)).sqrt();
    let (s, c) = crate::base::math::sin_cos_f64(std::f64::consts::TAU * u2);
    (r * c, r * s)
}

multiversion! {
    /// [`box_muller`] over blocks: `(c[i], s[i]) = box_muller(u1[i], u2[i])`.
    fn box_muller_block / box_muller_block_at(u1: &[f64], u2: &[f64], c: &mut [f64], s: &mut [f64]) {
        for (((&a, &b), c), s) in u1.iter().zip(u2).zip(c.iter_mut()).zip(s.iter_mut()) {
            (*c, *s) = box_muller(a, b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_stream_and_seeds_differ() {
        let mut a = Rng::new(7);
        let mut b = Rng::new(7);
        let mut c = Rng::new(8);
        let xa: Vec<u64> = (0..100).map(|_| a.next_u64()).collect();
        let xb: Vec<u64> = (0..100).map(|_| b.next_u64()).collect();
        let xc: Vec<u64> = (0..100).map(|_| c.next_u64()).collect();
        assert_eq!(xa, xb);
        assert_ne!(xa, xc);
    }

    #[test]
    fn known_first_output_pins_the_stream() {
        // Pins the algorithm: a silent change of generator would change every seeded run.
        let mut r = Rng::new(0);
        let first = r.next_u64();
        let mut again = Rng::new(0);
        assert_eq!(first, again.next_u64());
        assert_eq!(first, 0x53175d61490b23df, "xoshiro256++ seeded by splitmix64(0) changed");
    }

    #[test]
    fn uniform_and_normal_moments() {
        let mut r = Rng::new(42);
        let n = 200_000;
        let (mut su, mut sn, mut sn2) = (0.0, 0.0, 0.0);
        for _ in 0..n {
            let u = r.uniform();
            assert!((0.0..1.0).contains(&u));
            su += u;
            let z = r.normal();
            sn += z;
            sn2 += z * z;
        }
        let n = n as f64;
        assert!((su / n - 0.5).abs() < 0.005);
        assert!((sn / n).abs() < 0.01);
        assert!((sn2 / n - 1.0).abs() < 0.015);
    }

    #[test]
    fn below_stays_in_range_and_covers_it() {
        let mut r = Rng::new(3);
        let mut seen = [false; 7];
        for _ in 0..1000 {
            let k = r.below(7) as usize;
            seen[k] = true;
        }
        assert!(seen.iter().all(|&s| s));
    }

    #[test]
    fn fill_normal_f32_equals_repeated_normal() {
        // Every length around the block size, starting with and without a spare value.
        for start_with_spare in [false, true] {
            for len in [0, 1, 2, 3, 7, 63, 64, 65, 66, 127, 1536] {
                let mut a = Rng::new(len as u64);
                if start_with_spare {
                    a.normal();
                }
                let mut b = a.clone();
                let want: Vec<f32> = (0..len).map(|_| a.normal() as f32).collect();
                let mut got = vec![f32::NAN; len];
                let mut c = b.clone();
                b.fill_normal_f32(&mut got);
                let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "len {len}, spare {start_with_spare}");
                assert_eq!(a, b, "state after len {len}, spare {start_with_spare}");
                let mut got64 = vec![f64::NAN; len];
                c.fill_normal(&mut got64);
                assert!(got64.iter().zip(&want).all(|(&x, &w)| x as f32 == w), "f64, len {len}");
                assert_eq!(a, c, "f64 state after len {len}, spare {start_with_spare}");
            }
        }
    }

    #[test]
    fn box_muller_block_bit_identical_at_every_level() {
        use crate::base::simd::SimdLevel;
        let mut r = Rng::new(5);
        let n = 101;
        let (u1, u2): (Vec<f64>, Vec<f64>) = (0..n).map(|_| r.box_muller_uniforms()).unzip();
        let run = |level| {
            let (mut c, mut s) = (vec![0.0; n], vec![0.0; n]);
            box_muller_block_at(level, &u1, &u2, &mut c, &mut s);
            c.iter().chain(&s).map(|v| v.to_bits()).collect::<Vec<_>>()
        };
        let base = run(SimdLevel::Baseline);
        assert_eq!(run(SimdLevel::Avx512), base);
        assert_eq!(run(SimdLevel::Avx2), base);
        // And the scalar path agrees.
        let scalar: Vec<u64> = {
            let pairs: Vec<(f64, f64)> = u1.iter().zip(&u2).map(|(&a, &b)| box_muller(a, b)).collect();
            pairs.iter().map(|p| p.0.to_bits()).chain(pairs.iter().map(|p| p.1.to_bits())).collect()
        };
        assert_eq!(scalar, base);
    }

    #[test]
    fn normal_pinned_values() {
        // Pins the sampler (Box-Muller over crate::base::math): a change would change every seeded run.
        let mut r = Rng::new(0);
        let z: Vec<f64> = (0..4).map(|_| r.normal()).collect();
        let mut again = Rng::new(0);
        let u1 = 1.0 - again.uniform();
        let u2 = again.uniform();
        let radius = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        assert!((z[0] - radius * c).abs() < 1e-14 && (z[1] - radius * s).abs() < 1e-14, "{z:?}");
    }
}
