//! What a report says about the study as a whole: its regime (the paper's untuned settings or
//! our tuned defaults), its seeds and episodes, and the scripted Jacobian (damped least squares)
//! controller evaluated as a reference on the same targets as the runs' closing evaluations.

use serde::Serialize;

use super::runs::RunData;
use super::table::{reward_title, Group, GroupSummary};
use crate::env::{Policy, ReachEnv};
use crate::plan::controller::JacobianController;
use crate::reward::RewardFunction;
use crate::train::eval::{EvalOptions, EvalSummary};
use crate::Result;

/// Which settings a study's runs use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Regime {
    /// gamma 0.99 and unscaled observations (obs_delta_scale 1): the values most RL libraries
    /// use when nothing is said; the paper gives neither.
    Paper,
    /// Our measured defaults: gamma 0.95, obs_delta_scale 10.
    Tuned,
    /// Anything else, or runs of several regimes.
    Custom,
}

impl Regime {
    /// The regime of one run's settings.
    pub fn of(gamma: f64, obs_delta_scale: f64) -> Regime {
        match (gamma, obs_delta_scale) {
            (g, k) if g == 0.99 && k == 1.0 => Regime::Paper,
            (g, k) if g == 0.95 && k == 10.0 => Regime::Tuned,
            _ => Regime::Custom,
        }
    }

    /// The regime every primary run shares (`Custom` when they differ).
    pub fn of_groups(groups: &[Group]) -> Regime {
        let mut regimes = groups
            .iter()
            .filter(|g| g.primary)
            .flat_map(|g| g.runs.iter())
            .map(|r| Regime::of(r.config.agent.gamma, r.config.task.obs_delta_scale));
        let first = regimes.next().unwrap_or(Regime::Custom);
        if regimes.all(|r| r == first) {
            first
        } else {
            Regime::Custom
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Regime::Paper => "paper regime (gamma 0.99, unscaled observations: obs_delta_scale 1)",
            Regime::Tuned => "tuned regime (our defaults: gamma 0.95, obs_delta_scale 10)",
            Regime::Custom => "custom settings (neither the paper regime nor the tuned defaults)",
        }
    }
}

/// One line naming the study for tables and figure subtitles: regime, seeds, episodes, input.
pub fn study_line(groups: &[Group], input: &str) -> String {
    let primary: Vec<&RunData> = groups.iter().filter(|g| g.primary).flat_map(|g| g.runs.iter()).collect();
    let mut seeds: Vec<u64> = primary.iter().map(|r| r.seed()).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let mut episodes: Vec<u64> = primary.iter().map(|r| r.config.train.episodes).collect();
    episodes.sort_unstable();
    episodes.dedup();
    let list = |v: &[u64]| v.iter().map(u64::to_string).collect::<Vec<_>>().join(", ");
    let seeds_text = if seeds.len() > 6 {
        format!("{} seeds ({}-{})", seeds.len(), seeds[0], seeds[seeds.len() - 1])
    } else {
        format!("{} seed(s) ({})", seeds.len(), list(&seeds))
    };
    format!(
        "Study `{input}`: {}; {seeds_text}; {} episodes per run.",
        Regime::of_groups(groups).describe(),
        list(&episodes)
    )
}

/// The scripted controller on the closing evaluations' targets, under one reward function.
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceRow {
    pub reward: RewardFunction,
    pub seed: u64,
    pub summary: EvalSummary,
}

/// Evaluate the controller for every reward function of the primary groups, with the first run's
/// arm and task, on the targets and trial count of that group's closing evaluation (seed and
/// trials of its evaluation file; the run's `train.eval_trials` when it has none).
pub fn evaluate(groups: &[Group], summaries: &[GroupSummary]) -> Result<Vec<ReferenceRow>> {
    let mut out = Vec::new();
    for reward in RewardFunction::ALL {
        let Some((g, s)) = groups.iter().zip(summaries).find(|(g, _)| g.primary && g.reward == reward) else {
            continue;
        };
        let Some(run) = g.runs.first() else { continue };
        let seed = run.final_eval.as_ref().map_or(crate::train::eval::DEFAULT_EVAL_SEED, |f| f.seed);
        let trials = s.eval_trials.map_or(run.config.train.eval_trials, |t| t as u32).max(1);
        let mut cfg = run.config.clone();
        cfg.reward.function = reward;
        let mut env = ReachEnv::from_config(&cfg, 0)?;
        let chain = env.chain().clone();
        let mut ctl = JacobianController::new(&chain);
        let (summary, _) =
            crate::train::eval::evaluate(&mut env, &mut Policy(ctl.policy()), &EvalOptions::new(trials, seed))?;
        out.push(ReferenceRow { reward, seed, summary });
    }
    Ok(out)
}

/// The reference rows as a Markdown section.
pub fn render_markdown(rows: &[ReferenceRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\n## Reference: the scripted Jacobian controller\n\nA damped-least-squares controller \
         (`stagerl::plan::controller`, no learning) on the same targets as each reward function's closing \
         evaluation: what a learned planner is measured against.\n\n\
         | Method | Reward | Trials (seed) | Evaluation reward | Evaluation steps | Success rate |\n|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| Jacobian controller | {} | {} ({}) | {:.3} | {} | {:.1} % |\n",
            reward_title(r.reward),
            r.summary.trials,
            r.seed,
            r.summary.mean_reward,
            r.summary.mean_steps.map_or_else(|| "—".to_string(), |m| format!("{m:.2}")),
            100.0 * r.summary.success_rate
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regimes_from_settings() {
        assert_eq!(Regime::of(0.99, 1.0), Regime::Paper);
        assert_eq!(Regime::of(0.95, 10.0), Regime::Tuned);
        assert_eq!(Regime::of(0.99, 10.0), Regime::Custom);
        let d = crate::config::Config::default();
        assert_eq!(
            Regime::of(d.agent.gamma, d.task.obs_delta_scale),
            Regime::Tuned,
            "the defaults are the tuned regime"
        );
    }
}
