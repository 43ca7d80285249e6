//! `agent.her`: the settings of hindsight experience replay for the off-policy agents. The
//! relabelling itself is part of the off-policy training loop ([`crate::train::her`]): it needs
//! the task's step outcome, and the agents see arrays only.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// How substituted goals are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum HerStrategy {
    /// A position reached at this step or later in the episode.
    Future,
    /// The position reached at the episode's last step.
    Final,
    /// A position reached at any step of the episode.
    Episode,
}

impl HerStrategy {
    pub const ALL: [HerStrategy; 3] = [HerStrategy::Future, HerStrategy::Final, HerStrategy::Episode];

    pub fn name(self) -> &'static str {
        match self {
            HerStrategy::Future => "future",
            HerStrategy::Final => "final",
            HerStrategy::Episode => "episode",
        }
    }
}

impl std::str::FromStr for HerStrategy {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        HerStrategy::ALL
            .into_iter()
            .find(|h| h.name() == s)
            .ok_or_else(|| Error::config("agent.her.strategy", s, "one of future, final, episode"))
    }
}

/// Largest `agent.her.k`.
pub const MAX_HER_K: u32 = 64;

/// `agent.her`: hindsight relabelling of the off-policy agents' replay.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct HerConfig {
    pub strategy: HerStrategy,
    /// Substituted goals per transition for `future` and `episode` (`final` stores one): the
    /// replay holds `k` relabelled transitions for each real one. 4 as in the HER paper and
    /// Stable-Baselines3's `n_sampled_goal`.
    pub k: u32,
}

impl Default for HerConfig {
    fn default() -> Self {
        HerConfig { strategy: HerStrategy::Future, k: 4 }
    }
}

impl HerConfig {
    /// Check `k`; the error names the field.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_HER_K).contains(&self.k) {
            return Err(Error::config("agent.her.k", self.k, format!("an integer in 1..={MAX_HER_K}")));
        }
        Ok(())
    }

    /// Relabelled transitions stored per real one.
    pub fn copies(&self) -> usize {
        match self.strategy {
            HerStrategy::Final => 1,
            HerStrategy::Future | HerStrategy::Episode => self.k as usize,
        }
    }
}
