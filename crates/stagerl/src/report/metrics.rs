//! The paper's performance indicators (section VI): the convergence episode `E_start`, the
//! episode reward of eq. 16, the post-convergence mean reward and standard deviation `V_STDEV` of
//! eq. 17, the average steps and the evaluation success rate, and their aggregation over seeds
//! (the paper's "mean ± std").
//!
//! The paper gives no formula for `E_start`; [`ConvergenceCriterion`] documents ours.

use serde::{Deserialize, Serialize};

use crate::base::math::{mean, sample_std};
use crate::io::csv::EpisodeRecord;
use crate::{Error, Result};

/// How `E_start`, the episode at which training "starts to converge", is decided (the paper
/// gives no formula; this is our definition).
///
/// With the `n` episode rewards `R_1 .. R_n` of eq. 16:
/// 1. The *tail* is the last `L = max(W, ceil(tail_fraction * n))` episodes; `mu` is its mean and
///    `s` its sample standard deviation. The *band* is `mu ± h` with
///    `h = max(band_k * s, band_floor)`.
/// 2. `m_e` is the mean of the `W`-episode window `R_e .. R_{e+W-1}` (`W = window`).
/// 3. `E_start` is the smallest episode `e` such that every window starting at `e` or later has
///    its mean inside the band: `|m_j - mu| <= h` for all `e <= j <= n - W + 1`.
///
/// The run did *not* converge (`None`) when
/// - it is too short: `n < W + L`;
/// - the tail itself drifts: its two halves' means differ by more than `h`, or `E_start` falls
///   inside the tail (`E_start > n - L + 1`): some window of the tail leaves the band;
/// - it did not clearly improve: the first window is not at least one half-width below the band
///   (`m_1 >= mu - 2h`), i.e. the reward settled where it started, lower, or so little higher
///   that the rise is within the tail's own spread (a flat sparse-reward curve, a collapse, a
///   policy that succeeds and fails at random).
///
/// `E_start` is the first episode of the first window that stays in the band, so a reward that
/// steps from one level to another at episode `k` has `E_start = k` (up to the band's slack),
/// not `k + W - 1`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConvergenceCriterion {
    /// Moving-average window `W`, episodes (default 100).
    pub window: usize,
    /// Fraction of the run whose mean is the converged level (default 0.1: the last 10 %).
    pub tail_fraction: f64,
    /// Band half-width in tail standard deviations `k` (default 1).
    pub band_k: f64,
    /// Smallest band half-width, reward units (default 0.5), for tails with almost no spread.
    pub band_floor: f64,
}

impl Default for ConvergenceCriterion {
    fn default() -> Self {
        ConvergenceCriterion { window: 100, tail_fraction: 0.1, band_k: 1.0, band_floor: 0.5 }
    }
}

impl ConvergenceCriterion {
    /// Check every field's range.
    pub fn validate(&self) -> Result<()> {
        if self.window == 0 {
            return Err(Error::config("convergence.window", 0, "an integer >= 1"));
        }
        if !(self.tail_fraction > 0.0 && self.tail_fraction < 1.0) {
            return Err(Error::config("convergence.tail_fraction", self.tail_fraction, "a number in (0, 1)"));
        }
        if !(self.band_k.is_finite() && self.band_k >= 0.0) {
            return Err(Error::config("convergence.band_k", self.band_k, "a finite number >= 0"));
        }
        if !(self.band_floor.is_finite() && self.band_floor >= 0.0) {
            return Err(Error::config("convergence.band_floor", self.band_floor, "a finite number >= 0"));
        }
        if self.band_k == 0.0 && self.band_floor == 0.0 {
            return Err(Error::config(
                "convergence.band_floor",
                0,
                "a number > 0 when convergence.band_k is 0 (the band would be empty)",
            ));
        }
        Ok(())
    }

    /// Tail length `L` for a run of `n` episodes.
    pub fn tail_len(&self, n: usize) -> usize {
        ((self.tail_fraction * n as f64).ceil() as usize).max(self.window)
    }
}

/// Why a run has or has no `E_start`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConvergenceOutcome {
    /// Converged: `E_start` is known.
    Converged,
    /// Fewer than `W + L` episodes.
    TooShort,
    /// The last episodes still drift or leave the band.
    NotSettled,
    /// The settled level is not clearly above the first window: nothing was learned.
    NoImprovement,
    /// The rewards could not be analysed (a non-finite value); reports set this, never
    /// [`convergence`], which returns an error instead.
    InvalidData,
}

impl ConvergenceOutcome {
    /// A phrase for reports.
    pub fn describe(self) -> &'static str {
        match self {
            ConvergenceOutcome::Converged => "converged",
            ConvergenceOutcome::TooShort => "did not converge: run too short for the criterion",
            ConvergenceOutcome::NotSettled => "did not converge: the reward still drifts at the end",
            ConvergenceOutcome::NoImprovement => "did not converge: no clear rise above the first episodes",
            ConvergenceOutcome::InvalidData => "not analysed: invalid episode rewards",
        }
    }
}

/// The result of [`convergence`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Convergence {
    pub outcome: ConvergenceOutcome,
    /// `E_start`, 1-based position in the reward sequence; `Some` exactly when converged.
    pub e_start: Option<u64>,
    /// Tail mean `mu` (NaN when too short).
    pub tail_mean: f64,
    /// Tail sample standard deviation `s` (NaN when too short).
    pub tail_std: f64,
    /// Band half-width `h` (NaN when too short).
    pub band: f64,
    /// Mean of the first window `m_1` (NaN when too short).
    pub first_window_mean: f64,
}

fn check_finite(what: &str, xs: &[f64]) -> Result<()> {
    match xs.iter().position(|x| !x.is_finite()) {
        Some(i) => {
            Err(Error::InvalidInput(format!("{what}: value {} at position {} is not finite", xs[i], i + 1)))
        }
        None => Ok(()),
    }
}

/// Means of every window of `w` consecutive values: element `j` is `mean(xs[j .. j + w])`, so
/// the result has `xs.len() - w + 1` elements (none when `w == 0` or `w > xs.len()`).
pub fn window_means(xs: &[f64], w: usize) -> Vec<f64> {
    if w == 0 || w > xs.len() {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(xs.len() - w + 1);
    let mut sum: f64 = xs[..w].iter().sum();
    out.push(sum / w as f64);
    for j in w..xs.len() {
        // Re-sum now and then so rounding does not accumulate over long runs.
        sum = if j % 1024 == 0 { xs[j + 1 - w..=j].iter().sum() } else { sum + xs[j] - xs[j - w] };
        out.push(sum / w as f64);
    }
    out
}

/// Trailing moving average for plots: element `i` is the mean of `xs[max(0, i+1-w) ..= i]`
/// (shorter windows at the start), so the output has the input's length.
pub fn trailing_moving_average(xs: &[f64], w: usize) -> Vec<f64> {
    let w = w.max(1);
    let mut out = Vec::with_capacity(xs.len());
    let mut sum = 0.0;
    for i in 0..xs.len() {
        sum += xs[i];
        if i >= w {
            sum -= xs[i - w];
        }
        out.push(sum / (i + 1).min(w) as f64);
    }
    out
}

/// Decide convergence of the episode-reward curve `rewards` (eq. 16 values, in episode order)
/// under `criterion`; see [`ConvergenceCriterion`] for the definition of `E_start`.
pub fn convergence(rewards: &[f64], criterion: &ConvergenceCriterion) -> Result<Convergence> {
    criterion.validate()?;
    check_finite("episode rewards", rewards)?;
    let n = rewards.len();
    let w = criterion.window;
    let tail_len = criterion.tail_len(n);
    let nan = f64::NAN;
    if n < w + tail_len {
        return Ok(Convergence {
            outcome: ConvergenceOutcome::TooShort,
            e_start: None,
            tail_mean: nan,
            tail_std: nan,
            band: nan,
            first_window_mean: nan,
        });
    }
    let tail = &rewards[n - tail_len..];
    let mu = mean(tail).unwrap_or(nan);
    let s = sample_std(tail).unwrap_or(0.0);
    let h = (criterion.band_k * s).max(criterion.band_floor);
    let means = window_means(rewards, w);
    let first = means[0];
    let mut result = Convergence {
        outcome: ConvergenceOutcome::Converged,
        e_start: None,
        tail_mean: mu,
        tail_std: s,
        band: h,
        first_window_mean: first,
    };
    let (a, b) = tail.split_at(tail_len / 2);
    let drift = (mean(a).unwrap_or(mu) - mean(b).unwrap_or(mu)).abs();
    if drift > h {
        result.outcome = ConvergenceOutcome::NotSettled;
        return Ok(result);
    }
    if first >= mu - 2.0 * h {
        result.outcome = ConvergenceOutcome::NoImprovement;
        return Ok(result);
    }
    // 0-based start of the first window after the last one outside the band.
    let start = means.iter().rposition(|m| (m - mu).abs() > h).map_or(0, |j| j + 1);
    if start > n - tail_len {
        result.outcome = ConvergenceOutcome::NotSettled;
        return Ok(result);
    }
    result.e_start = Some(start as u64 + 1);
    Ok(result)
}

/// `E_start` of the episode-reward curve `rewards` (1-based position in the slice), or `None`
/// when the run did not converge; see [`ConvergenceCriterion`].
pub fn e_start(rewards: &[f64], criterion: &ConvergenceCriterion) -> Result<Option<u64>> {
    Ok(convergence(rewards, criterion)?.e_start)
}

/// Eq. 17 over the episodes from `E_start` (1-based position in `rewards`) to the end:
/// `R_bar = sum_{i=E_start}^{n} R_episode^i / (n - E_start + 1)` and
/// `V_STDEV = sqrt(sum_{i=E_start}^{n} (R_episode^i - R_bar)^2 / (m - 1))`, `m = n - E_start + 1`.
///
/// The paper prints the denominator as `n - 1` with `n = 10000`, the total number of episodes;
/// we take it as the sample standard deviation of the `m` episodes averaged (the literal reading
/// would shrink `V_STDEV` by `sqrt((m - 1) / (n - 1))`). `V_STDEV` is `None` when `m < 2`; the
/// whole result is `None` when `E_start` is 0 or past the end.
pub fn eq17(rewards: &[f64], e_start: u64) -> Option<(f64, Option<f64>)> {
    let from = usize::try_from(e_start).ok()?.checked_sub(1)?;
    let xs = rewards.get(from..).filter(|xs| !xs.is_empty())?;
    Some((mean(xs)?, sample_std(xs)))
}

/// Training indicators of one run, over the episodes from `E_start` on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TrainMetrics {
    /// `E_start`, as an episode number of the CSV.
    pub e_start: u64,
    /// Episodes from `E_start` to the end, `m`.
    pub episodes: u64,
    /// `R_bar` of eq. 17.
    pub mean_reward: f64,
    /// `V_STDEV` of eq. 17 (`None` for a single episode).
    pub v_stdev: Option<f64>,
    /// Mean steps of the successful episodes (the paper's "average number of steps to complete
    /// the task"); `None` when none succeeded.
    pub mean_steps_success: Option<f64>,
    /// Mean steps of all episodes (failures count the step limit).
    pub mean_steps_all: f64,
    /// Fraction of successful episodes.
    pub success_rate: f64,
}

/// [`TrainMetrics`] of `records` from the episode numbered `e_start` on (`None` when no record has
/// that number or a later one).
pub fn train_metrics(records: &[EpisodeRecord], e_start: u64) -> Option<TrainMetrics> {
    let from = records.iter().position(|r| r.episode >= e_start)?;
    let rs = &records[from..];
    let rewards: Vec<f64> = rs.iter().map(|r| r.reward).collect();
    let (mean_reward, v_stdev) = eq17(&rewards, 1)?;
    let steps: Vec<f64> = rs.iter().map(|r| f64::from(r.steps)).collect();
    let ok: Vec<f64> = rs.iter().filter(|r| r.success).map(|r| f64::from(r.steps)).collect();
    Some(TrainMetrics {
        e_start: rs[0].episode,
        episodes: rs.len() as u64,
        mean_reward,
        v_stdev,
        mean_steps_success: mean(&ok),
        mean_steps_all: mean(&steps)?,
        success_rate: ok.len() as f64 / rs.len() as f64,
    })
}

/// A value aggregated over seeds: the paper's "mean ± std".
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MeanStd {
    pub mean: f64,
    /// Sample standard deviation across seeds (n - 1); `None` for a single seed.
    pub std: Option<f64>,
    /// Seeds that contributed.
    pub n: usize,
}

impl MeanStd {
    /// Mean and sample std of the per-seed values; `None` for none.
    pub fn of(values: &[f64]) -> Option<MeanStd> {
        Some(MeanStd { mean: mean(values)?, std: sample_std(values), n: values.len() })
    }

    /// Of the values that are present.
    pub fn of_present(values: impl IntoIterator<Item = Option<f64>>) -> Option<MeanStd> {
        let v: Vec<f64> = values.into_iter().flatten().collect();
        MeanStd::of(&v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::rng::Rng;
    use crate::io::csv::TrialRecord;
    use crate::train::eval::EvalSummary;

    fn crit(floor: f64) -> ConvergenceCriterion {
        ConvergenceCriterion { band_floor: floor, ..ConvergenceCriterion::default() }
    }

    #[test]
    fn step_curve_converges_at_the_step() {
        // Episodes 1..=999 earn -20, episodes 1000..=3000 earn 15.
        let r: Vec<f64> = (1..=3000).map(|e| if e < 1000 { -20.0 } else { 15.0 }).collect();
        let c = convergence(&r, &crit(0.1)).unwrap();
        assert_eq!(c.outcome, ConvergenceOutcome::Converged);
        assert_eq!(c.e_start, Some(1000));
        assert_eq!((c.tail_mean, c.tail_std, c.band), (15.0, 0.0, 0.1));
        // A floor of 0.5 tolerates one low episode in the window: 15 - 35/100 >= 14.5.
        assert_eq!(e_start(&r, &crit(0.5)).unwrap(), Some(999));
    }

    #[test]
    fn noisy_exponential_rise() {
        // R_e = 18 - 40 exp(-e / 300) + 2 z. Tail std ~ 2 so h ~ 2; the window starting at e has the
        // noise-free mean 18 - 40 exp(-e/300) (1 - e^{-1/3}) / (100 (1 - e^{-1/300})), which is
        // 18 - 2 at e = 300 ln(17.0) ~ 850.
        let mut rng = Rng::new(17);
        let r: Vec<f64> =
            (1..=3000).map(|e| 18.0 - 40.0 * (-(e as f64) / 300.0).exp() + 2.0 * rng.normal()).collect();
        let c = convergence(&r, &ConvergenceCriterion::default()).unwrap();
        assert_eq!(c.outcome, ConvergenceOutcome::Converged);
        assert!((c.tail_std - 2.0).abs() < 0.2, "{c:?}");
        let g = 40.0 * (1.0 - (-1.0f64 / 3.0).exp()) / (100.0 * (1.0 - (-1.0f64 / 300.0).exp()));
        let expect = 300.0 * (g / 2.0f64).ln();
        assert!((expect - 850.0).abs() < 5.0, "{expect}");
        let e = c.e_start.unwrap() as f64;
        assert!((e - expect).abs() < 100.0, "E_start {e}, noise-free answer {expect}");
    }

    #[test]
    fn curves_that_never_settle() {
        let mut rng = Rng::new(5);
        // A ramp still rising at the end.
        let ramp: Vec<f64> = (0..3000).map(|e| 0.02 * e as f64 + rng.normal()).collect();
        let c = convergence(&ramp, &ConvergenceCriterion::default()).unwrap();
        assert_eq!((c.outcome, c.e_start), (ConvergenceOutcome::NotSettled, None));
        // A noiseless ramp of any slope.
        let ramp: Vec<f64> = (0..3000).map(|e| 1e-4 * e as f64).collect();
        assert_eq!(e_start(&ramp, &crit(0.0)).unwrap(), None);
        // Flat noise: nothing learned (the sparse reward that never succeeds is all zeros).
        let flat: Vec<f64> = (0..3000).map(|_| rng.normal()).collect();
        assert_eq!(convergence(&flat, &crit(0.5)).unwrap().outcome, ConvergenceOutcome::NoImprovement);
        assert_eq!(e_start(&vec![0.0; 3000], &crit(0.5)).unwrap(), None);
        // A collapse at the end: the tail's halves differ by 24 > h = 19.9.
        let mut late: Vec<f64> = (0..3000).map(|e| if e < 500 { -20.0 } else { 15.0 }).collect();
        late[2920..].iter_mut().for_each(|x| *x = -30.0);
        let c = convergence(&late, &crit(0.5)).unwrap();
        assert_eq!(c.outcome, ConvergenceOutcome::NotSettled, "{c:?}");
        // A late step: the tail holds both levels.
        let step: Vec<f64> = (0..3000).map(|e| if e < 2850 { -20.0 } else { 15.0 }).collect();
        assert_eq!(convergence(&step, &crit(0.5)).unwrap().outcome, ConvergenceOutcome::NotSettled);
        // Too short for W + L.
        assert_eq!(convergence(&[1.0; 150], &crit(0.5)).unwrap().outcome, ConvergenceOutcome::TooShort);
    }

    #[test]
    fn collapse_before_the_tail_moves_e_start_after_it() {
        let mut r: Vec<f64> = (0..3000).map(|e| if e < 500 { -20.0 } else { 15.0 }).collect();
        r[1500..1600].iter_mut().for_each(|x| *x = -20.0);
        // Windows overlapping the collapse by more than 1.43 episodes leave the band (h = 0.5).
        assert_eq!(e_start(&r, &crit(0.5)).unwrap(), Some(1600));
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        assert!(convergence(&[1.0, f64::NAN], &ConvergenceCriterion::default()).is_err());
        for bad in [
            ConvergenceCriterion { window: 0, ..Default::default() },
            ConvergenceCriterion { tail_fraction: 1.0, ..Default::default() },
            ConvergenceCriterion { band_k: -1.0, ..Default::default() },
            ConvergenceCriterion { band_k: 0.0, band_floor: 0.0, ..Default::default() },
        ] {
            assert!(convergence(&[1.0; 10], &bad).is_err(), "{bad:?}");
        }
        assert_eq!(
            convergence(&[], &ConvergenceCriterion::default()).unwrap().outcome,
            ConvergenceOutcome::TooShort
        );
    }

    #[test]
    fn eq17_by_hand() {
        let r = [-5.0, 0.0, 2.0, 4.0, 6.0];
        // From the third episode: mean (2 + 4 + 6) / 3 = 4, std sqrt((4 + 0 + 4) / 2) = 2.
        assert_eq!(eq17(&r, 3), Some((4.0, Some(2.0))));
        assert_eq!(eq17(&r, 5), Some((6.0, None)));
        assert_eq!(eq17(&r, 1).unwrap().0, 1.4);
        assert_eq!(eq17(&r, 0), None);
        assert_eq!(eq17(&r, 6), None);
    }

    #[test]
    fn train_and_eval_metrics_by_hand() {
        let rec = |episode, reward, steps, success| EpisodeRecord {
            collision_steps: None,
            episode,
            reward,
            steps,
            success,
            final_distance_m: 0.0,
            env_steps: 0,
            wall_s: 0.0,
        };
        let rs =
            [rec(1, -30.0, 50, false), rec(2, 10.0, 50, false), rec(3, 19.0, 6, true), rec(4, 19.0, 8, true)];
        let m = train_metrics(&rs, 2).unwrap();
        assert_eq!((m.e_start, m.episodes), (2, 3));
        assert_eq!(m.mean_reward, 16.0);
        assert!((m.v_stdev.unwrap() - 27.0f64.sqrt()).abs() < 1e-12);
        assert_eq!(m.mean_steps_success, Some(7.0));
        assert_eq!(m.mean_steps_all, 64.0 / 3.0);
        assert!((m.success_rate - 2.0 / 3.0).abs() < 1e-15);
        assert!(train_metrics(&rs, 5).is_none());

        let t = |trial, reward, steps, success| TrialRecord {
            collision_steps: None,
            trial,
            reward,
            steps,
            success,
            start_distance_m: 0.4,
            final_distance_m: 0.0,
            target: [0.0; 3],
        };
        let e = EvalSummary::of(&[
            t(1, 18.0, 6, true),
            t(2, -4.0, 50, false),
            t(3, 19.0, 4, true),
            t(4, 19.0, 5, true),
        ])
        .unwrap();
        assert_eq!((e.trials, e.mean_reward, e.mean_steps, e.success_rate), (4, 13.0, Some(5.0), 0.75));
        assert_eq!((e.median_final_distance_m, e.mean_final_distance_m), (0.0, 0.0));
        assert!(EvalSummary::of(&[]).is_none());
    }

    #[test]
    fn mean_std_over_seeds() {
        let a = MeanStd::of(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(a.mean, 2.5);
        assert!((a.std.unwrap() - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(MeanStd::of(&[7.0]).unwrap().std, None);
        assert!(MeanStd::of(&[]).is_none());
        assert_eq!(MeanStd::of_present([Some(1.0), None, Some(3.0)]).unwrap().n, 2);
    }

    #[test]
    fn moving_averages() {
        assert_eq!(window_means(&[1.0, 2.0, 3.0, 4.0], 2), vec![1.5, 2.5, 3.5]);
        assert!(window_means(&[1.0], 2).is_empty());
        assert_eq!(trailing_moving_average(&[1.0, 3.0, 5.0, 7.0], 2), vec![1.0, 2.0, 4.0, 6.0]);
        let long: Vec<f64> = (0..5000).map(|i| (i % 7) as f64 * 0.1).collect();
        let m = window_means(&long, 100);
        for (j, v) in m.iter().enumerate().step_by(333) {
            let direct: f64 = long[j..j + 100].iter().sum::<f64>() / 100.0;
            assert!((v - direct).abs() < 1e-12);
        }
    }
}
