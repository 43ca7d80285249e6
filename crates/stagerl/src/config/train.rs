//! The training schedule (the `[train]` section): the seed, how many episodes, when to evaluate
//! and when to checkpoint; the trainer asks it at every episode's end.

use serde::{Deserialize, Serialize};

use super::curriculum::CurriculumConfig;
use super::demonstrations::DemonstrationsConfig;
use crate::{Error, Result};

/// The largest evaluation asked for at once (its per-trial records are kept in memory).
pub const MAX_EVAL_TRIALS: u32 = 10_000_000;

/// The largest budget in environment steps (`train.env_steps`, `train.eval_every_env_steps`):
/// 2^40, about 10^12, years of training at our speeds.
pub const MAX_ENV_STEPS: u64 = 1 << 40;

/// Training settings (the `[train]` section).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The run's seed: environment targets, initial weights, exploration, replay sampling.
    pub seed: u64,
    /// Training episodes (paper: 10000). Default 5000: DDPG + SAR reaches 99 % by then, SAC + SAR
    /// by about 1500. Not used when `env_steps` is set.
    pub episodes: u64,
    /// A budget in environment steps instead of episodes (unset by default: the episode
    /// budget): the run ends with the episode in which its N-th environment step falls (so it
    /// may pass N by less than one episode's steps per environment), whatever its episode count.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub env_steps: Option<u64>,
    /// Evaluate the deterministic policy every this many episodes; 0 disables.
    pub eval_every_episodes: u64,
    /// Evaluate every this many environment steps instead of every `eval_every_episodes` (unset
    /// by default): after each episode in which a multiple of it is passed, and after the last.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eval_every_env_steps: Option<u64>,
    /// Trials of each periodic evaluation.
    pub eval_trials: u32,
    /// Seed of the evaluation targets (the same targets at every evaluation point).
    pub eval_seed: u64,
    /// Write `checkpoints/latest.safetensors` every this many episodes; 0 only at the end.
    pub checkpoint_every_episodes: u64,
    /// A curriculum for `[task.random_obstacles]`: the probability that a training episode's
    /// first random obstacle is placed in the way, across the straight line from the start
    /// pose's end effector to the target (`sim::scene::place_obstacles`), rather than anywhere
    /// in the region. Evaluations draw their obstacles as the task says, unbiased. In [0, 1];
    /// 0 (the default, left out of a written config) changes nothing.
    #[serde(skip_serializing_if = "is_zero")]
    pub obstacles_in_path: f64,
    /// A curriculum over the random obstacles (unset by default): stages of rising in-the-way
    /// probability and obstacle count that advance with the training success rate (see
    /// [`CurriculumConfig`]). Off-policy agents only; needs `[task.random_obstacles]`; replaces
    /// `train.obstacles_in_path`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curriculum: Option<CurriculumConfig>,
    /// Demonstrations from the reference planner in the replay buffer before the first episode
    /// (unset by default; see [`DemonstrationsConfig`]). Off-policy agents only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub demonstrations: Option<DemonstrationsConfig>,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            seed: 0,
            episodes: 5000,
            env_steps: None,
            eval_every_episodes: 250,
            eval_every_env_steps: None,
            eval_trials: 100,
            eval_seed: 1_000_003,
            checkpoint_every_episodes: 250,
            obstacles_in_path: 0.0,
            curriculum: None,
            demonstrations: None,
        }
    }
}

impl TrainConfig {
    pub fn validate(&self) -> Result<()> {
        if self.episodes == 0 {
            return Err(Error::config("train.episodes", 0, "an integer >= 1"));
        }
        if self.eval_trials > MAX_EVAL_TRIALS {
            return Err(Error::config(
                "train.eval_trials",
                self.eval_trials,
                format!("at most {MAX_EVAL_TRIALS}"),
            ));
        }
        for (field, value) in
            [("train.env_steps", self.env_steps), ("train.eval_every_env_steps", self.eval_every_env_steps)]
        {
            if let Some(v) = value.filter(|v| !(1..=MAX_ENV_STEPS).contains(v)) {
                return Err(Error::config(
                    field,
                    v,
                    format!("an integer from 1 to {MAX_ENV_STEPS} (or leave it out: the budget and evaluations by episodes)"),
                ));
            }
        }
        if self.eval_every_env_steps.is_some() && self.eval_trials == 0 {
            return Err(Error::config(
                "train.eval_trials",
                0,
                "an integer >= 1 (or leave train.eval_every_env_steps out and set train.eval_every_episodes = 0 to disable evaluation)",
            ));
        }
        if self.eval_every_env_steps.is_none() && self.eval_every_episodes > 0 && self.eval_trials == 0 {
            return Err(Error::config(
                "train.eval_trials",
                0,
                "an integer >= 1 (or set train.eval_every_episodes = 0 to disable evaluation)",
            ));
        }
        if let Some(c) = &self.curriculum {
            c.validate_values()?;
        }
        Ok(())
    }
}

impl TrainConfig {
    /// The run ends after this (1-based) episode, which ended at `env_steps` environment steps:
    /// the episode budget's last episode, or the first to reach `env_steps`.
    pub fn is_last(&self, episode: u64, env_steps: u64) -> bool {
        match self.env_steps {
            Some(n) => env_steps >= n,
            None => episode >= self.episodes,
        }
    }

    /// The run evaluates after this (1-based) episode, which took the run from `steps_before`
    /// to `steps_after` environment steps (the previous episode's end and its own): every
    /// `eval_every_env_steps` passed when that is set, else every `eval_every_episodes`; and
    /// after the last one.
    pub fn is_eval_point(&self, episode: u64, steps_before: u64, steps_after: u64) -> bool {
        let last = self.is_last(episode, steps_after);
        match self.eval_every_env_steps {
            Some(k) => steps_after / k > steps_before / k || last,
            None => {
                let every = self.eval_every_episodes;
                every > 0 && (episode.is_multiple_of(every) || last)
            }
        }
    }

    /// The run writes `latest.safetensors` after this episode: every
    /// `checkpoint_every_episodes`, but the last (the end of the run saves it anyway).
    pub fn is_checkpoint_point(&self, episode: u64, env_steps: u64) -> bool {
        let k = self.checkpoint_every_episodes;
        k > 0 && episode.is_multiple_of(k) && !self.is_last(episode, env_steps)
    }

    /// How far the run is, in [0, 1]: by environment steps under an env-step budget, else by
    /// episodes (PPO's learning-rate annealing).
    pub fn progress(&self, episode: u64, env_steps: u64) -> f64 {
        match self.env_steps {
            Some(n) => env_steps as f64 / n.max(1) as f64,
            None => episode as f64 / self.episodes.max(1) as f64,
        }
        .min(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evaluation_and_checkpoint_points() {
        let t = TrainConfig {
            episodes: 10,
            eval_every_episodes: 4,
            checkpoint_every_episodes: 5,
            ..TrainConfig::default()
        };
        // 50 steps an episode: the env steps play no part in an episode budget.
        let evals: Vec<u64> = (1..=10).filter(|&e| t.is_eval_point(e, 50 * (e - 1), 50 * e)).collect();
        let checkpoints: Vec<u64> = (1..=10).filter(|&e| t.is_checkpoint_point(e, 50 * e)).collect();
        assert_eq!((evals, checkpoints), (vec![4, 8, 10], vec![5]));
        assert!((1..10).all(|e| !t.is_last(e, 1 << 40)) && t.is_last(10, 0));
        let never = TrainConfig { eval_every_episodes: 0, checkpoint_every_episodes: 0, ..t.clone() };
        assert!((1..=10).all(|e| !never.is_eval_point(e, 0, 1) && !never.is_checkpoint_point(e, 1)));
        assert_eq!((t.progress(5, 0), t.progress(10, 0)), (0.5, 1.0));
    }

    #[test]
    fn an_env_step_budget_ends_the_run_and_places_evaluations_by_env_steps() {
        // Episodes of 30, 30, 45, 50, 50, 40 steps: the run ends with the one that reaches 200.
        let ends = [30u64, 60, 105, 155, 205, 245];
        let t = TrainConfig {
            episodes: 3,
            env_steps: Some(200),
            eval_every_env_steps: Some(50),
            checkpoint_every_episodes: 2,
            ..TrainConfig::default()
        };
        t.validate().unwrap();
        let last = (1..=6).find(|&e| t.is_last(e, ends[e as usize - 1])).unwrap();
        assert_eq!(last, 5, "not by the episode count (3): by the 200th step");
        let before = |e: u64| if e == 1 { 0 } else { ends[e as usize - 2] };
        let evals: Vec<u64> =
            (1..=5).filter(|&e| t.is_eval_point(e, before(e), ends[e as usize - 1])).collect();
        // 50 passed in episode 2, 100 in 3, 150 in 4, 200 in 5 (also the last).
        assert_eq!(evals, vec![2, 3, 4, 5]);
        let checkpoints: Vec<u64> =
            (1..=5).filter(|&e| t.is_checkpoint_point(e, ends[e as usize - 1])).collect();
        assert_eq!(checkpoints, vec![2, 4]);
        assert_eq!((t.progress(1, 100), t.progress(9, 300)), (0.5, 1.0));
        // Evaluations by episodes under an env-step budget: every 2, and the last.
        let by_episodes = TrainConfig { eval_every_env_steps: None, eval_every_episodes: 2, ..t.clone() };
        let evals: Vec<u64> =
            (1..=5).filter(|&e| by_episodes.is_eval_point(e, before(e), ends[e as usize - 1])).collect();
        assert_eq!(evals, vec![2, 4, 5]);
    }

    #[test]
    fn bad_env_step_budgets_are_refused_naming_the_field() {
        for (cfg, field) in [
            (TrainConfig { env_steps: Some(0), ..TrainConfig::default() }, "train.env_steps"),
            (TrainConfig { env_steps: Some(MAX_ENV_STEPS + 1), ..TrainConfig::default() }, "train.env_steps"),
            (
                TrainConfig { eval_every_env_steps: Some(0), ..TrainConfig::default() },
                "train.eval_every_env_steps",
            ),
            (
                TrainConfig {
                    eval_every_env_steps: Some(100),
                    eval_trials: 0,
                    eval_every_episodes: 0,
                    ..TrainConfig::default()
                },
                "train.eval_trials",
            ),
        ] {
            let err = cfg.validate().unwrap_err().to_string();
            assert!(err.contains(&format!("`{field}`")), "{err}");
        }
    }
}
