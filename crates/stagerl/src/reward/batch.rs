//! The rewards over many rows at once (what `stagerl.rewards.compute` runs over numpy arrays),
//! bit for bit [`RewardTerms::compute`] on each row.
//!
//! A row's terms are a short chain of square roots and divisions around one `acos` (eq. 5's
//! phi). Computed a row at a time, that chain's latency and the `acos` call left the core idle
//! for most of a row. Here the rows go in blocks of [`BLOCK`], in three passes that each call
//! the same functions as `compute`: the distance, eq. 5's cosine and eq. 9's movement of every
//! row of the block, compiled for the widest SIMD level the CPU has (the same IEEE operations
//! per row, so the same bits, see [`crate::base::simd`]); then every `acos`; then the remaining terms
//! ([`RewardTerms::from_parts`]), written to their columns. A block with a bad row is scanned
//! again a row at a time, so the error is that of the first bad row, as with
//! [`RewardTerms::try_compute`] row by row.

use std::mem::MaybeUninit;

use nalgebra::Vector3;

use super::{angle_from_cosine, direction_cosine, movement_reward, RewardConfig, RewardInput, RewardTerms};
use crate::base::simd::SimdLevel;
use crate::{Error, Result};
use stagerl_base::multiversion;

/// The float columns of [`compute_rows`]: the names of [`RewardTerms::reported`] but `reached`,
/// in that order.
pub const COLUMNS: usize = 11;

/// Rows per block: the passes' intermediate values (four arrays of this many `f64`) stay in
/// the L1 cache.
pub const BLOCK: usize = 64;

/// Rows of reward input, row-major: row `i` is `ee_pos[3i..3i + 3]` (metres),
/// `ee_quat[4i..4i + 4]` (x, y, z, w), `target[3i..3i + 3]` (metres), `joint_vel[j i..j i + j]`
/// (rad/s, `j` = `joints`) and, when given, `prev_ee_pos[3i..3i + 3]` (metres).
#[derive(Clone, Copy, Debug)]
pub struct Rows<'a> {
    ee_pos: &'a [f64],
    ee_quat: &'a [f64],
    target: &'a [f64],
    joint_vel: &'a [f64],
    joints: usize,
    prev_ee_pos: Option<&'a [f64]>,
}

impl<'a> Rows<'a> {
    /// The rows of these slices, or an error naming the slice whose length does not fit the
    /// number of rows `ee_pos` gives (`joints` >= 1).
    pub fn new(
        ee_pos: &'a [f64],
        ee_quat: &'a [f64],
        target: &'a [f64],
        joint_vel: &'a [f64],
        joints: usize,
        prev_ee_pos: Option<&'a [f64]>,
    ) -> Result<Self> {
        if joints == 0 {
            return Err(Error::config("joints", 0, "one or more joints per row"));
        }
        if !ee_pos.len().is_multiple_of(3) {
            return Err(Error::InvalidInput(format!("ee_pos has {} values, not 3 per row", ee_pos.len())));
        }
        let n = ee_pos.len() / 3;
        let fields = [
            ("ee_quat", ee_quat.len(), 4),
            ("target", target.len(), 3),
            ("joint_vel", joint_vel.len(), joints),
        ];
        let prev = prev_ee_pos.map(|p| ("prev_ee_pos", p.len(), 3));
        for (name, len, per_row) in fields.into_iter().chain(prev) {
            if len != n * per_row {
                return Err(Error::InvalidInput(format!(
                    "{name} has {len} values; {n} rows (from ee_pos) need {} ({per_row} per row)",
                    n * per_row
                )));
            }
        }
        Ok(Rows { ee_pos, ee_quat, target, joint_vel, joints, prev_ee_pos })
    }

    /// The number of rows.
    pub fn len(&self) -> usize {
        self.ee_pos.len() / 3
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.ee_pos.is_empty()
    }

    /// Row `i` as a reward input.
    #[inline(always)]
    pub fn input(&self, i: usize) -> RewardInput<'a> {
        RewardInput { joint_vel: &self.joint_vel[self.joints * i..self.joints * (i + 1)], ..self.pose(i) }
    }

    /// Row `i` as a reward input without its joint velocities (an empty `joint_vel`).
    #[inline(always)]
    fn pose(&self, i: usize) -> RewardInput<'a> {
        let v3 = |a: &[f64]| Vector3::new(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
        RewardInput {
            ee_pos: v3(self.ee_pos),
            ee_quat: [
                self.ee_quat[4 * i],
                self.ee_quat[4 * i + 1],
                self.ee_quat[4 * i + 2],
                self.ee_quat[4 * i + 3],
            ],
            target: v3(self.target),
            joint_vel: &[],
            prev_ee_pos: self.prev_ee_pos.map(v3),
        }
    }
}

/// The first row refused by [`compute_rows`] and why ([`RewardTerms::try_compute`]'s error).
#[derive(Debug)]
pub struct BadRow {
    /// Its index among all the rows.
    pub row: usize,
    /// What is wrong with it.
    pub error: Error,
}

impl std::fmt::Display for BadRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "row {}: {}", self.row, self.error)
    }
}

/// Rows `start..start + reached.len()` of `rows`: row `start + k`'s reported terms go to
/// `cols[c][k]` (the [`COLUMNS`] float terms in [`RewardTerms::reported`]'s order) and
/// `reached[k]`, each value that of [`RewardTerms::try_compute`] on [`Rows::input`]. Every value
/// is written unless a row is refused; then the first refused row's error is returned (and the
/// columns hold unspecified values).
pub fn compute_rows(
    cfg: &RewardConfig,
    dt_s: f64,
    rows: &Rows<'_>,
    start: usize,
    cols: &mut [&mut [MaybeUninit<f64>]; COLUMNS],
    reached: &mut [bool],
) -> std::result::Result<(), BadRow> {
    compute_rows_at(crate::base::simd::simd_level(), cfg, dt_s, rows, start, cols, reached)
}

/// [`compute_rows`] with its vector loops at SIMD level `level` (for the tests that compare
/// the levels).
fn compute_rows_at(
    level: SimdLevel,
    cfg: &RewardConfig,
    dt_s: f64,
    rows: &Rows<'_>,
    start: usize,
    cols: &mut [&mut [MaybeUninit<f64>]; COLUMNS],
    reached: &mut [bool],
) -> std::result::Result<(), BadRow> {
    let n = reached.len();
    assert!(
        cols.iter().all(|c| c.len() == n) && start + n <= rows.len(),
        "columns of {n} values within the rows"
    );
    let (mut distance, mut cosine, mut movement) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
    let mut done = 0;
    while done < n {
        let b = BLOCK.min(n - done);
        let block = rows.block(start + done, b);
        let valid = block.all_valid(level);
        geometry_at(level, cfg, &block, &mut distance[..b], &mut cosine[..b]);
        block.movement(level, dt_s, &mut movement[..b]);
        // `cosine` becomes phi in place.
        for c in &mut cosine[..b] {
            *c = angle_from_cosine(*c);
        }
        let mut out: [&mut [MaybeUninit<f64>]; COLUMNS] = std::array::from_fn(|_| &mut [][..]);
        for (dst, col) in out.iter_mut().zip(cols.iter_mut()) {
            *dst = &mut col[done..done + b];
        }
        let finite = finish_at(
            level,
            cfg,
            &distance[..b],
            &cosine[..b],
            &movement[..b],
            &mut out,
            &mut reached[done..done + b],
        );
        if !(valid && finite) {
            first_bad(cfg, dt_s, rows, start + done..start + done + b)?;
        }
        done += b;
    }
    Ok(())
}

impl<'a> Rows<'a> {
    /// Rows `first..first + len` as rows of their own (row 0 is row `first`).
    fn block(&self, first: usize, len: usize) -> Rows<'a> {
        fn part(a: &[f64], per_row: usize, first: usize, len: usize) -> &[f64] {
            &a[per_row * first..per_row * (first + len)]
        }
        let part = |a: &'a [f64], per_row: usize| part(a, per_row, first, len);
        Rows {
            ee_pos: part(self.ee_pos, 3),
            ee_quat: part(self.ee_quat, 4),
            target: part(self.target, 3),
            joint_vel: part(self.joint_vel, self.joints),
            joints: self.joints,
            prev_ee_pos: self.prev_ee_pos.map(|p| part(p, 3)),
        }
    }

    /// Whether every row is [`RewardInput::is_valid`] (each value finite, each quaternion's norm
    /// within 1e-6 of 1), as vector loops.
    fn all_valid(&self, level: SimdLevel) -> bool {
        let finite = |values: &[f64]| finite_all_at(level, values);
        finite(self.ee_pos)
            & finite(self.ee_quat)
            & finite(self.target)
            & finite(self.joint_vel)
            & self.prev_ee_pos.is_none_or(finite)
            & unit_all_at(level, self.ee_quat)
    }

    /// R_move of each row (eq. 9, [`movement_reward`]); a vector loop for the common joint counts.
    fn movement(&self, level: SimdLevel, dt_s: f64, out: &mut [f64]) {
        match self.joints {
            6 => movement_of_at::<Joints<6>>(level, self.joint_vel, dt_s, out),
            7 => movement_of_at::<Joints<7>>(level, self.joint_vel, dt_s, out),
            j => {
                for (m, v) in out.iter_mut().zip(self.joint_vel.chunks_exact(j)) {
                    *m = movement_reward(v, dt_s);
                }
            }
        }
    }
}

multiversion! {
    /// Whether every value is finite.
    #[allow(dead_code)] // called as `finite_all_at`, at `compute_rows_at`'s level
    fn finite_all / finite_all_at(values: &[f64]) -> bool {
        values.iter().fold(true, |all, x| all & x.is_finite())
    }
}

multiversion! {
    /// Whether every quaternion (4 values each) has a norm within 1e-6 of 1, as
    /// [`RewardInput::is_valid`] tests it.
    #[allow(dead_code)] // called as `unit_all_at`, at `compute_rows_at`'s level
    fn unit_all / unit_all_at(quats: &[f64]) -> bool {
        quats.chunks_exact(4).fold(true, |all, q| all & ((super::quat_norm(&[q[0], q[1], q[2], q[3]]) - 1.0).abs() <= 1e-6))
    }
}

/// A joint count known when compiling, for [`movement_of`].
pub(crate) trait JointCount {
    const N: usize;
}

/// `N` joints.
pub(crate) struct Joints<const N: usize>;

impl<const N: usize> JointCount for Joints<N> {
    const N: usize = N;
}

multiversion! {
    /// R_move of each row of `J` joint velocities.
    #[allow(dead_code)] // called as `movement_of_at`, at `compute_rows_at`'s level
    fn movement_of / movement_of_at<J: JointCount>(joint_vel: &[f64], dt_s: f64, out: &mut [f64]) {
        for (m, v) in out.iter_mut().zip(joint_vel.chunks_exact(J::N)) {
            *m = movement_reward(v, dt_s);
        }
    }
}

multiversion! {
    /// D_PT and eq. 5's cosine of each row, as [`RewardTerms::compute`] gets them.
    #[allow(dead_code)] // called as `geometry_at`, at `compute_rows_at`'s level
    fn geometry / geometry_at(cfg: &RewardConfig, rows: &Rows<'_>, distance: &mut [f64], cosine: &mut [f64]) {
        for (k, (d, c)) in distance.iter_mut().zip(cosine.iter_mut()).enumerate() {
            let input = rows.pose(k);
            let to_target = input.target - input.ee_pos;
            *d = to_target.norm();
            *c = direction_cosine(cfg, &input, &to_target);
        }
    }
}

multiversion! {
    /// Every term of row `k` from its distance, phi and movement, into `cols[..][k]` and
    /// `reached[k]`; whether every checked term is finite.
    #[allow(dead_code)] // called as `finish_at`, at `compute_rows_at`'s level
    fn finish / finish_at(
        cfg: &RewardConfig,
        distance: &[f64],
        phi: &[f64],
        movement: &[f64],
        cols: &mut [&mut [MaybeUninit<f64>]; COLUMNS],
        reached: &mut [bool],
    ) -> bool {
        let n = reached.len();
        let (distance, phi, movement) = (&distance[..n], &phi[..n], &movement[..n]);
        let mut cols = cols.each_mut().map(|c| &mut c[..n]);
        let mut finite = true;
        for k in 0..n {
            let terms = RewardTerms::from_parts(cfg, distance[k], phi[k], movement[k]);
            finite &= terms.checked().iter().fold(true, |all, (_, x)| all & x.is_finite());
            reached[k] = terms.reached;
            let [(_, d), _reached, rest @ ..] = terms.reported();
            cols[0][k].write(d);
            for (col, (_, x)) in cols[1..].iter_mut().zip(rest) {
                col[k].write(x);
            }
        }
        finite
    }
}
/// The first row of `range` that [`RewardTerms::try_compute`] refuses, as an error.
#[cold]
#[inline(never)]
fn first_bad(
    cfg: &RewardConfig,
    dt_s: f64,
    rows: &Rows<'_>,
    range: std::ops::Range<usize>,
) -> std::result::Result<(), BadRow> {
    for row in range {
        if let Err(error) = RewardTerms::try_compute(cfg, dt_s, &rows.input(row)) {
            return Err(BadRow { row, error });
        }
    }
    // The block's passes compute what `try_compute` does, so some row failed it.
    Err(BadRow {
        row: 0,
        error: Error::InvalidInput(
            "a block was refused but none of its rows (a bug in stagerl; please report it)".into(),
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::rng::Rng;
    use crate::reward::{DirectionSource, RewardFunction};

    /// Random rows: positions within 1.5 m, unit quaternions, joint speeds within 3 rad/s; some
    /// rows at the target, with a zero axis, or exactly at the success radius.
    fn random_rows(n: usize, joints: usize, seed: u64) -> [Vec<f64>; 5] {
        let mut rng = Rng::new(seed);
        let mut u =
            |lo: f64, hi: f64, k: usize| (0..k).map(|_| rng.uniform_range(lo, hi)).collect::<Vec<f64>>();
        let (mut p, mut q, mut t, v, prev) = (
            u(-1.5, 1.5, 3 * n),
            u(-1.0, 1.0, 4 * n),
            u(-1.5, 1.5, 3 * n),
            u(-3.0, 3.0, joints * n),
            u(-1.5, 1.5, 3 * n),
        );
        for (i, row) in q.chunks_mut(4).enumerate() {
            match i % 17 {
                3 => row.copy_from_slice(&[0.0, 0.0, 0.0, 1.0]),
                5 => row.copy_from_slice(&[0.0, 0.0, 0.0, -1.0]),
                _ => {
                    let norm = row.iter().map(|x| x * x).sum::<f64>().sqrt();
                    row.iter_mut().for_each(|x| *x /= norm);
                }
            }
        }
        for i in (0..n).step_by(13) {
            t.copy_within(3 * i..3 * i + 3, 0);
            let target = [t[0], t[1], t[2]];
            t[3 * i..3 * i + 3].copy_from_slice(&target);
            p[3 * i..3 * i + 3].copy_from_slice(&target); // at the target: distance 0
        }
        for i in (7..n).step_by(29) {
            p[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]);
            t[3 * i..3 * i + 3].copy_from_slice(&[0.01, 0.0, 0.0]); // exactly beta
        }
        [p, q, t, v, prev]
    }

    /// `compute_rows_at(level)` over all the rows, the columns as `f64`.
    fn batch(
        level: SimdLevel,
        cfg: &RewardConfig,
        rows: &Rows<'_>,
    ) -> std::result::Result<(Vec<Vec<f64>>, Vec<bool>), BadRow> {
        let n = rows.len();
        let mut cols = vec![vec![MaybeUninit::new(f64::NAN); n]; COLUMNS];
        let mut reached = vec![false; n];
        let mut view: [&mut [MaybeUninit<f64>]; COLUMNS] = std::array::from_fn(|_| &mut [][..]);
        for (v, c) in view.iter_mut().zip(cols.iter_mut()) {
            *v = &mut c[..];
        }
        compute_rows_at(level, cfg, 0.05, rows, 0, &mut view, &mut reached)?;
        // SAFETY: compute_rows returned Ok, so every value was written (and each was initialised anyway).
        let cols =
            cols.into_iter().map(|c| c.into_iter().map(|x| unsafe { x.assume_init() }).collect()).collect();
        Ok((cols, reached))
    }

    const LEVELS: [SimdLevel; 3] = [SimdLevel::Avx512, SimdLevel::Avx2, SimdLevel::Baseline];

    #[test]
    fn every_row_is_try_compute_bit_for_bit_at_every_level() {
        let configs = [
            RewardConfig::default(),
            RewardConfig { function: RewardFunction::Har, direction_fold: false, ..RewardConfig::default() },
            RewardConfig {
                function: RewardFunction::Posture,
                sar_sigma1: 2.0,
                sar_sigma2: 1.5,
                sar_scale_m: 0.7,
                ..RewardConfig::default()
            },
            RewardConfig {
                function: RewardFunction::Stride,
                direction: DirectionSource::Displacement,
                ..RewardConfig::default()
            },
            RewardConfig { function: RewardFunction::Basic, beta_m: 0.3, ..RewardConfig::default() },
        ];
        // 6 and 7 joints take the fixed-count loops, 3 the general one; 1000 rows end in a part block.
        for (joints, seed) in [(6, 1), (7, 2), (3, 3)] {
            let [p, q, t, v, prev] = random_rows(1000, joints, seed);
            for cfg in &configs {
                let prev = (cfg.direction == DirectionSource::Displacement).then_some(&prev[..]);
                let rows = Rows::new(&p, &q, &t, &v, joints, prev).unwrap();
                for level in LEVELS {
                    let (cols, reached) = batch(level, cfg, &rows).unwrap();
                    for i in 0..rows.len() {
                        let want = RewardTerms::try_compute(cfg, 0.05, &rows.input(i)).unwrap();
                        assert_eq!(reached[i], want.reached, "row {i}, {level:?}, {cfg:?}");
                        let got = cols.iter().map(|c| c[i].to_bits());
                        let want: Vec<_> = want
                            .reported()
                            .iter()
                            .filter(|(k, _)| *k != "reached")
                            .map(|(_, x)| x.to_bits())
                            .collect();
                        assert!(got.eq(want), "row {i}, {joints} joints, {level:?}, {cfg:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_first_bad_row_is_reported_with_try_computes_error() {
        let [mut p, mut q, t, mut v, _] = random_rows(300, 6, 4);
        let cfg = RewardConfig::default();
        // Row 250 (in the fourth block) overflows, row 140 (the third) has a NaN speed, row 200 a
        // quaternion off unit norm: row 140 comes first.
        p[3 * 250..3 * 250 + 3].copy_from_slice(&[1e200, 0.0, 0.0]);
        v[6 * 140 + 4] = f64::NAN;
        q[4 * 200] *= 1.01;
        for level in LEVELS {
            let rows = Rows::new(&p, &q, &t, &v, 6, None).unwrap();
            let bad = batch(level, &cfg, &rows).unwrap_err();
            assert_eq!(bad.row, 140);
            assert_eq!(bad.to_string(), "row 140: invalid input: joint_vel[4] = NaN is not finite");
        }
        v[6 * 140 + 4] = 0.0;
        let rows = Rows::new(&p, &q, &t, &v, 6, None).unwrap();
        let bad = batch(SimdLevel::Baseline, &cfg, &rows).unwrap_err();
        assert_eq!(bad.row, 200);
        assert!(bad.to_string().starts_with("row 200: invalid input: ee_quat has norm 1.0"), "{bad}");
        q[4 * 200] /= 1.01;
        let rows = Rows::new(&p, &q, &t, &v, 6, None).unwrap();
        let bad = batch(SimdLevel::Avx2, &cfg, &rows).unwrap_err();
        assert_eq!(bad.row, 250);
        assert!(bad.to_string().contains("is not finite: the finite input overflows f64"), "{bad}");
    }

    #[test]
    fn rows_of_the_wrong_length_are_refused_by_name() {
        let (p, q, t, v) = (vec![0.0; 6], vec![0.0; 8], vec![0.0; 6], vec![0.0; 12]);
        assert!(Rows::new(&p, &q, &t, &v, 6, None).is_ok());
        let err = |r: Result<Rows<'_>>| r.unwrap_err().to_string();
        assert!(err(Rows::new(&p, &q[..7], &t, &v, 6, None))
            .contains("ee_quat has 7 values; 2 rows (from ee_pos) need 8"));
        assert!(err(Rows::new(&p, &q, &t, &v, 5, None))
            .contains("joint_vel has 12 values; 2 rows (from ee_pos) need 10 (5 per row)"));
        assert!(err(Rows::new(&p, &q, &t, &v, 6, Some(&t[..3]))).contains("prev_ee_pos has 3 values"));
        assert!(err(Rows::new(&p[..5], &q, &t, &v, 6, None)).contains("ee_pos has 5 values, not 3 per row"));
        assert!(err(Rows::new(&p, &q, &t, &v, 0, None)).contains("joints"));
    }
}
