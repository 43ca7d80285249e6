//! Aggregate scores over seeds as Agarwal et al. (NeurIPS 2021, "Deep Reinforcement Learning at
//! the Edge of the Statistical Precipice") recommend for few-run studies: the interquartile mean
//! (IQM) of each (algorithm, reward function) with a stratified-bootstrap 95 % CI, the
//! probability that SAR improves on each other reward function, and performance profiles. The
//! definitions follow their `rliable` package (`aggregate_iqm`, `StratifiedBootstrap`,
//! `probability_of_improvement`, `create_performance_profile`).

use serde::Serialize;
use std::fmt::Write as _;

use super::claims::Metric;
use super::table::{algo_title, primary, reward_title, GroupSummary, ALGO_ORDER};
use crate::report::method::Method;
use crate::report::stats;
use crate::reward::RewardFunction;

/// Bootstrap resamples of every interval here.
pub const RESAMPLES: usize = 10_000;
/// Seed of the resampling (fixed: the report is reproducible).
const SEED: u64 = 0x0A66_2E6A;

/// The indicators aggregated (one value per seed from the evaluation of each run).
pub const METRICS: [Metric; 2] = [Metric::SuccessRate, Metric::EvalReward];

/// A point estimate with its 95 % CI.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Estimate {
    pub value: f64,
    pub ci95: (f64, f64),
}

/// The IQM of one indicator for one (algorithm, reward function).
#[derive(Clone, Debug, Serialize)]
pub struct GroupIqm {
    pub algo: Method,
    pub reward: RewardFunction,
    pub metric: Metric,
    pub seeds: usize,
    pub iqm: Estimate,
}

/// P(a run with SAR scores above a run with `other`), same algorithm and indicator.
#[derive(Clone, Debug, Serialize)]
pub struct Improvement {
    pub algo: Method,
    pub other: RewardFunction,
    pub metric: Metric,
    pub probability: Estimate,
}

/// The fraction of runs scoring above each threshold (success rate).
#[derive(Clone, Debug, Serialize)]
pub struct Profile {
    pub algo: Method,
    pub reward: RewardFunction,
    /// Runs behind the profile.
    pub runs: usize,
    pub taus: Vec<f64>,
    pub fraction_above: Vec<f64>,
}

/// Every aggregate of a report.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Aggregates {
    pub iqm: Vec<GroupIqm>,
    pub improvement: Vec<Improvement>,
    pub profiles: Vec<Profile>,
}

/// Per-seed values of `metric` for the primary group of `(algo, reward)` (empty if none).
fn values(groups: &[GroupSummary], algo: Method, reward: RewardFunction, metric: Metric) -> Vec<f64> {
    primary(groups, algo, reward).map(|g| metric.per_seed(g).0).unwrap_or_default()
}

/// The IQM and its stratified-bootstrap CI (one task: the seeds of one group).
pub fn iqm_estimate(xs: &[f64], seed: u64) -> Estimate {
    Estimate {
        value: stats::iqm(xs),
        ci95: stats::stratified_bootstrap_ci(&[xs], stats::iqm, 0.95, RESAMPLES, seed),
    }
}

/// The probability of improvement of `x` over `y` with a bootstrap CI (both resampled).
pub fn improvement_estimate(x: &[f64], y: &[f64], seed: u64) -> Estimate {
    let mut rng = crate::base::rng::Rng::new(seed);
    let (mut rx, mut ry) = (vec![0.0; x.len()], vec![0.0; y.len()]);
    let mut draws: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            for v in rx.iter_mut() {
                *v = x[rng.below(x.len() as u64) as usize];
            }
            for v in ry.iter_mut() {
                *v = y[rng.below(y.len() as u64) as usize];
            }
            stats::probability_of_improvement(&rx, &ry)
        })
        .collect();
    Estimate {
        value: stats::probability_of_improvement(x, y),
        ci95: stats::percentile_interval(&mut draws, 0.95),
    }
}

/// Thresholds of the success-rate profiles: 0 to 1 in steps of 0.01.
pub fn profile_taus() -> Vec<f64> {
    (0..=100).map(|i| f64::from(i) / 100.0).collect()
}

/// Compute every aggregate from the groups' per-seed evaluations.
pub fn compute(groups: &[GroupSummary]) -> Aggregates {
    let mut out = Aggregates::default();
    let mut seed = SEED;
    let mut next_seed = || {
        seed += 1;
        seed
    };
    for algo in ALGO_ORDER {
        for reward in RewardFunction::ALL {
            for metric in METRICS {
                let xs = values(groups, algo, reward, metric);
                if !xs.is_empty() {
                    let iqm = iqm_estimate(&xs, next_seed());
                    out.iqm.push(GroupIqm { algo, reward, metric, seeds: xs.len(), iqm });
                }
            }
            let s = values(groups, algo, reward, Metric::SuccessRate);
            if !s.is_empty() {
                let taus = profile_taus();
                out.profiles.push(Profile {
                    algo,
                    reward,
                    runs: s.len(),
                    fraction_above: stats::performance_profile(&s, &taus),
                    taus,
                });
            }
        }
        for other in RewardFunction::ALL.into_iter().filter(|&r| r != RewardFunction::Sar) {
            for metric in METRICS {
                let (x, y) =
                    (values(groups, algo, RewardFunction::Sar, metric), values(groups, algo, other, metric));
                if !x.is_empty() && !y.is_empty() {
                    let probability = improvement_estimate(&x, &y, next_seed());
                    out.improvement.push(Improvement { algo, other, metric, probability });
                }
            }
        }
    }
    out
}

fn fmt(metric: Metric, v: f64) -> String {
    match metric {
        Metric::SuccessRate => format!("{:.1} %", 100.0 * v),
        _ => format!("{v:.3}"),
    }
}

/// The aggregates as Markdown.
pub fn render_markdown(a: &Aggregates) -> String {
    let mut s = String::from("# Aggregates over seeds (IQM, probability of improvement)\n\n");
    s.push_str(
        "As Agarwal et al. (NeurIPS 2021) recommend for few runs: the interquartile mean over seeds (the mean of \
         the middle half, robust to outlier seeds) with a 95 % stratified-bootstrap CI, and the probability that a \
         run with SAR scores above a run with another reward function (ties count half; 0.5 = no difference) with \
         a 95 % bootstrap CI. Each seed contributes its evaluation (success rate over the evaluation trials, mean \
         episode reward of eq. 16). ",
    );
    let _ = writeln!(s, "{RESAMPLES} resamples, seeded. Definitions as in the `rliable` package.\n");
    s.push_str("## Interquartile mean\n\n| Method | Reward | Seeds | Success rate IQM [95 % CI] | Evaluation reward IQM [95 % CI] |\n|---|---|---|---|---|\n");
    let mut rows: Vec<(Method, RewardFunction)> = a.iqm.iter().map(|g| (g.algo, g.reward)).collect();
    rows.dedup();
    for (algo, reward) in rows {
        let cell = |m: Metric| {
            a.iqm.iter().find(|g| g.algo == algo && g.reward == reward && g.metric == m).map_or_else(
                || "—".to_string(),
                |g| format!("{} [{}, {}]", fmt(m, g.iqm.value), fmt(m, g.iqm.ci95.0), fmt(m, g.iqm.ci95.1)),
            )
        };
        let seeds = a.iqm.iter().find(|g| g.algo == algo && g.reward == reward).map_or(0, |g| g.seeds);
        let _ = writeln!(
            s,
            "| {} | {} | {seeds} | {} | {} |",
            algo_title(algo),
            reward_title(reward),
            cell(Metric::SuccessRate),
            cell(Metric::EvalReward)
        );
    }
    s.push_str("\n## Probability of improvement of SAR\n\n| Method | SAR over | P(improvement), success rate [95 % CI] | P(improvement), evaluation reward [95 % CI] |\n|---|---|---|---|\n");
    let mut pairs: Vec<(Method, RewardFunction)> = a.improvement.iter().map(|i| (i.algo, i.other)).collect();
    pairs.dedup();
    for (algo, other) in pairs {
        let cell = |m: Metric| {
            a.improvement.iter().find(|i| i.algo == algo && i.other == other && i.metric == m).map_or_else(
                || "—".to_string(),
                |i| {
                    format!(
                        "{:.2} [{:.2}, {:.2}]",
                        i.probability.value, i.probability.ci95.0, i.probability.ci95.1
                    )
                },
            )
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} |",
            algo_title(algo),
            reward_title(other),
            cell(Metric::SuccessRate),
            cell(Metric::EvalReward)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iqm_ci_contains_the_estimate_and_is_reproducible() {
        let xs: Vec<f64> = (0..20).map(|i| 0.9 + 0.005 * f64::from(i)).collect();
        let e = iqm_estimate(&xs, 1);
        assert!((e.value - stats::mean(&xs[5..15])).abs() < 1e-15);
        assert!(e.ci95.0 <= e.value && e.value <= e.ci95.1 && e.ci95.0 > 0.9 && e.ci95.1 < 1.0);
        assert_eq!(e, iqm_estimate(&xs, 1));
    }

    /// Reference values from `rliable` 1.2.0 (`docs/checks/rliable_iqm.py`: `aggregate_iqm` and
    /// `get_interval_estimates` with 50 000 reps): the IQM agrees exactly; the CI endpoints, both
    /// Monte Carlo estimates, within 5 % of the interval's width.
    #[test]
    fn iqm_matches_rliable() {
        let success = [
            0.962, 0.998, 0.974, 0.990, 0.912, 0.996, 0.984, 0.978, 1.0, 0.956, 0.988, 0.934, 0.994, 0.970,
            0.982, 0.998, 0.946, 0.992, 0.968, 0.986,
        ];
        let reward = [17.91, 18.40, 16.95, 18.77, 18.02, 17.35, 18.93, 18.11, 16.48, 18.56];
        for (xs, iqm, lo, hi) in [
            (&success[..], 0.9812, 0.968_800, 0.989_600),
            (&reward[..], 18.058_333_333_333_334, 17.40, 18.52),
        ] {
            let e = iqm_estimate(xs, 7);
            assert!((e.value - iqm).abs() < 1e-12, "{} vs {iqm}", e.value);
            let tol = 0.05 * (hi - lo);
            assert!(
                (e.ci95.0 - lo).abs() < tol && (e.ci95.1 - hi).abs() < tol,
                "{:?} vs ({lo}, {hi})",
                e.ci95
            );
        }
    }

    #[test]
    fn improvement_of_a_dominating_group_is_one() {
        let e = improvement_estimate(&[0.99, 0.98, 1.0], &[0.5, 0.6, 0.7], 3);
        assert_eq!((e.value, e.ci95), (1.0, (1.0, 1.0)));
        let e = improvement_estimate(&[0.5, 0.6], &[0.5, 0.6], 3);
        assert_eq!(e.value, 0.5);
        assert!(e.ci95.0 < 0.5 && e.ci95.1 > 0.5);
    }
}
