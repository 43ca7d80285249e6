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
mod tests;
