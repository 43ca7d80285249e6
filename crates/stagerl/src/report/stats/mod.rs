//! Statistics for verdicts on the paper's claims and for aggregate scores across seeds.
//!
//! Comparisons ("A is better than B on a metric", one value per seed and group):
//! - the effect: difference of means and relative difference ([`Effect`]);
//! - a 95 % percentile-bootstrap confidence interval of the difference ([`bootstrap_diff_ci`],
//!   10 000 resamples by default, seeded);
//! - a p-value from a two-sided permutation test of the difference of means
//!   ([`permutation_test`]): exact when the group split has at most [`EXACT_PERMUTATIONS`]
//!   arrangements, else 100 000 seeded random permutations. We use it rather than Welch's t-test
//!   because the metrics are far from normal (success rates pile up at 100 %, E_start is skewed)
//!   and it needs no assumption but exchangeability under the null; Welch's test
//!   ([`welch_t_test`]) is kept for reference and for the power estimate;
//! - Holm-Bonferroni correction over the whole family of comparisons ([`holm`]);
//! - a verdict ([`Verdict`]): supported, contradicted or inconclusive; and for an inconclusive
//!   comparison, the seeds per group that would resolve the observed effect at 80 % power
//!   ([`seeds_for_power`]);
//! - for counts (runs that converged or not): Fisher's exact test ([`fisher_exact`]).
//!
//! Aggregates as Agarwal et al. (NeurIPS 2021) recommend: the interquartile mean ([`iqm`]) with a
//! stratified-bootstrap CI ([`stratified_bootstrap_ci`]), the probability of improvement
//! ([`probability_of_improvement`]) and performance profiles ([`performance_profile`]).

pub mod special;

use crate::base::rng::Rng;

/// Significance level of every verdict, after correction.
pub const ALPHA: f64 = 0.05;
/// Power the "seeds needed" estimate aims at.
pub const POWER: f64 = 0.8;
/// Bootstrap resamples by default.
pub const BOOTSTRAP_RESAMPLES: usize = 10_000;
/// Random permutations when the exact test has too many arrangements.
pub const RANDOM_PERMUTATIONS: usize = 100_000;
/// Largest number of arrangements enumerated exactly by [`permutation_test`].
pub const EXACT_PERMUTATIONS: u64 = 200_000;

/// Arithmetic mean; NaN for an empty slice.
pub fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// Sample variance (n - 1); 0 for fewer than two values.
pub fn variance(xs: &[f64]) -> f64 {
    if xs.len() < 2 {
        return 0.0;
    }
    let m = mean(xs);
    xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (xs.len() - 1) as f64
}

/// The difference between two groups' means, `a - b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Effect {
    pub mean_a: f64,
    pub mean_b: f64,
    /// `mean_a - mean_b`.
    pub diff: f64,
    /// `diff / |mean_b|` (`None` when `mean_b` is 0).
    pub relative: Option<f64>,
    /// Cohen's d: `diff` over the pooled standard deviation (`None` when both groups are constant).
    pub cohen_d: Option<f64>,
}

impl Effect {
    pub fn of(a: &[f64], b: &[f64]) -> Effect {
        let (mean_a, mean_b) = (mean(a), mean(b));
        let diff = mean_a - mean_b;
        let (na, nb) = (a.len() as f64, b.len() as f64);
        let pooled = (((na - 1.0) * variance(a) + (nb - 1.0) * variance(b)) / (na + nb - 2.0)).sqrt();
        Effect {
            mean_a,
            mean_b,
            diff,
            relative: (mean_b != 0.0).then(|| diff / mean_b.abs()),
            cohen_d: (pooled > 0.0 && pooled.is_finite()).then(|| diff / pooled),
        }
    }
}

/// Welch's two-sample t-test (unequal variances): the statistic, its Welch-Satterthwaite degrees
/// of freedom and the two-sided p-value. Two constant groups give p = 1 when their means are
/// equal and p = 0 otherwise.
pub fn welch_t_test(a: &[f64], b: &[f64]) -> (f64, f64, f64) {
    let (na, nb) = (a.len() as f64, b.len() as f64);
    let (va, vb) = (variance(a) / na, variance(b) / nb);
    let diff = mean(a) - mean(b);
    let se2 = va + vb;
    if se2 == 0.0 {
        let p = if diff == 0.0 { 1.0 } else { 0.0 };
        return (if diff == 0.0 { 0.0 } else { diff.signum() * f64::INFINITY }, na + nb - 2.0, p);
    }
    let t = diff / se2.sqrt();
    let df = se2 * se2 / (va * va / (na - 1.0) + vb * vb / (nb - 1.0));
    (t, df, special::student_t_two_sided(t, df))
}

/// Two-sided permutation test of the difference of means: the share of arrangements of the
/// pooled values into groups of the same sizes whose |difference| is at least the observed one.
/// Exact when there are at most [`EXACT_PERMUTATIONS`] arrangements; otherwise
/// [`RANDOM_PERMUTATIONS`] random ones from `seed`, with the usual `(hits + 1) / (n + 1)`.
pub fn permutation_test(a: &[f64], b: &[f64], seed: u64) -> f64 {
    let pooled: Vec<f64> = a.iter().chain(b).copied().collect();
    let (na, n) = (a.len(), pooled.len());
    if na == 0 || na == n {
        return 1.0;
    }
    let total: f64 = pooled.iter().sum();
    // |mean_a - mean_b| from the sum of group a alone.
    let stat = |sum_a: f64| (sum_a / na as f64 - (total - sum_a) / (n - na) as f64).abs();
    let observed = stat(a.iter().sum());
    // Ties within rounding count as "at least as extreme".
    let tol = 1e-12 * (1.0 + observed.abs());
    if binomial(n as u64, na as u64) <= EXACT_PERMUTATIONS as f64 {
        let (mut hits, mut count) = (0u64, 0u64);
        for_each_combination(n, na, &mut |idx| {
            let s: f64 = idx.iter().map(|&i| pooled[i]).sum();
            count += 1;
            hits += u64::from(stat(s) >= observed - tol);
        });
        return hits as f64 / count as f64;
    }
    let mut rng = Rng::new(seed);
    let mut work = pooled.clone();
    let mut hits = 0usize;
    for _ in 0..RANDOM_PERMUTATIONS {
        // Partial Fisher-Yates: the first `na` slots become a uniform random group a.
        for i in 0..na {
            let j = i + rng.below((n - i) as u64) as usize;
            work.swap(i, j);
        }
        let s: f64 = work[..na].iter().sum();
        hits += usize::from(stat(s) >= observed - tol);
    }
    (hits + 1) as f64 / (RANDOM_PERMUTATIONS + 1) as f64
}

/// `n choose k` as a float (exact up to 2^53).
pub fn binomial(n: u64, k: u64) -> f64 {
    let k = k.min(n - k);
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64).round()
}

/// Call `f` with every k-subset of 0..n, in lexicographic order.
fn for_each_combination(n: usize, k: usize, f: &mut dyn FnMut(&[usize])) {
    let mut idx: Vec<usize> = (0..k).collect();
    loop {
        f(&idx);
        let Some(i) = (0..k).rev().find(|&i| idx[i] != i + n - k) else { return };
        idx[i] += 1;
        for j in i + 1..k {
            idx[j] = idx[j - 1] + 1;
        }
    }
}

/// A percentile-bootstrap confidence interval of `mean(a) - mean(b)`: each group resampled with
/// replacement `resamples` times (seeded), the `(1 - level) / 2` and `(1 + level) / 2` quantiles.
pub fn bootstrap_diff_ci(a: &[f64], b: &[f64], level: f64, resamples: usize, seed: u64) -> (f64, f64) {
    let mut rng = Rng::new(seed);
    let mut diffs: Vec<f64> =
        (0..resamples).map(|_| resample_mean(a, &mut rng) - resample_mean(b, &mut rng)).collect();
    percentile_interval(&mut diffs, level)
}

/// A percentile-bootstrap confidence interval of one group's mean.
pub fn bootstrap_mean_ci(a: &[f64], level: f64, resamples: usize, seed: u64) -> (f64, f64) {
    let mut rng = Rng::new(seed);
    let mut means: Vec<f64> = (0..resamples).map(|_| resample_mean(a, &mut rng)).collect();
    percentile_interval(&mut means, level)
}

fn resample_mean(xs: &[f64], rng: &mut Rng) -> f64 {
    let n = xs.len() as u64;
    (0..xs.len()).map(|_| xs[rng.below(n) as usize]).sum::<f64>() / xs.len() as f64
}

/// The central `level` interval of `values` (sorted in place), by linear interpolation between
/// order statistics (numpy's default `percentile`).
pub fn percentile_interval(values: &mut [f64], level: f64) -> (f64, f64) {
    values.sort_by(f64::total_cmp);
    (quantile_sorted(values, (1.0 - level) / 2.0), quantile_sorted(values, (1.0 + level) / 2.0))
}

/// The q-quantile of sorted values, linear interpolation (numpy's default).
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// The two-sided t interval of a mean: `mean +- t_{(1+level)/2, n-1} s / sqrt(n)`.
pub fn t_interval(a: &[f64], level: f64) -> (f64, f64) {
    let n = a.len() as f64;
    let half = special::student_t_quantile((1.0 + level) / 2.0, n - 1.0) * (variance(a) / n).sqrt();
    (mean(a) - half, mean(a) + half)
}

/// Holm-Bonferroni adjusted p-values, in the input order: sorted ascending, the i-th smallest
/// (0-based) becomes `max_{j <= i} min(1, (m - j) p_(j))`. Reject where adjusted < alpha.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| p[i].total_cmp(&p[j]));
    let mut out = vec![0.0; m];
    let mut running = 0.0f64;
    for (rank, &i) in order.iter().enumerate() {
        running = running.max(((m - rank) as f64 * p[i]).min(1.0));
        out[i] = running;
    }
    out
}

/// The outcome of one comparison, or of a claim made of several.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The paper's direction, significant after correction.
    Supported,
    /// The opposite direction, significant after correction.
    Contradicted,
    /// Not significant at this number of seeds.
    Inconclusive,
}

impl Verdict {
    /// The verdict of one comparison whose paper-claimed direction is `expected_sign` (+1: a > b).
    pub fn of(diff: f64, adjusted_p: f64, expected_sign: f64) -> Verdict {
        if adjusted_p >= ALPHA || diff == 0.0 {
            Verdict::Inconclusive
        } else if diff.signum() == expected_sign.signum() {
            Verdict::Supported
        } else {
            Verdict::Contradicted
        }
    }

    /// A claim of several comparisons: supported only if all are, contradicted if any is.
    pub fn all(vs: impl IntoIterator<Item = Verdict>) -> Verdict {
        let vs: Vec<Verdict> = vs.into_iter().collect();
        if vs.contains(&Verdict::Contradicted) {
            Verdict::Contradicted
        } else if !vs.is_empty() && vs.iter().all(|v| *v == Verdict::Supported) {
            Verdict::Supported
        } else {
            Verdict::Inconclusive
        }
    }

    pub fn text(self) -> &'static str {
        match self {
            Verdict::Supported => "supported",
            Verdict::Contradicted => "contradicted",
            Verdict::Inconclusive => "inconclusive",
        }
    }
}

/// Seeds per group that a two-sided two-sample t-test at level `alpha` needs to detect a
/// standardised effect `d` (Cohen's d) with probability `power`: the smallest n with
/// `n >= 2 (t_{1-alpha/2, 2n-2} + t_{power, 2n-2})^2 / d^2`. `None` for d = 0 (no effect to
/// resolve) or when more than 100 000 seeds would be needed.
pub fn seeds_for_power(d: f64, alpha: f64, power: f64) -> Option<u64> {
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    let need = |n: u64| {
        let df = (2 * n - 2) as f64;
        let t = special::student_t_quantile(1.0 - alpha / 2.0, df) + special::student_t_quantile(power, df);
        2.0 * t * t / (d * d)
    };
    (2..=100_000u64).find(|&n| n as f64 >= need(n))
}

/// Fisher's exact test (two-sided) on a 2x2 table `[[a, b], [c, d]]` (e.g. converged and not, per
/// group): the total probability of the tables with the same margins that are at most as likely
/// as the observed one.
pub fn fisher_exact(a: u64, b: u64, c: u64, d: u64) -> f64 {
    let (row1, col1, n) = (a + b, a + c, a + b + c + d);
    let ln_c = |n: u64, k: u64| {
        special::ln_gamma(n as f64 + 1.0)
            - special::ln_gamma(k as f64 + 1.0)
            - special::ln_gamma((n - k) as f64 + 1.0)
    };
    // P(top-left = x) under the hypergeometric law with these margins.
    let ln_p = |x: u64| ln_c(col1, x) + ln_c(n - col1, row1 - x) - ln_c(n, row1);
    let observed = ln_p(a);
    let lo = row1.saturating_sub(n - col1);
    let hi = row1.min(col1);
    let p: f64 = (lo..=hi).map(ln_p).filter(|&l| l <= observed + 1e-9).map(f64::exp).sum();
    p.min(1.0)
}

/// The interquartile mean: the mean of the values left after a quarter is cut from each end
/// (`floor(n / 4)` values each side, as scipy's `trim_mean(x, 0.25)` and rliable do).
pub fn iqm(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let cut = v.len() / 4;
    mean(&v[cut..v.len() - cut])
}

/// A stratified-bootstrap CI of an aggregate over runs grouped by task: every resample draws,
/// within each task, as many runs as it has, with replacement (rliable's `StratifiedBootstrap`),
/// then applies `aggregate` to the pooled resample. Percentile interval at `level`.
pub fn stratified_bootstrap_ci(
    tasks: &[&[f64]],
    aggregate: impl Fn(&[f64]) -> f64,
    level: f64,
    resamples: usize,
    seed: u64,
) -> (f64, f64) {
    let mut rng = Rng::new(seed);
    let total: usize = tasks.iter().map(|t| t.len()).sum();
    let mut pool = Vec::with_capacity(total);
    let mut stats: Vec<f64> = (0..resamples)
        .map(|_| {
            pool.clear();
            for t in tasks {
                pool.extend((0..t.len()).map(|_| t[rng.below(t.len() as u64) as usize]));
            }
            aggregate(&pool)
        })
        .collect();
    percentile_interval(&mut stats, level)
}

/// The probability of improvement P(X > Y) (ties count half): how likely a run of `x` scores
/// above a run of `y` (Agarwal et al.'s definition for one task, the Mann-Whitney U over n m).
pub fn probability_of_improvement(x: &[f64], y: &[f64]) -> f64 {
    let mut s = 0.0;
    for &a in x {
        for &b in y {
            s += if a > b {
                1.0
            } else if a == b {
                0.5
            } else {
                0.0
            };
        }
    }
    s / (x.len() * y.len()) as f64
}

/// A performance profile: for each threshold tau, the fraction of runs scoring above it.
pub fn performance_profile(scores: &[f64], taus: &[f64]) -> Vec<f64> {
    taus.iter().map(|&tau| scores.iter().filter(|&&s| s > tau).count() as f64 / scores.len() as f64).collect()
}

#[cfg(test)]
mod tests;
