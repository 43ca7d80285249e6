//! Sample efficiency (issue 36): for runs trained on a budget of environment steps
//! (`train.env_steps`) with periodic evaluations (`eval.csv`), how many environment steps each
//! method needs, with 95 % bootstrap CIs over seeds:
//!
//! 1. per run, the steps to the first periodic evaluation at or above a success rate of 95 %
//!    (`None`: not within the budget);
//! 2. per group, the median of those over seeds, a run that never got there counting as
//!    infinitely many steps (so the median is defined while at least half the seeds get there),
//!    with the percentile interval of 10 000 bootstrap medians (an infinite end: "not reached");
//! 3. per group, the IQM of the success rate at 5 000 and 10 000 environment steps and at the end
//!    (each run's first periodic evaluation at or after that many steps, at most one episode
//!    later), with its stratified-bootstrap CI as in [`super::aggregate`].
//!
//! Only the primary groups of runs with a step budget enter; a report without any has no such
//! section (and writes no `sample_efficiency.md`).

use serde::Serialize;
use std::fmt::Write as _;

use super::aggregate::{iqm_estimate, Estimate, RESAMPLES};
use super::method::Method;
use super::table::{reward_title, Group};
use crate::io::csv::EvalPoint;
use crate::reward::RewardFunction;

/// The success rate that counts as reaching the task's standard.
pub const THRESHOLD: f64 = 0.95;
/// The budgets the success rate is read at (the run's end is added).
pub const AT_STEPS: [u64; 2] = [5_000, 10_000];
/// Seed of the resampling (fixed: the report is reproducible).
const SEED: u64 = 0x5A3B_1E00;

/// One group's figures.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub method: Method,
    pub reward: RewardFunction,
    /// The configuration (see [`super::table::variant_label`]).
    pub variant: String,
    pub seeds: usize,
    /// The budget of the runs, environment steps (the largest of the group's).
    pub budget: u64,
    /// Per seed, in seed order: the environment steps of the first evaluation at >= 95 %.
    pub steps_to_threshold: Vec<Option<u64>>,
    /// Median over seeds (`None`: fewer than half got there) and its 95 % CI (`None` ends:
    /// not reached).
    pub median_steps: Option<f64>,
    pub median_ci95: (Option<f64>, Option<f64>),
    /// `(environment steps, seeds with an evaluation there, IQM of their success rate)` for
    /// each of [`AT_STEPS`] below the budget.
    pub success_at: Vec<(u64, usize, Estimate)>,
    /// The same at the last evaluation every run has (the end of the budget).
    pub success_end: Option<(u64, usize, Estimate)>,
}

/// The first evaluation at or above [`THRESHOLD`], its environment steps.
pub fn steps_to_threshold(points: &[EvalPoint]) -> Option<u64> {
    points.iter().find(|p| p.success_rate >= THRESHOLD).map(|p| p.env_steps)
}

/// The success rate of the first evaluation at or after `steps` environment steps.
pub fn success_at(points: &[EvalPoint], steps: u64) -> Option<f64> {
    points.iter().find(|p| p.env_steps >= steps).map(|p| p.success_rate)
}

/// The median with runs that did not get there as infinity; `None` when it is infinite.
fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// The rows of every primary group of step-budget runs, in Table 1's order.
pub fn compute(groups: &[Group]) -> Vec<Row> {
    let mut out = Vec::new();
    let mut seed = SEED;
    for g in groups.iter().filter(|g| g.primary && !g.runs.is_empty()) {
        let Some(budget) = g.runs.iter().filter_map(|r| r.config.train.env_steps).max() else { continue };
        let steps: Vec<Option<u64>> = g.runs.iter().map(|r| steps_to_threshold(&r.eval_points)).collect();
        let xs: Vec<f64> = steps.iter().map(|s| s.map_or(f64::INFINITY, |s| s as f64)).collect();
        seed += 1;
        let (lo, hi) = bootstrap_median_ci(&xs, seed);
        let mut at_steps = |at: u64| {
            let s: Vec<f64> = g.runs.iter().filter_map(|r| success_at(&r.eval_points, at)).collect();
            (!s.is_empty()).then(|| {
                seed += 1;
                (at, s.len(), iqm_estimate(&s, seed))
            })
        };
        let success: Vec<_> =
            AT_STEPS.into_iter().filter(|&a| a < budget).filter_map(&mut at_steps).collect();
        let end = g.runs.iter().filter_map(|r| r.eval_points.last().map(|p| p.env_steps)).min();
        let success_end = end.and_then(&mut at_steps);
        out.push(Row {
            method: g.algo,
            reward: g.reward,
            variant: g.variant.clone(),
            seeds: g.runs.len(),
            budget,
            steps_to_threshold: steps,
            median_steps: finite(median(&xs)),
            median_ci95: (finite(lo), finite(hi)),
            success_at: success,
            success_end,
        });
    }
    out
}

/// The 95 % percentile interval of the median over bootstrap resamples of `xs` (`xs` not empty).
fn bootstrap_median_ci(xs: &[f64], seed: u64) -> (f64, f64) {
    let mut rng = crate::base::rng::Rng::new(seed);
    let mut r = vec![0.0; xs.len()];
    let mut draws: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            for v in r.iter_mut() {
                *v = xs[rng.below(xs.len() as u64) as usize];
            }
            median(&r)
        })
        .collect();
    // Order statistics, not interpolated: the upper end may be infinite.
    draws.sort_by(f64::total_cmp);
    let at = |q: f64| draws[((q * (draws.len() - 1) as f64).round() as usize).min(draws.len() - 1)];
    (at(0.025), at(0.975))
}

/// The section as Markdown (empty without rows).
pub fn render_markdown(rows: &[Row], study: &str) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut s = String::from("# Sample efficiency: environment steps to 95 % success\n\n");
    let _ = writeln!(s, "{study}\n");
    s.push_str(
        "Each run's periodic evaluations (`eval.csv`: the deterministic policy on the same targets every few \
         thousand environment steps). Steps to 95 %: the environment steps of a run's first evaluation at or \
         above 95 % success; the median over seeds counts a run that never got there as infinitely many steps, \
         with the 95 % percentile interval of 10000 bootstrap medians (\"not reached\": that end is infinite). \
         Success at N steps: each run's first evaluation at or after N environment steps (at most one episode \
         later), the IQM over seeds with its 95 % stratified-bootstrap CI.\n\n",
    );
    let ats: Vec<u64> = {
        let mut v: Vec<u64> = AT_STEPS.to_vec();
        v.retain(|a| rows.iter().any(|r| r.success_at.iter().any(|x| x.0 == *a)));
        v
    };
    s.push_str("| Method | Reward | Configuration | Seeds | Budget (env steps) | Reached 95 % | Steps to 95 %, median [95 % CI] |");
    for a in &ats {
        let _ = write!(s, " Success at {a}, IQM [95 % CI] |");
    }
    s.push_str(" Success at the end, IQM [95 % CI] |\n|---|---|---|---|---|---|---|");
    s.push_str(&"---|".repeat(ats.len() + 1));
    s.push('\n');
    let steps = |x: Option<f64>| x.map_or_else(|| "not reached".to_string(), |v| format!("{v:.0}"));
    let pct =
        |e: &Estimate| format!("{:.1} % [{:.1}, {:.1}]", 100.0 * e.value, 100.0 * e.ci95.0, 100.0 * e.ci95.1);
    for r in rows {
        let reached = r.steps_to_threshold.iter().filter(|s| s.is_some()).count();
        let _ = write!(
            s,
            "| {} | {} | {} | {} | {} | {reached}/{} | {} [{}, {}] |",
            r.method.title(),
            reward_title(r.reward),
            r.variant,
            r.seeds,
            r.budget,
            r.seeds,
            steps(r.median_steps),
            steps(r.median_ci95.0),
            steps(r.median_ci95.1),
        );
        for a in &ats {
            let cell = r.success_at.iter().find(|x| x.0 == *a).map_or_else(|| "—".into(), |x| pct(&x.2));
            let _ = write!(s, " {cell} |");
        }
        let end = r.success_end.as_ref();
        let _ =
            writeln!(s, " {} |", end.map_or_else(|| "—".into(), |x| format!("{} (at {})", pct(&x.2), x.0)));
    }
    s.push_str("\nPer seed, the environment steps to 95 % (—: not within the budget):\n\n");
    for r in rows {
        let per: Vec<String> = r
            .steps_to_threshold
            .iter()
            .map(|x| x.map_or_else(|| "—".to_string(), |v| v.to_string()))
            .collect();
        let _ = writeln!(s, "- {} + {}: {}", r.method.title(), reward_title(r.reward), per.join(", "));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(env_steps: u64, success_rate: f64) -> EvalPoint {
        EvalPoint {
            episode: env_steps / 50,
            env_steps,
            success_rate,
            mean_reward: 0.0,
            mean_steps: None,
            median_final_distance_m: 0.0,
        }
    }

    #[test]
    fn steps_and_success_are_read_at_the_first_evaluation_that_qualifies() {
        let p = [point(1010, 0.2), point(2040, 0.96), point(3001, 0.90), point(4020, 0.99)];
        assert_eq!(steps_to_threshold(&p), Some(2040));
        assert_eq!(steps_to_threshold(&p[..1]), None);
        assert_eq!(success_at(&p, 3000), Some(0.90));
        assert_eq!(success_at(&p, 2040), Some(0.96));
        assert_eq!(success_at(&p, 5000), None);
    }

    #[test]
    fn the_median_counts_runs_that_did_not_get_there_as_infinite() {
        let inf = f64::INFINITY;
        assert_eq!(median(&[3.0, 1.0, inf]), 3.0);
        assert_eq!(median(&[3.0, inf, inf]), inf);
        assert_eq!(median(&[1.0, 3.0, 5.0, inf]), 4.0);
        // A bootstrap interval brackets the median and is reproducible.
        let xs = [4000.0, 5000.0, 6000.0, 7000.0, inf];
        let (lo, hi) = bootstrap_median_ci(&xs, 7);
        assert!(lo <= 6000.0 && 6000.0 <= hi && lo >= 4000.0, "{lo} {hi}");
        assert_eq!((lo, hi), bootstrap_median_ci(&xs, 7));
        // Two of five reached: resamples with three infinite values have an infinite median.
        let (_, hi) = bootstrap_median_ci(&[1000.0, 2000.0, inf, inf, inf], 7);
        assert_eq!(hi, inf);
    }
}
