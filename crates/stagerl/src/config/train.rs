//! The training schedule (the `[train]` section): the seed, how many episodes, when to evaluate
//! and when to checkpoint; the trainer asks it at every episode's end.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The largest evaluation asked for at once (its per-trial records are kept in memory).
pub const MAX_EVAL_TRIALS: u32 = 10_000_000;

/// Training settings (the `[train]` section).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The run's seed: environment targets, initial weights, exploration, replay sampling.
    pub seed: u64,
    /// Training episodes (paper: 10000). Default 5000: DDPG + SAR reaches 99 % by then, SAC + SAR
    /// by about 1500.
    pub episodes: u64,
    /// Evaluate the deterministic policy every this many episodes; 0 disables.
    pub eval_every_episodes: u64,
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
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            seed: 0,
            episodes: 5000,
            eval_every_episodes: 250,
            eval_trials: 100,
            eval_seed: 1_000_003,
            checkpoint_every_episodes: 250,
            obstacles_in_path: 0.0,
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
        if self.eval_every_episodes > 0 && self.eval_trials == 0 {
            return Err(Error::config(
                "train.eval_trials",
                0,
                "an integer >= 1 (or set train.eval_every_episodes = 0 to disable evaluation)",
            ));
        }
        Ok(())
    }
}

impl TrainConfig {
    /// The run evaluates after this (1-based) episode: every `eval_every_episodes`, and after
    /// the last one.
    pub fn is_eval_point(&self, episode: u64) -> bool {
        let every = self.eval_every_episodes;
        every > 0 && (episode.is_multiple_of(every) || episode == self.episodes)
    }

    /// The run writes `latest.safetensors` after this episode: every
    /// `checkpoint_every_episodes`, but the last (the end of the run saves it anyway).
    pub fn is_checkpoint_point(&self, episode: u64) -> bool {
        let k = self.checkpoint_every_episodes;
        k > 0 && episode.is_multiple_of(k) && episode < self.episodes
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
        let evals: Vec<u64> = (1..=10).filter(|&e| t.is_eval_point(e)).collect();
        let checkpoints: Vec<u64> = (1..=10).filter(|&e| t.is_checkpoint_point(e)).collect();
        assert_eq!((evals, checkpoints), (vec![4, 8, 10], vec![5]));
        let never = TrainConfig { eval_every_episodes: 0, checkpoint_every_episodes: 0, ..t };
        assert!((1..=10).all(|e| !never.is_eval_point(e) && !never.is_checkpoint_point(e)));
    }
}
