//! What a report says about the study as a whole: its regime (the paper's untuned settings or
//! our tuned defaults), its seeds and episodes, and the scripted Jacobian (damped least squares)
//! controller evaluated as a reference on the same targets as the runs' closing evaluations.

use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::Path;

use super::runs::RunData;
use super::table::{reward_title, Group, GroupSummary};
use crate::env::{Policy, ReachEnv};
use crate::plan::controller::JacobianController;
use crate::reward::RewardFunction;
use crate::train::eval::{EvalOptions, EvalSummary};
use crate::Result;

/// Which settings a study's runs use, as the preset of their sweep names it (`[sweep] regime`,
/// recorded in the sweep directory's `preset.toml`); never inferred from the runs' values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Regime {
    /// gamma 0.99 and unscaled observations (obs_delta_scale 1): the values most RL libraries
    /// use when nothing is said; the paper gives neither.
    Paper,
    /// Our measured defaults: gamma 0.95, obs_delta_scale 10.
    Tuned,
    /// Runs whose preset names no regime, runs of no sweep, or runs of several regimes.
    Custom,
}

/// The largest `preset.toml` read for its regime, bytes.
const MAX_PRESET_BYTES: u64 = 1 << 20;

impl Regime {
    /// The values `(agent.gamma, task.obs_delta_scale)` of the regime (none for `Custom`): a
    /// preset that names the regime must use them (the sweep checks it).
    pub fn settings(self) -> Option<(f64, f64)> {
        match self {
            Regime::Paper => Some((0.99, 1.0)),
            Regime::Tuned => Some((0.95, 10.0)),
            Regime::Custom => None,
        }
    }

    /// The regime named by the preset of the sweep the run in `run_dir` belongs to: the
    /// `[sweep] regime` of the nearest `preset.toml` from `run_dir` up to `root`, the report's
    /// input directory; `Custom` when none names one.
    pub fn of_run(run_dir: &Path, root: &Path) -> Regime {
        let named = |dir: &Path| -> Option<Regime> {
            let mut text = String::new();
            let file = std::fs::File::open(dir.join("preset.toml")).ok()?;
            file.take(MAX_PRESET_BYTES).read_to_string(&mut text).ok()?;
            let table: toml::Table = toml::from_str(&text).ok()?;
            table.get("sweep")?.get("regime")?.clone().try_into().ok()
        };
        run_dir.ancestors().take_while(|d| d.starts_with(root)).find_map(named).unwrap_or(Regime::Custom)
    }

    /// The regime every primary run shares (`Custom` when they differ).
    pub fn of_groups(groups: &[Group]) -> Regime {
        let mut regimes = groups.iter().filter(|g| g.primary).flat_map(|g| g.runs.iter()).map(|r| r.regime);
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
            Regime::Custom => {
                "custom settings (no sweep preset names the paper or the tuned regime for all runs)"
            }
        }
    }
}

/// One line naming the study for tables and figure subtitles: regime, seeds, episodes, input.
pub fn study_line(groups: &[Group], input: &str) -> String {
    let primary: Vec<&RunData> = groups.iter().filter(|g| g.primary).flat_map(|g| g.runs.iter()).collect();
    let mut seeds: Vec<u64> = primary.iter().map(|r| r.seed()).collect();
    seeds.sort_unstable();
    seeds.dedup();
    // A budget of environment steps replaces the episode count (`train.env_steps`).
    let (budgets, unit): (Vec<u64>, &str) = if primary.iter().any(|r| r.config.train.env_steps.is_some()) {
        (primary.iter().map(|r| r.config.train.env_steps.unwrap_or(0)).collect(), "environment steps")
    } else {
        (primary.iter().map(|r| r.config.train.episodes).collect(), "episodes")
    };
    let mut episodes = budgets;
    episodes.sort_unstable();
    episodes.dedup();
    let list = |v: &[u64]| v.iter().map(u64::to_string).collect::<Vec<_>>().join(", ");
    let seeds_text = if seeds.len() > 6 {
        format!("{} seeds ({}-{})", seeds.len(), seeds[0], seeds[seeds.len() - 1])
    } else {
        format!("{} seed(s) ({})", seeds.len(), list(&seeds))
    };
    format!(
        "Study `{input}`: {}; {seeds_text}; {} {unit} per run.",
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
        let (summary, _) = crate::train::eval::evaluate(
            &mut env,
            &mut Policy(ctl.policy()),
            &EvalOptions::new(trials, seed),
        )?;
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
    fn the_tuned_regime_is_the_defaults() {
        let d = crate::config::Config::default();
        assert_eq!(Regime::Tuned.settings(), Some((d.agent.gamma, d.task.obs_delta_scale)));
        assert_eq!(Regime::Custom.settings(), None);
    }

    #[test]
    fn a_runs_regime_is_the_one_its_nearest_preset_names() {
        let root = std::env::temp_dir().join(format!("stagerl-regime-{}", std::process::id()));
        let (sweep, run) = (root.join("sweep"), root.join("sweep/sac-sar-seed1"));
        std::fs::create_dir_all(&run).unwrap();
        let write = |dir: &Path, text: &str| std::fs::write(dir.join("preset.toml"), text).unwrap();
        assert_eq!(Regime::of_run(&run, &root), Regime::Custom, "no preset");
        write(&root, "[sweep]\nregime = \"tuned\"\n");
        write(&sweep, "[sweep]\nalgorithms = [\"sac\"]\nregime = \"paper\"\n");
        assert_eq!(Regime::of_run(&run, &root), Regime::Paper, "the nearest preset");
        assert_eq!(Regime::of_run(&run, &sweep), Regime::Paper);
        write(&sweep, "[sweep]\nalgorithms = [\"sac\"]\n");
        assert_eq!(Regime::of_run(&run, &root), Regime::Tuned, "a preset naming none: the next one up");
        assert_eq!(Regime::of_run(&run, &sweep), Regime::Custom, "nothing above the report's input");
        write(&sweep, "[sweep]\nregime = \"fast\"\n");
        assert_eq!(Regime::of_run(&run, &sweep), Regime::Custom, "an unknown name");
        std::fs::remove_dir_all(&root).unwrap();
    }
}
