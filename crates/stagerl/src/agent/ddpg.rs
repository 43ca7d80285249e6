//! Deep Deterministic Policy Gradient (Lillicrap et al. 2015), the paper's first method, as in
//! CleanRL; written, as in Stable-Baselines3, as [TD3](super::td3) with one critic, no policy
//! delay and no target policy smoothing. The update is [`Td3`]'s.
//!
//! Networks: a deterministic actor `mu: obs -> act` (tanh output), a critic `Q: [obs | act] -> 1`,
//! and Polyak-averaged targets of both.
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. critic target `y = r + gamma (1 - d) Q'(s', mu'(s'))`; the critic minimises
//!    `mean (Q(s, a) - y)^2`;
//! 2. the actor maximises `mean Q(s, mu(s))`: its gradient is dQ/da back-propagated through mu;
//! 3. targets `theta' <- (1 - tau) theta' + tau theta`.
//!
//! Exploration: Gaussian or Ornstein-Uhlenbeck noise added to `mu(s)`, clipped to [-1, 1].
//!
//! Its own settings: `[agent.ddpg]`, [`DdpgConfig`] (exploration).

use serde::{Deserialize, Serialize};

use super::config::validate_noise;
use super::td3::{Family, Td3};
use super::{AgentConfig, Algo, NoiseKind};
use crate::Result;

/// `[agent.ddpg]`: DDPG's exploration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DdpgConfig {
    /// Exploration noise kind.
    pub noise: NoiseKind,
    /// Exploration noise scale sigma (action units, actions in [-1, 1]).
    pub noise_sigma: f64,
    /// Ornstein-Uhlenbeck mean-reversion rate theta (per step).
    pub ou_theta: f64,
}

impl Default for DdpgConfig {
    fn default() -> Self {
        DdpgConfig { noise: NoiseKind::Gaussian, noise_sigma: 0.1, ou_theta: 0.15 }
    }
}

impl DdpgConfig {
    /// Check every value; the error names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        validate_noise("agent.ddpg", self.noise_sigma, self.ou_theta)
    }
}

/// DDPG's place in the TD3 family. Its critic keeps DDPG's checkpoint names (`critic`,
/// `critic_target`, `critic_opt`).
pub fn family(cfg: &AgentConfig) -> Family {
    let d = cfg.ddpg();
    Family {
        algo: Algo::Ddpg,
        critics: &[["critic", "critic_target", "critic_opt"]],
        policy_delay: 1,
        target_smoothing: None,
        noise: (d.noise, d.noise_sigma, d.ou_theta),
        salts: (0xDD96, 0xDD961),
    }
}

/// DDPG as the config describes it.
pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Td3 {
    Td3::with_family(family(cfg), cfg, obs_dim, act_dim, seed)
}
