//! The paper's claims from section VI, checked against our runs with statistics (and against the
//! paper's own Table 1, which does not always support the text).
//!
//! Every comparison "A is better than B on an indicator" takes one value per seed from each
//! group and gets (see [`crate::report::stats`]):
//! - the effect: difference and relative difference of the means;
//! - a 95 % percentile-bootstrap CI of the difference ([`BOOTSTRAP_RESAMPLES`] resamples, seeded);
//! - a two-sided permutation test of the difference of means (exact for small groups, else
//!   100 000 seeded permutations): the indicators are far from normal (success rates pile up near
//!   100 %, E_start is skewed), and the permutation test needs no normality;
//! - Holm-Bonferroni over the whole family of comparisons of the report;
//! - a verdict: **supported** (the paper's direction, significant at 5 % after correction),
//!   **contradicted** (the opposite direction, significant) or **inconclusive**; for an
//!   inconclusive comparison, the seeds per group that would resolve the observed effect at 80 %
//!   power (two-sample t-test at the Bonferroni level 0.05 / m, a conservative bound).
//!
//! E_start of a seed that did not converge is censored at its episode count + 1 (it converged
//! no earlier than the end), so convergence itself counts; the other training indicators exist
//! only for converged seeds. Convergence counts (the basic reward's claim) use Fisher's exact
//! test. A claim of several comparisons is supported only if all are, contradicted if any is,
//! else inconclusive (or not measurable when a group it needs is missing).

use serde::Serialize;
use std::fmt::Write as _;

use super::paper::{self, PaperRow};
use super::table::{algo_title, primary, reward_title, GroupSummary};
use crate::report::method::Method;
use crate::report::metrics::MeanStd;
use crate::report::stats::{self, BOOTSTRAP_RESAMPLES};
use crate::reward::RewardFunction::{self, Basic, Har, Posture, Sar, Stride};

/// Our verdict on a comparison or a claim.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The paper's direction, significant after correction.
    Supported,
    /// The opposite direction, significant after correction.
    Contradicted,
    /// Not significant at this number of seeds.
    Inconclusive,
    /// A group it needs was not run, or did not produce the indicator.
    NotMeasurable,
}

impl Verdict {
    pub const ALL: [Verdict; 4] =
        [Verdict::Supported, Verdict::Contradicted, Verdict::Inconclusive, Verdict::NotMeasurable];

    pub fn text(self) -> &'static str {
        match self {
            Verdict::Supported => "supported",
            Verdict::Contradicted => "contradicted",
            Verdict::Inconclusive => "inconclusive",
            Verdict::NotMeasurable => "not measurable",
        }
    }

    /// A claim of several comparisons: contradicted if any is; else not measurable if any is;
    /// else supported if all are; else inconclusive.
    fn all(vs: impl IntoIterator<Item = Verdict>) -> Verdict {
        let vs: Vec<Verdict> = vs.into_iter().collect();
        if vs.contains(&Verdict::Contradicted) {
            Verdict::Contradicted
        } else if vs.is_empty() || vs.contains(&Verdict::NotMeasurable) {
            Verdict::NotMeasurable
        } else if vs.iter().all(|v| *v == Verdict::Supported) {
            Verdict::Supported
        } else {
            Verdict::Inconclusive
        }
    }

    fn from_stats(v: stats::Verdict) -> Verdict {
        match v {
            stats::Verdict::Supported => Verdict::Supported,
            stats::Verdict::Contradicted => Verdict::Contradicted,
            stats::Verdict::Inconclusive => Verdict::Inconclusive,
        }
    }
}

/// What the paper's own Table 1 says of a claim: its means only (it gives no per-seed values),
/// so a direction, not a test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TableVerdict {
    Holds,
    DoesNotHold,
    /// Not in the paper's table.
    NotMeasurable,
}

impl TableVerdict {
    pub fn text(self) -> &'static str {
        match self {
            TableVerdict::Holds => "holds",
            TableVerdict::DoesNotHold => "does not hold",
            TableVerdict::NotMeasurable => "not measurable",
        }
    }

    /// Any failure decides; then anything unmeasurable; else it holds.
    fn all(vs: impl IntoIterator<Item = TableVerdict>) -> TableVerdict {
        let vs: Vec<TableVerdict> = vs.into_iter().collect();
        if vs.contains(&TableVerdict::DoesNotHold) {
            TableVerdict::DoesNotHold
        } else if vs.is_empty() || vs.contains(&TableVerdict::NotMeasurable) {
            TableVerdict::NotMeasurable
        } else {
            TableVerdict::Holds
        }
    }
}

/// A Table 1 column.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    EStart,
    TrainReward,
    TrainSteps,
    VStdev,
    EvalReward,
    EvalSteps,
    SuccessRate,
    /// Share of seeds whose training reward converged (E_start exists).
    Converged,
}

impl Metric {
    pub fn name(self) -> &'static str {
        match self {
            Metric::EStart => "E_start",
            Metric::TrainReward => "training reward R̄",
            Metric::TrainSteps => "training steps",
            Metric::VStdev => "V_STDEV",
            Metric::EvalReward => "evaluation reward",
            Metric::EvalSteps => "evaluation steps",
            Metric::SuccessRate => "success rate",
            Metric::Converged => "seeds converged",
        }
    }

    pub fn lower_is_better(self) -> bool {
        matches!(self, Metric::EStart | Metric::TrainSteps | Metric::VStdev | Metric::EvalSteps)
    }

    pub fn ours(self, g: &GroupSummary) -> Option<MeanStd> {
        match self {
            Metric::EStart => g.e_start,
            Metric::TrainReward => g.train_reward,
            Metric::TrainSteps => g.train_steps,
            Metric::VStdev => g.v_stdev,
            Metric::EvalReward => g.eval_reward,
            Metric::EvalSteps => g.eval_steps,
            Metric::SuccessRate => g.success_rate,
            Metric::Converged => (g.seeds > 0).then(|| MeanStd {
                mean: g.converged as f64 / g.seeds as f64,
                std: None,
                n: g.seeds,
            }),
        }
    }

    pub fn paper(self, p: &PaperRow) -> Option<f64> {
        match self {
            Metric::EStart => p.e_start,
            Metric::TrainReward => p.train_reward.map(|x| x.0),
            Metric::TrainSteps => p.train_steps,
            Metric::VStdev => p.v_stdev.map(|x| x.0),
            Metric::EvalReward => p.eval_reward,
            Metric::EvalSteps => p.eval_steps,
            Metric::SuccessRate => p.success_rate,
            Metric::Converged => Some(if p.converged() { 1.0 } else { 0.0 }),
        }
    }

    /// One value per seed of a group: the training indicators of its converged seeds (E_start of
    /// the others censored at their episode count + 1), the evaluation indicators of its
    /// evaluated seeds. The second value counts the censored seeds.
    pub fn per_seed(self, g: &GroupSummary) -> (Vec<f64>, usize) {
        let mut censored = 0;
        let values = g
            .runs
            .iter()
            .filter_map(|r| {
                let t = r.train.as_ref();
                let e = r.eval.as_ref();
                match self {
                    Metric::EStart => Some(t.map_or_else(
                        || {
                            censored += 1;
                            (r.episodes + 1) as f64
                        },
                        |t| t.e_start as f64,
                    )),
                    Metric::TrainReward => t.map(|t| t.mean_reward),
                    Metric::TrainSteps => t.and_then(|t| t.mean_steps_success),
                    Metric::VStdev => t.and_then(|t| t.v_stdev),
                    Metric::EvalReward => e.map(|e| e.mean_reward),
                    Metric::EvalSteps => e.and_then(|e| e.mean_steps),
                    Metric::SuccessRate => e.map(|e| e.success_rate),
                    Metric::Converged => Some(if t.is_some() { 1.0 } else { 0.0 }),
                }
            })
            .collect();
        (values, censored)
    }

    fn fmt(self, v: f64) -> String {
        match self {
            Metric::EStart => format!("{v:.0}"),
            Metric::SuccessRate | Metric::Converged => format!("{:.1} %", 100.0 * v),
            Metric::TrainSteps | Metric::EvalSteps => format!("{v:.1}"),
            _ => format!("{v:.3}"),
        }
    }

    fn fmt_ms(self, m: &MeanStd) -> String {
        match m.std {
            Some(s) if matches!(self, Metric::SuccessRate | Metric::Converged) => {
                format!("{:.1} ± {:.1} %", 100.0 * m.mean, 100.0 * s)
            }
            Some(s) => format!("{} ± {}", self.fmt(m.mean), self.fmt(s).trim_end_matches(" %")),
            None => self.fmt(m.mean),
        }
    }
}

/// The test behind a comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Test {
    /// Two-sided permutation test of the difference of the per-seed means.
    Permutation,
    /// Fisher's exact test on counts (converged or not).
    FisherExact,
}

/// The statistics of one comparison, `better - worse` in the indicator's own units (for a
/// lower-is-better indicator the paper's direction is a negative difference).
#[derive(Clone, Debug, Serialize)]
pub struct Stats {
    pub test: Test,
    /// Seeds (values) in each group.
    pub n: (usize, usize),
    pub diff: f64,
    /// `diff / |worse|`.
    pub relative: Option<f64>,
    /// 95 % percentile-bootstrap CI of `diff`.
    pub ci95: (f64, f64),
    /// Uncorrected two-sided p-value.
    pub p: f64,
    /// Holm-Bonferroni adjusted over the report's family of comparisons.
    pub p_holm: f64,
    /// Cohen's d (or h for counts) of the observed effect.
    pub effect_size: Option<f64>,
    /// For an inconclusive comparison: seeds per group that would resolve the observed effect at
    /// 80 % power (`None`: no effect observed, or more than 100 000).
    pub seeds_needed: Option<u64>,
}

/// One "a is better than b on metric" check.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    pub metric: Metric,
    pub better: (Method, RewardFunction),
    pub worse: (Method, RewardFunction),
    pub verdict: Verdict,
    /// Our numbers, e.g. `SAC+SAR 812 ± 95 vs SAC+HAR 1032 ± 40: 21.3 % lower`.
    pub ours: String,
    /// `None` when not measurable.
    pub stats: Option<Stats>,
    pub paper_verdict: TableVerdict,
    pub paper: String,
}

/// A claim of section VI with our verdict.
#[derive(Clone, Debug, Serialize)]
pub struct Claim {
    pub id: String,
    /// Where the paper says it.
    pub section: &'static str,
    /// The claim, as we test it.
    pub statement: String,
    /// What the paper's text says (its numbers).
    pub paper_text: &'static str,
    pub verdict: Verdict,
    /// The verdict the paper's own Table 1 gives.
    pub paper_verdict: TableVerdict,
    pub comparisons: Vec<Comparison>,
    /// Our numbers for claims that are not comparisons.
    pub detail: String,
}

fn label((a, r): (Method, RewardFunction)) -> String {
    format!("{}+{}", algo_title(a), reward_title(r))
}

fn relative(metric: Metric, a: f64, b: f64) -> String {
    if b == 0.0 {
        return String::new();
    }
    let (rel, word) = if metric.lower_is_better() {
        ((b - a) / b.abs(), if metric == Metric::EStart { "earlier" } else { "lower" })
    } else {
        ((a - b) / b.abs(), "higher")
    };
    let word = if rel < 0.0 {
        match word {
            "earlier" => "later",
            "lower" => "higher",
            _ => "lower",
        }
    } else {
        word
    };
    format!(": {:.1} % {word}", 100.0 * rel.abs())
}

/// The paper's expected sign of `better - worse`.
fn expected_sign(metric: Metric) -> f64 {
    if metric.lower_is_better() {
        -1.0
    } else {
        1.0
    }
}

/// Effect, bootstrap CI and permutation p-value of `a - b` (Holm and the verdict come later,
/// once the whole family is known). `seed` makes the resampling reproducible.
fn permutation_stats(a: &[f64], b: &[f64], seed: u64) -> Stats {
    let e = stats::Effect::of(a, b);
    Stats {
        test: Test::Permutation,
        n: (a.len(), b.len()),
        diff: e.diff,
        relative: e.relative,
        ci95: stats::bootstrap_diff_ci(a, b, 0.95, BOOTSTRAP_RESAMPLES, seed),
        p: stats::permutation_test(a, b, seed),
        p_holm: f64::NAN,
        effect_size: e.cohen_d,
        seeds_needed: None,
    }
}

/// [`permutation_stats`] for 0/1 values (converged or not): Fisher's exact test on the counts,
/// Cohen's h as the effect size.
fn fisher_stats(a: &[f64], b: &[f64], seed: u64) -> Stats {
    let count = |xs: &[f64]| xs.iter().filter(|&&x| x > 0.5).count() as u64;
    let (ka, kb) = (count(a), count(b));
    let (na, nb) = (a.len() as u64, b.len() as u64);
    let e = stats::Effect::of(a, b);
    let h = 2.0 * e.mean_a.sqrt().asin() - 2.0 * e.mean_b.sqrt().asin();
    Stats {
        test: Test::FisherExact,
        n: (a.len(), b.len()),
        diff: e.diff,
        relative: e.relative,
        ci95: stats::bootstrap_diff_ci(a, b, 0.95, BOOTSTRAP_RESAMPLES, seed),
        p: stats::fisher_exact(ka, na - ka, kb, nb - kb),
        p_holm: f64::NAN,
        effect_size: Some(h),
        seeds_needed: None,
    }
}

/// Our side of a comparison: the statistics, or why it cannot be measured; and the text.
fn ours(
    groups: &[GroupSummary],
    metric: Metric,
    better: Cell,
    worse: Cell,
    seed: u64,
) -> (Option<Stats>, String) {
    let (la, lb) = (label(better), label(worse));
    let ga = primary(groups, better.0, better.1).filter(|g| g.seeds > 0);
    let gb = primary(groups, worse.0, worse.1).filter(|g| g.seeds > 0);
    let (Some(ga), Some(gb)) = (ga, gb) else {
        let missing: Vec<String> = [(ga, &la), (gb, &lb)]
            .iter()
            .filter(|(g, _)| g.is_none())
            .map(|(_, l)| format!("{l} not run"))
            .collect();
        return (None, missing.join(", "));
    };
    let ((xa, ca), (xb, cb)) = (metric.per_seed(ga), metric.per_seed(gb));
    let shown = |g: &GroupSummary, xs: &[f64], censored: usize, l: &str| {
        let m = if metric == Metric::EStart { metric.ours(g) } else { MeanStd::of(xs) };
        let value = m.map_or_else(|| "—".to_string(), |m| metric.fmt_ms(&m));
        match censored {
            0 => format!("{l} {value}"),
            c if c == g.seeds => format!("{l} did not converge ({c} seeds)"),
            c => format!("{l} {value} ({c} of {} seeds did not converge)", g.seeds),
        }
    };
    let text = format!("{} vs {}", shown(ga, &xa, ca, &la), shown(gb, &xb, cb, &lb));
    if xa.is_empty() || xb.is_empty() {
        let why = |g: &GroupSummary, xs: &[f64], l: &str| {
            (xs.is_empty()).then(|| {
                if g.converged == 0 && metric != Metric::EvalReward {
                    format!("{l} did not converge")
                } else {
                    format!("{l} has no {}", metric.name())
                }
            })
        };
        let parts: Vec<String> = [why(ga, &xa, &la), why(gb, &xb, &lb)].into_iter().flatten().collect();
        return (None, parts.join(", "));
    }
    let (ma, mb) = (stats::mean(&xa), stats::mean(&xb));
    let st = if metric == Metric::Converged {
        fisher_stats(&xa, &xb, seed)
    } else {
        permutation_stats(&xa, &xb, seed)
    };
    (Some(st), format!("{text}{}", relative(metric, ma, mb)))
}

fn compare(
    groups: &[GroupSummary],
    paper_rows: &[PaperRow],
    (metric, better, worse): Check,
    seed: u64,
) -> Comparison {
    let beats = |a: f64, b: f64| if metric.lower_is_better() { a < b } else { a > b };
    let (stats, ours) = ours(groups, metric, better, worse, seed);
    let pa = paper::row(paper_rows, better.0, better.1);
    let pb = paper::row(paper_rows, worse.0, worse.1);
    let (paper_verdict, paper) = match (pa.map(|p| metric.paper(p)), pb.map(|p| metric.paper(p))) {
        (Some(Some(a)), Some(Some(b))) => (
            if beats(a, b) { TableVerdict::Holds } else { TableVerdict::DoesNotHold },
            format!("{} vs {}{}", metric.fmt(a), metric.fmt(b), relative(metric, a, b)),
        ),
        _ => (TableVerdict::NotMeasurable, "not in the paper's table".into()),
    };
    let verdict = if stats.is_some() { Verdict::Inconclusive } else { Verdict::NotMeasurable };
    Comparison { metric, better, worse, verdict, ours, stats, paper_verdict, paper }
}

/// An (algorithm, reward function) pair: one row of Table 1.
type Cell = (Method, RewardFunction);
/// `(metric, better, worse)`.
type Check = (Metric, Cell, Cell);

struct Spec {
    id: &'static str,
    section: &'static str,
    statement: String,
    paper_text: &'static str,
    checks: Vec<Check>,
}

/// The id of the basic reward's claim.
const BASIC_CLAIM: &str = "basic-does-not-converge";

/// The paper's learners.
const PAPER_ALGOS: [Method; 2] = [Method::Sac, Method::Ddpg];

/// The learners the claims about rewards ("with each algorithm") are checked with: the paper's
/// SAC and DDPG when the report holds either; otherwise every learner it holds (in Table 1's
/// order), so that a study of other learners (CrossQ's rewards, say) gets the reward claims
/// checked with them. The claims that compare SAC with DDPG stay theirs.
pub fn claim_learners(groups: &[GroupSummary]) -> Vec<Method> {
    let held = |a: Method| groups.iter().any(|g| g.primary && g.algo == a && g.seeds > 0);
    if PAPER_ALGOS.iter().any(|&a| held(a)) {
        return PAPER_ALGOS.to_vec();
    }
    let others: Vec<Method> = Method::ORDER.into_iter().filter(|&a| held(a)).collect();
    if others.is_empty() {
        PAPER_ALGOS.to_vec()
    } else {
        others
    }
}

fn per_algo(
    algos: &[Method],
    metric: Metric,
    better: RewardFunction,
    worse: &[RewardFunction],
) -> Vec<Check> {
    algos.iter().flat_map(|&a| worse.iter().map(move |&w| (metric, (a, better), (a, w)))).collect()
}

/// The paper's claims, section by section, the reward claims checked with `algos`.
fn specs(algos: &[Method]) -> Vec<Spec> {
    [specs_vi_a(algos), specs_vi_b(algos), specs_vi_c(algos)].into_iter().flatten().collect()
}

/// Section VI.A: posture against stride, SAC against DDPG.
fn specs_vi_a(algos: &[Method]) -> Vec<Spec> {
    use Metric::*;
    let dense = [Posture, Stride, Har, Sar];
    let with = if algos == PAPER_ALGOS {
        "with SAC and DDPG".to_string()
    } else {
        let names: Vec<&str> = algos.iter().map(|&a| algo_title(a)).collect();
        format!("with {}", names.join(" and "))
    };
    vec![
        Spec {
            id: BASIC_CLAIM,
            section: "VI.A",
            statement: format!("The sparse basic reward (eq. 18) converges in fewer seeds than every dense reward, {with} (the paper: it does not converge at all)"),
            paper_text: "\"DDPG and SAC could not converge even after a long training period based on a sparse reward function\"",
            checks: algos
                .iter()
                .flat_map(|&a| dense.iter().map(move |&r| (Converged, (a, r), (a, Basic))))
                .collect(),
        },
        Spec {
            id: "sac-converges-faster",
            section: "VI.A",
            statement: "SAC converges faster than DDPG (smaller E_start) with every dense reward".into(),
            paper_text: "\"SAC converged faster in general\"; 10.8 % faster with posture, 17.9 % with stride",
            checks: dense.iter().map(|&r| (EStart, (Method::Sac, r), (Method::Ddpg, r))).collect(),
        },
        Spec {
            id: "posture-faster-than-stride",
            section: "VI.A",
            statement: "Posture converges faster than stride (smaller E_start), with each algorithm".into(),
            paper_text: "\"the convergence rate of the posture reward function increased by 22.6-26.4 %\"",
            checks: per_algo(algos, EStart, Posture, &[Stride]),
        },
        Spec {
            id: "stride-lower-std-than-posture",
            section: "VI.A",
            statement: "Stride has a lower V_STDEV than posture, with each algorithm".into(),
            paper_text: "\"the standard deviation of the stride reward function was 23.7-46.4 % lower\"",
            checks: per_algo(algos, VStdev, Stride, &[Posture]),
        },
        Spec {
            id: "stride-higher-reward-ddpg",
            section: "VI.A",
            statement: "With DDPG, stride has a higher mean training reward than posture".into(),
            paper_text: "\"the mean reward of the stride reward function was 3.2 % higher than that of the posture reward function in DDPG\"",
            checks: vec![(TrainReward, (Method::Ddpg, Stride), (Method::Ddpg, Posture))],
        },
        Spec {
            id: "posture-fewer-steps",
            section: "VI.A",
            statement: "Posture completes the task in fewer evaluation steps than stride, with each algorithm".into(),
            paper_text: "\"the posture reward function completes trajectory planning with fewer average steps\"",
            checks: per_algo(algos, EvalSteps, Posture, &[Stride]),
        },
        Spec {
            id: "stride-more-reward",
            section: "VI.A",
            statement: "Stride obtains a higher evaluation reward than posture, with each algorithm".into(),
            paper_text: "\"the stride reward function obtains more rewards\"",
            checks: per_algo(algos, EvalReward, Stride, &[Posture]),
        },
    ]
}

/// Section VI.B: HAR.
fn specs_vi_b(algos: &[Method]) -> Vec<Spec> {
    use Metric::*;
    vec![
        Spec {
            id: "har-lower-std-than-posture",
            section: "VI.B",
            statement: "HAR has a lower V_STDEV than posture, with each algorithm".into(),
            paper_text: "\"the standard deviation decreased by about 42.6 % with HAR compared to the posture reward function\"",
            checks: per_algo(algos, VStdev, Har, &[Posture]),
        },
        Spec {
            id: "har-faster-than-stride",
            section: "VI.B",
            statement: "HAR converges faster than stride, with each algorithm".into(),
            paper_text: "\"The convergence rate of the HAR reward function was about 20.4 % faster than that of the stride reward function\"",
            checks: per_algo(algos, EStart, Har, &[Stride]),
        },
        Spec {
            id: "har-slower-than-posture",
            section: "VI.B",
            statement: "HAR converges more slowly than posture, with each algorithm".into(),
            paper_text: "\"but it was slower than the posture reward function\"",
            checks: algos.iter().map(|&a| (EStart, (a, Posture), (a, Har))).collect(),
        },
        Spec {
            id: "har-better-evaluation",
            section: "VI.B",
            statement: "In evaluation HAR beats posture and stride on reward, steps and success rate, with each algorithm".into(),
            paper_text: "\"The reward increased to 24.7 %, the average steps decreased by 16.7-27.2 %, and the success rate for trajectory planning increased by 2.4-5.2 %\"",
            checks: [EvalReward, EvalSteps, SuccessRate]
                .iter()
                .flat_map(|&m| per_algo(algos, m, Har, &[Posture, Stride]))
                .collect(),
        },
    ]
}

/// Section VI.C: SAR.
fn specs_vi_c(algos: &[Method]) -> Vec<Spec> {
    use Metric::*;
    let mut v = Vec::new();
    for (id, metric, what, text) in [
        ("sar-fastest", EStart, "converges fastest (smallest E_start)", "\"the convergence rate was accelerated by 18.7-40.1 % in DDPG and by 31.4-46.9 % in SAC\""),
        ("sar-highest-train-reward", TrainReward, "has the highest mean training reward R̄", "\"For the convergent mean reward, the promotion was between 4.6-15.5 % in DDPG and 4.4-9.5 % in SAC\""),
        ("sar-lowest-std", VStdev, "has the lowest V_STDEV", "\"the standard deviation decreased by 35.9-63.2 % in DDPG and by 21.9-26.7 % in SAC\""),
        ("sar-fewest-train-steps", TrainSteps, "needs the fewest training steps", "\"the results of SAR were superior in all cases\""),
        ("sar-highest-eval-reward", EvalReward, "has the highest evaluation reward", "\"SAR ... obtains more rewards, and is more stable\" (Fig. 8)"),
        ("sar-fewest-eval-steps", EvalSteps, "needs the fewest evaluation steps", "\"SAR needs fewer steps to realize trajectory planning\" (Fig. 8)"),
        ("sar-highest-success", SuccessRate, "has the highest evaluation success rate", "\"the results of SAR were superior in all cases\""),
    ] {
        v.push(Spec {
            id,
            section: "VI.C",
            statement: format!("SAR {what} among posture, stride, HAR and SAR, with each algorithm"),
            paper_text: text,
            checks: per_algo(algos, metric, Sar, &[Posture, Stride, Har]),
        });
    }
    v.push(Spec {
        id: "sar-sac-faster-than-ddpg",
        section: "VI.C",
        statement: "With SAR, SAC converges faster than DDPG".into(),
        paper_text: "\"The convergence rate of SAR in DDPG was slower than that of SAR in SAC\"",
        checks: vec![(EStart, (Method::Sac, Sar), (Method::Ddpg, Sar))],
    });
    v.push(Spec {
        id: "sar-ddpg-better-otherwise",
        section: "VI.C",
        statement: "With SAR, DDPG beats SAC on every indicator but E_start".into(),
        paper_text: "\"but other indicators were better in DDPG than in SAC\"",
        checks: [TrainReward, TrainSteps, VStdev, EvalReward, EvalSteps, SuccessRate]
            .iter()
            .map(|&m| (m, (Method::Ddpg, Sar), (Method::Sac, Sar)))
            .collect(),
    });
    v
}

/// Success-rate tolerance of the headline claim, in absolute terms (one percentage point).
const HEADLINE_TOLERANCE: f64 = 0.01;

/// Seed of the resampling of comparison `i` of the report (and of the headline claim).
fn comparison_seed(i: usize) -> u64 {
    0x5EED_C1A1_0000 + i as u64
}

/// The headline (DDPG+SAR at the paper's success rate and steps): supported when the 95 %
/// bootstrap CIs over seeds lie on the paper's side of both thresholds, contradicted when
/// either lies wholly on the other side, else inconclusive.
fn headline(groups: &[GroupSummary], paper_rows: &[PaperRow]) -> Claim {
    let p = paper::row(paper_rows, Method::Ddpg, Sar);
    let target_s = p.and_then(|p| p.success_rate).unwrap_or(0.996);
    let target_steps = p.and_then(|p| p.eval_steps).unwrap_or(5.0);
    let (need_s, need_steps) = (target_s - HEADLINE_TOLERANCE, target_steps + 0.5);
    let g = primary(groups, Method::Ddpg, Sar).filter(|g| g.seeds > 0);
    let (verdict, detail) = match g {
        None => (Verdict::NotMeasurable, "DDPG+SAR not run".to_string()),
        Some(g) => {
            let (s, _) = Metric::SuccessRate.per_seed(g);
            let (st, _) = Metric::EvalSteps.per_seed(g);
            if s.len() < 2 || st.len() < 2 {
                (Verdict::NotMeasurable, "DDPG+SAR needs at least 2 evaluated seeds with a success".into())
            } else {
                let seed = comparison_seed(usize::MAX >> 1);
                let (slo, shi) = stats::bootstrap_mean_ci(&s, 0.95, BOOTSTRAP_RESAMPLES, seed);
                let (tlo, thi) = stats::bootstrap_mean_ci(&st, 0.95, BOOTSTRAP_RESAMPLES, seed + 1);
                let verdict = if slo >= need_s && thi < need_steps {
                    Verdict::Supported
                } else if shi < need_s || tlo >= need_steps {
                    Verdict::Contradicted
                } else {
                    Verdict::Inconclusive
                };
                let detail = format!(
                    "DDPG+SAR over {} seeds: success rate {:.1} % (95 % CI {:.1}-{:.1} %), evaluation steps {:.2} \
                     (95 % CI {:.2}-{:.2}); supported when both CIs lie on the paper's side of {:.1} % and \
                     {need_steps:.1} steps, contradicted when either lies wholly on the other side",
                    s.len(),
                    100.0 * stats::mean(&s),
                    100.0 * slo,
                    100.0 * shi,
                    stats::mean(&st),
                    tlo,
                    thi,
                    100.0 * need_s
                );
                (verdict, detail)
            }
        }
    };
    Claim {
        id: "ddpg-sar-headline".into(),
        section: "VI.C",
        statement: format!(
            "DDPG+SAR reaches a {:.1} % success rate in {target_steps:.0} steps on average (evaluation)",
            100.0 * target_s
        ),
        paper_text: "\"the success rate of the trajectory planning reached 99.6 %. The average number of steps to complete the trajectory planning was 5\"",
        verdict,
        paper_verdict: if p.is_some() { TableVerdict::Holds } else { TableVerdict::NotMeasurable },
        comparisons: Vec::new(),
        detail,
    }
}

/// Which seeds of the basic reward converged, and why the others did not.
fn basic_detail(groups: &[GroupSummary], algos: &[Method]) -> String {
    let mut parts = Vec::new();
    for &a in algos {
        if let Some(g) = primary(groups, a, Basic).filter(|g| g.seeds > 0) {
            let why: Vec<String> = g
                .runs
                .iter()
                .map(|r| format!("seed {}: {}", r.seed, r.convergence.outcome.describe()))
                .collect();
            parts.push(format!(
                "{}: {} of {} seeds converged ({})",
                label((a, Basic)),
                g.converged,
                g.seeds,
                why.join("; ")
            ));
        }
    }
    parts.join("; ")
}

/// Seeds per group that would resolve `st`'s observed effect at 80 % power at the Bonferroni
/// level `ALPHA / family` (a conservative stand-in for Holm's step-down levels).
fn seeds_needed(st: &Stats, family: usize) -> Option<u64> {
    let alpha = stats::ALPHA / family.max(1) as f64;
    let d = st.effect_size?;
    match st.test {
        Test::Permutation => stats::seeds_for_power(d, alpha, stats::POWER),
        Test::FisherExact => {
            // Two proportions, Cohen's h: n = ((z_{1-alpha/2} + z_power) / h)^2 per group.
            let z = stats::special::normal_quantile(1.0 - alpha / 2.0)
                + stats::special::normal_quantile(stats::POWER);
            (d != 0.0).then(|| ((z / d).powi(2)).ceil() as u64).filter(|&n| n <= 100_000)
        }
    }
}

/// Check every claim against our groups (their primary configurations) and the paper's table:
/// the comparisons' p-values are Holm-corrected together, as one family.
pub fn evaluate(groups: &[GroupSummary], paper_rows: &[PaperRow]) -> Vec<Claim> {
    let mut i = 0;
    let algos = claim_learners(groups);
    let mut claims: Vec<Claim> = specs(&algos)
        .into_iter()
        .map(|s| {
            let comparisons: Vec<Comparison> = s
                .checks
                .iter()
                .map(|&check| {
                    i += 1;
                    compare(groups, paper_rows, check, comparison_seed(i))
                })
                .collect();
            Claim {
                id: s.id.into(),
                section: s.section,
                statement: s.statement,
                paper_text: s.paper_text,
                verdict: Verdict::NotMeasurable,
                paper_verdict: TableVerdict::all(comparisons.iter().map(|c| c.paper_verdict)),
                comparisons,
                detail: String::new(),
            }
        })
        .collect();
    let tested: Vec<(usize, usize)> = claims
        .iter()
        .enumerate()
        .flat_map(|(ci, c)| {
            c.comparisons.iter().enumerate().filter(|(_, k)| k.stats.is_some()).map(move |(ki, _)| (ci, ki))
        })
        .collect();
    let p: Vec<f64> = tested
        .iter()
        .map(|&(ci, ki)| claims[ci].comparisons[ki].stats.as_ref().map_or(1.0, |s| s.p))
        .collect();
    for (&(ci, ki), q) in tested.iter().zip(stats::holm(&p)) {
        let k = &mut claims[ci].comparisons[ki];
        if let Some(st) = k.stats.as_mut() {
            st.p_holm = q;
            k.verdict = Verdict::from_stats(stats::Verdict::of(st.diff, q, expected_sign(k.metric)));
            if k.verdict == Verdict::Inconclusive {
                st.seeds_needed = seeds_needed(st, tested.len());
            }
        }
    }
    for c in &mut claims {
        c.verdict = Verdict::all(c.comparisons.iter().map(|k| k.verdict));
        if c.id == BASIC_CLAIM {
            c.detail = basic_detail(groups, &algos);
        }
    }
    claims.push(headline(groups, paper_rows));
    claims
}

fn mark(v: Verdict) -> &'static str {
    match v {
        Verdict::Supported => "✓",
        Verdict::Contradicted => "✗",
        Verdict::Inconclusive => "~",
        Verdict::NotMeasurable => "?",
    }
}

fn table_mark(v: TableVerdict) -> &'static str {
    match v {
        TableVerdict::Holds => "✓",
        TableVerdict::DoesNotHold => "✗",
        TableVerdict::NotMeasurable => "?",
    }
}

/// A comparison's statistics as table cells: difference [CI], p (Holm), seeds needed.
fn stats_cells(metric: Metric, st: Option<&Stats>) -> [String; 3] {
    let Some(st) = st else { return ["—".into(), "—".into(), "—".into()] };
    let f = |v: f64| match metric {
        Metric::SuccessRate | Metric::Converged => format!("{:+.1} pp", 100.0 * v),
        Metric::EStart => format!("{v:+.0}"),
        _ => format!("{v:+.3}"),
    };
    let test = if st.test == Test::FisherExact { " (Fisher)" } else { "" };
    [
        format!("{} [{}, {}]", f(st.diff), f(st.ci95.0), f(st.ci95.1)),
        format!("{:.2e} ({:.2e}){test}", st.p, st.p_holm),
        st.seeds_needed.map_or_else(|| "—".into(), |n| n.to_string()),
    ]
}

/// The claims as Markdown: how they were tested, a summary table, then each claim with its
/// numbers.
pub fn render_markdown(claims: &[Claim]) -> String {
    let mut s = String::from("# The paper's claims (section VI) against our runs\n\n");
    let count = |v: Verdict| claims.iter().filter(|c| c.verdict == v).count();
    let family: usize =
        claims.iter().map(|c| c.comparisons.iter().filter(|k| k.stats.is_some()).count()).sum();
    let _ = writeln!(
        s,
        "{} claims: {} supported, {} contradicted, {} inconclusive, {} not measurable.\n\n\
         Ours are the primary configuration of each algorithm and reward function in `table1.md`, one value \
         per seed. Each comparison has the difference of the means (first minus second, in the indicator's \
         units; pp = percentage points) with its 95 % bootstrap CI ({BOOTSTRAP_RESAMPLES} resamples), and the \
         p-value of a two-sided permutation test of the difference (Fisher's exact test for convergence \
         counts), Holm-Bonferroni adjusted over the family of all {family} tested comparisons (in brackets). \
         **Supported**: the paper's direction, adjusted p < 0.05; **contradicted**: the opposite direction, \
         adjusted p < 0.05; **inconclusive**: not significant at this number of seeds, with the seeds per \
         group that would resolve the observed effect at 80 % power (t-test at 0.05 / {family}). A claim is \
         supported when all its comparisons are, contradicted when any is. E_start of a seed that did not \
         converge counts as its episodes + 1. \"Paper's table\" is the direction the paper's own Table 1 \
         gives (means only), which does not always support its text.\n",
        claims.len(),
        count(Verdict::Supported),
        count(Verdict::Contradicted),
        count(Verdict::Inconclusive),
        count(Verdict::NotMeasurable)
    );
    // The learners of the reward claims, when they are not the paper's (`claim_learners`).
    let mut learners: Vec<Method> = Vec::new();
    for k in claims.iter().filter(|c| c.id == BASIC_CLAIM).flat_map(|c| &c.comparisons) {
        if !learners.contains(&k.better.0) {
            learners.push(k.better.0);
        }
    }
    if !learners.is_empty() && learners != PAPER_ALGOS {
        let names: Vec<&str> = learners.iter().map(|&a| algo_title(a)).collect();
        let _ = writeln!(
            s,
            "This report holds neither of the paper's learners (SAC, DDPG), so the claims about rewards \
             (\"with each algorithm\") are checked with {}; the claims that compare SAC with DDPG are not \
             measurable here.\n",
            names.join(" and ")
        );
    }
    s.push_str("| # | Section | Claim | Ours | Paper's table |\n|---|---|---|---|---|\n");
    for (i, c) in claims.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {} | {} | **{}** | {} |",
            i + 1,
            c.section,
            c.statement,
            c.verdict.text(),
            c.paper_verdict.text()
        );
    }
    for (i, c) in claims.iter().enumerate() {
        let _ = writeln!(s, "\n## {}. {} — {}\n", i + 1, c.statement, c.verdict.text());
        let _ = writeln!(s, "Section {}: {}\n", c.section, c.paper_text);
        if !c.detail.is_empty() {
            let _ = writeln!(s, "{}\n", c.detail);
        }
        if !c.comparisons.is_empty() {
            s.push_str(
                "| Indicator | Ours | Difference [95 % CI] | p (Holm) | Verdict | Seeds for 80 % power | Paper's table | |\n\
                 |---|---|---|---|---|---|---|---|\n",
            );
            for k in &c.comparisons {
                let [diff, p, need] = stats_cells(k.metric, k.stats.as_ref());
                let _ = writeln!(
                    s,
                    "| {} | {} | {diff} | {p} | {} {} | {need} | {} | {} |",
                    k.metric.name(),
                    k.ours,
                    mark(k.verdict),
                    k.verdict.text(),
                    k.paper,
                    table_mark(k.paper_verdict)
                );
            }
        }
    }
    s
}

#[cfg(test)]
mod tests;
