//! The paper's claims from section VI, checked against our Table 1 (and against the paper's own
//! Table 1, which does not always support the text).

use serde::Serialize;
use std::fmt::Write as _;

use super::paper::{self, PaperRow};
use super::table::{algo_title, primary, reward_title, GroupSummary};
use crate::agent::Algo;
use crate::metrics::MeanStd;
use crate::reward::RewardFunction::{self, Basic, Har, Posture, Sar, Stride};

/// Our verdict on a claim.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Holds,
    DoesNotHold,
    /// A group it needs was not run, or did not produce the indicator.
    NotMeasurable,
}

impl Verdict {
    pub fn text(self) -> &'static str {
        match self {
            Verdict::Holds => "holds",
            Verdict::DoesNotHold => "does not hold",
            Verdict::NotMeasurable => "not measurable",
        }
    }

    /// Any failure decides; then anything unmeasurable; else it holds.
    fn all(vs: impl IntoIterator<Item = Verdict>) -> Verdict {
        let vs: Vec<Verdict> = vs.into_iter().collect();
        if vs.contains(&Verdict::DoesNotHold) {
            Verdict::DoesNotHold
        } else if vs.is_empty() || vs.contains(&Verdict::NotMeasurable) {
            Verdict::NotMeasurable
        } else {
            Verdict::Holds
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
        }
    }

    fn fmt(self, v: f64) -> String {
        match self {
            Metric::EStart => format!("{v:.0}"),
            Metric::SuccessRate => format!("{:.1} %", 100.0 * v),
            Metric::TrainSteps | Metric::EvalSteps => format!("{v:.1}"),
            _ => format!("{v:.3}"),
        }
    }

    fn fmt_ms(self, m: &MeanStd) -> String {
        match m.std {
            Some(s) if self == Metric::SuccessRate => format!("{:.1} ± {:.1} %", 100.0 * m.mean, 100.0 * s),
            Some(s) => format!("{} ± {}", self.fmt(m.mean), self.fmt(s).trim_end_matches(" %")),
            None => self.fmt(m.mean),
        }
    }
}

/// One "a is better than b on metric" check.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    pub metric: Metric,
    pub better: (Algo, RewardFunction),
    pub worse: (Algo, RewardFunction),
    pub verdict: Verdict,
    /// Our numbers, e.g. `SAC+SAR 812 ± 95 vs SAC+HAR 1032 ± 40: 21.3 % lower`.
    pub ours: String,
    pub paper_verdict: Verdict,
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
    pub paper_verdict: Verdict,
    pub comparisons: Vec<Comparison>,
    /// Our numbers for claims that are not comparisons.
    pub detail: String,
}

fn label((a, r): (Algo, RewardFunction)) -> String {
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

fn compare(
    groups: &[GroupSummary],
    paper_rows: &[PaperRow],
    metric: Metric,
    better: (Algo, RewardFunction),
    worse: (Algo, RewardFunction),
) -> Comparison {
    let beats = |a: f64, b: f64| if metric.lower_is_better() { a < b } else { a > b };
    let (la, lb) = (label(better), label(worse));
    // Ours.
    let ga = primary(groups, better.0, better.1).filter(|g| g.seeds > 0);
    let gb = primary(groups, worse.0, worse.1).filter(|g| g.seeds > 0);
    let (verdict, ours) = match (ga, gb) {
        (None, _) | (_, None) => {
            let missing: Vec<String> = [(ga, &la), (gb, &lb)]
                .iter()
                .filter(|(g, _)| g.is_none())
                .map(|(_, l)| format!("{l} not run"))
                .collect();
            (Verdict::NotMeasurable, missing.join(", "))
        }
        (Some(ga), Some(gb)) => match (metric.ours(ga), metric.ours(gb)) {
            (Some(a), Some(b)) => {
                let v = if beats(a.mean, b.mean) { Verdict::Holds } else { Verdict::DoesNotHold };
                let spread = a.std.unwrap_or(0.0).max(b.std.unwrap_or(0.0));
                let within = if (a.mean - b.mean).abs() < spread { " (within the seed spread)" } else { "" };
                let text = format!(
                    "{la} {} vs {lb} {}{}{within}",
                    metric.fmt_ms(&a),
                    metric.fmt_ms(&b),
                    relative(metric, a.mean, b.mean)
                );
                (v, text)
            }
            (Some(a), None) if metric == Metric::EStart && gb.converged == 0 => {
                (Verdict::Holds, format!("{la} {} vs {lb} did not converge", metric.fmt_ms(&a)))
            }
            (None, Some(b)) if metric == Metric::EStart && ga.converged == 0 => {
                (Verdict::DoesNotHold, format!("{la} did not converge vs {lb} {}", metric.fmt_ms(&b)))
            }
            (a, b) => {
                let why = |g: &GroupSummary, m: Option<MeanStd>, l: &str| match m {
                    Some(m) => format!("{l} {}", metric.fmt_ms(&m)),
                    None if g.converged == 0 && metric != Metric::EvalReward => {
                        format!("{l} did not converge")
                    }
                    None => format!("{l} has no {}", metric.name()),
                };
                (Verdict::NotMeasurable, format!("{}, {}", why(ga, a, &la), why(gb, b, &lb)))
            }
        },
    };
    // The paper's table.
    let pa = paper::row(paper_rows, better.0, better.1);
    let pb = paper::row(paper_rows, worse.0, worse.1);
    let (paper_verdict, paper) = match (pa.map(|p| metric.paper(p)), pb.map(|p| metric.paper(p))) {
        (Some(Some(a)), Some(Some(b))) => (
            if beats(a, b) { Verdict::Holds } else { Verdict::DoesNotHold },
            format!("{} vs {}{}", metric.fmt(a), metric.fmt(b), relative(metric, a, b)),
        ),
        _ => (Verdict::NotMeasurable, "not in the paper's table".into()),
    };
    Comparison { metric, better, worse, verdict, ours, paper_verdict, paper }
}

/// An (algorithm, reward function) pair: one row of Table 1.
type Cell = (Algo, RewardFunction);
/// `(metric, better, worse)`.
type Check = (Metric, Cell, Cell);

struct Spec {
    id: &'static str,
    section: &'static str,
    statement: String,
    paper_text: &'static str,
    checks: Vec<Check>,
}

const ALGOS: [Algo; 2] = [Algo::Sac, Algo::Ddpg];

fn per_algo(metric: Metric, better: RewardFunction, worse: &[RewardFunction]) -> Vec<Check> {
    ALGOS.iter().flat_map(|&a| worse.iter().map(move |&w| (metric, (a, better), (a, w)))).collect()
}

/// The paper's claims, section by section.
fn specs() -> Vec<Spec> {
    [specs_vi_a(), specs_vi_b(), specs_vi_c()].into_iter().flatten().collect()
}

/// Section VI.A: posture against stride, SAC against DDPG.
fn specs_vi_a() -> Vec<Spec> {
    use Metric::*;
    let dense = [Posture, Stride, Har, Sar];
    vec![
        Spec {
            id: "sac-converges-faster",
            section: "VI.A",
            statement: "SAC converges faster than DDPG (smaller E_start) with every dense reward".into(),
            paper_text: "\"SAC converged faster in general\"; 10.8 % faster with posture, 17.9 % with stride",
            checks: dense.iter().map(|&r| (EStart, (Algo::Sac, r), (Algo::Ddpg, r))).collect(),
        },
        Spec {
            id: "posture-faster-than-stride",
            section: "VI.A",
            statement: "Posture converges faster than stride (smaller E_start), with each algorithm".into(),
            paper_text: "\"the convergence rate of the posture reward function increased by 22.6-26.4 %\"",
            checks: per_algo(EStart, Posture, &[Stride]),
        },
        Spec {
            id: "stride-lower-std-than-posture",
            section: "VI.A",
            statement: "Stride has a lower V_STDEV than posture, with each algorithm".into(),
            paper_text: "\"the standard deviation of the stride reward function was 23.7-46.4 % lower\"",
            checks: per_algo(VStdev, Stride, &[Posture]),
        },
        Spec {
            id: "stride-higher-reward-ddpg",
            section: "VI.A",
            statement: "With DDPG, stride has a higher mean training reward than posture".into(),
            paper_text: "\"the mean reward of the stride reward function was 3.2 % higher than that of the posture reward function in DDPG\"",
            checks: vec![(TrainReward, (Algo::Ddpg, Stride), (Algo::Ddpg, Posture))],
        },
        Spec {
            id: "posture-fewer-steps",
            section: "VI.A",
            statement: "Posture completes the task in fewer evaluation steps than stride, with each algorithm".into(),
            paper_text: "\"the posture reward function completes trajectory planning with fewer average steps\"",
            checks: per_algo(EvalSteps, Posture, &[Stride]),
        },
        Spec {
            id: "stride-more-reward",
            section: "VI.A",
            statement: "Stride obtains a higher evaluation reward than posture, with each algorithm".into(),
            paper_text: "\"the stride reward function obtains more rewards\"",
            checks: per_algo(EvalReward, Stride, &[Posture]),
        },
    ]
}

/// Section VI.B: HAR.
fn specs_vi_b() -> Vec<Spec> {
    use Metric::*;
    vec![
        Spec {
            id: "har-lower-std-than-posture",
            section: "VI.B",
            statement: "HAR has a lower V_STDEV than posture, with each algorithm".into(),
            paper_text: "\"the standard deviation decreased by about 42.6 % with HAR compared to the posture reward function\"",
            checks: per_algo(VStdev, Har, &[Posture]),
        },
        Spec {
            id: "har-faster-than-stride",
            section: "VI.B",
            statement: "HAR converges faster than stride, with each algorithm".into(),
            paper_text: "\"The convergence rate of the HAR reward function was about 20.4 % faster than that of the stride reward function\"",
            checks: per_algo(EStart, Har, &[Stride]),
        },
        Spec {
            id: "har-slower-than-posture",
            section: "VI.B",
            statement: "HAR converges more slowly than posture, with each algorithm".into(),
            paper_text: "\"but it was slower than the posture reward function\"",
            checks: ALGOS.iter().map(|&a| (EStart, (a, Posture), (a, Har))).collect(),
        },
        Spec {
            id: "har-better-evaluation",
            section: "VI.B",
            statement: "In evaluation HAR beats posture and stride on reward, steps and success rate, with each algorithm".into(),
            paper_text: "\"The reward increased to 24.7 %, the average steps decreased by 16.7-27.2 %, and the success rate for trajectory planning increased by 2.4-5.2 %\"",
            checks: [EvalReward, EvalSteps, SuccessRate]
                .iter()
                .flat_map(|&m| per_algo(m, Har, &[Posture, Stride]))
                .collect(),
        },
    ]
}

/// Section VI.C: SAR.
fn specs_vi_c() -> Vec<Spec> {
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
            checks: per_algo(metric, Sar, &[Posture, Stride, Har]),
        });
    }
    v.push(Spec {
        id: "sar-sac-faster-than-ddpg",
        section: "VI.C",
        statement: "With SAR, SAC converges faster than DDPG".into(),
        paper_text: "\"The convergence rate of SAR in DDPG was slower than that of SAR in SAC\"",
        checks: vec![(EStart, (Algo::Sac, Sar), (Algo::Ddpg, Sar))],
    });
    v.push(Spec {
        id: "sar-ddpg-better-otherwise",
        section: "VI.C",
        statement: "With SAR, DDPG beats SAC on every indicator but E_start".into(),
        paper_text: "\"but other indicators were better in DDPG than in SAC\"",
        checks: [TrainReward, TrainSteps, VStdev, EvalReward, EvalSteps, SuccessRate]
            .iter()
            .map(|&m| (m, (Algo::Ddpg, Sar), (Algo::Sac, Sar)))
            .collect(),
    });
    v
}

/// Success-rate tolerance of the headline claim, in absolute terms (one percentage point).
const HEADLINE_TOLERANCE: f64 = 0.01;

fn headline(groups: &[GroupSummary], paper_rows: &[PaperRow]) -> Claim {
    let p = paper::row(paper_rows, Algo::Ddpg, Sar);
    let (ps, pst) = (p.and_then(|p| p.success_rate), p.and_then(|p| p.eval_steps));
    let target_s = ps.unwrap_or(0.996);
    let target_steps = pst.unwrap_or(5.0);
    let g = primary(groups, Algo::Ddpg, Sar).filter(|g| g.seeds > 0);
    let (verdict, detail) = match g.map(|g| (g.success_rate, g.eval_steps)) {
        Some((Some(s), Some(st))) => {
            let ok = s.mean >= target_s - HEADLINE_TOLERANCE && st.mean < target_steps + 0.5;
            (
                if ok { Verdict::Holds } else { Verdict::DoesNotHold },
                format!(
                    "DDPG+SAR: success rate {}, evaluation steps {} (holds when the success rate is at least {:.1} % and the steps round to {target_steps:.0} or fewer)",
                    Metric::SuccessRate.fmt_ms(&s),
                    Metric::EvalSteps.fmt_ms(&st),
                    100.0 * (target_s - HEADLINE_TOLERANCE)
                ),
            )
        }
        Some(_) => (Verdict::NotMeasurable, "DDPG+SAR has no per-trial evaluation".into()),
        None => (Verdict::NotMeasurable, "DDPG+SAR not run".into()),
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
        paper_verdict: if p.is_some() { Verdict::Holds } else { Verdict::NotMeasurable },
        comparisons: Vec::new(),
        detail,
    }
}

fn basic(groups: &[GroupSummary], paper_rows: &[PaperRow]) -> Claim {
    let mut verdicts = Vec::new();
    let mut parts = Vec::new();
    for a in ALGOS {
        match primary(groups, a, Basic).filter(|g| g.seeds > 0) {
            None => {
                verdicts.push(Verdict::NotMeasurable);
                parts.push(format!("{} not run", label((a, Basic))));
            }
            Some(g) => {
                verdicts.push(if g.converged == 0 { Verdict::Holds } else { Verdict::DoesNotHold });
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
    }
    let paper_ok = ALGOS.iter().all(|&a| paper::row(paper_rows, a, Basic).is_some_and(|p| !p.converged()));
    Claim {
        id: "basic-does-not-converge".into(),
        section: "VI.A",
        statement: "The sparse basic reward (eq. 18) does not converge with SAC or DDPG".into(),
        paper_text: "\"DDPG and SAC could not converge even after a long training period based on a sparse reward function\"",
        verdict: Verdict::all(verdicts),
        paper_verdict: if paper_ok { Verdict::Holds } else { Verdict::NotMeasurable },
        comparisons: Vec::new(),
        detail: parts.join("; "),
    }
}

/// Check every claim against our groups (their primary configurations) and the paper's table.
pub fn evaluate(groups: &[GroupSummary], paper_rows: &[PaperRow]) -> Vec<Claim> {
    let mut claims: Vec<Claim> = specs()
        .into_iter()
        .map(|s| {
            let comparisons: Vec<Comparison> =
                s.checks.iter().map(|&(m, a, b)| compare(groups, paper_rows, m, a, b)).collect();
            Claim {
                id: s.id.into(),
                section: s.section,
                statement: s.statement,
                paper_text: s.paper_text,
                verdict: Verdict::all(comparisons.iter().map(|c| c.verdict)),
                paper_verdict: Verdict::all(comparisons.iter().map(|c| c.paper_verdict)),
                comparisons,
                detail: String::new(),
            }
        })
        .collect();
    claims.insert(0, basic(groups, paper_rows));
    claims.push(headline(groups, paper_rows));
    claims
}

fn mark(v: Verdict) -> &'static str {
    match v {
        Verdict::Holds => "✓",
        Verdict::DoesNotHold => "✗",
        Verdict::NotMeasurable => "?",
    }
}

/// The claims as Markdown: a summary table, then each claim with its numbers.
pub fn render_markdown(claims: &[Claim]) -> String {
    let mut s = String::from("# The paper's claims (section VI) against our runs\n\n");
    let count = |v: Verdict| claims.iter().filter(|c| c.verdict == v).count();
    let _ = writeln!(
        s,
        "{} claims: {} hold, {} do not hold, {} not measurable. Ours are the primary configuration of each \
         algorithm and reward function in `table1.md` (mean over seeds); \"paper's table\" is the verdict the \
         paper's own Table 1 gives, which does not always support its text. Percentages are relative to the \
         second value of each comparison; \"within the seed spread\": the difference is smaller than the larger \
         std over seeds.\n",
        claims.len(),
        count(Verdict::Holds),
        count(Verdict::DoesNotHold),
        count(Verdict::NotMeasurable)
    );
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
            s.push_str("| Indicator | Ours | | Paper's table | |\n|---|---|---|---|---|\n");
            for k in &c.comparisons {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {} |",
                    k.metric.name(),
                    k.ours,
                    mark(k.verdict),
                    k.paper,
                    mark(k.paper_verdict)
                );
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_combine() {
        use Verdict::*;
        assert_eq!(Verdict::all([Holds, Holds]), Holds);
        assert_eq!(Verdict::all([Holds, NotMeasurable]), NotMeasurable);
        assert_eq!(Verdict::all([NotMeasurable, DoesNotHold, Holds]), DoesNotHold);
        assert_eq!(Verdict::all([]), NotMeasurable);
    }

    #[test]
    fn the_papers_own_table_on_its_claims() {
        let rows = paper::table1();
        let claims = evaluate(&[], &rows);
        let by_id = |id: &str| claims.iter().find(|c| c.id == id).unwrap();
        // Everything is unmeasurable for us without runs.
        assert!(claims.iter().all(|c| c.verdict == Verdict::NotMeasurable));
        // The paper's table supports these...
        for id in [
            "sac-converges-faster",
            "posture-faster-than-stride",
            "sar-fastest",
            "sar-lowest-std",
            "basic-does-not-converge",
        ] {
            assert_eq!(by_id(id).paper_verdict, Verdict::Holds, "{id}");
        }
        // ... but not "posture needs fewer steps" (DDPG: 11 vs 11).
        assert_eq!(by_id("posture-fewer-steps").paper_verdict, Verdict::DoesNotHold);
        // Relative differences are computed like the paper's percentages: 10.8 % for posture.
        let c = &by_id("sac-converges-faster").comparisons[0];
        assert!(c.paper.contains("10.8 % earlier"), "{}", c.paper);
    }
}
