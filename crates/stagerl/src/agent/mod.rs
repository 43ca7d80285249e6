//! The agents. Each algorithm reads top to bottom in its own file, its `[agent.<algo>]` section
//! (defaults and checks) included: the off-policy `td3.rs` ([`Td3`], with DDPG, `ddpg.rs`, as
//! its one-critic case, as in Stable-Baselines3), `sac.rs` ([`Sac`]) and `crossq.rs`
//! ([`Crossq`]: no target networks, batch renormalisation), and the on-policy `ppo.rs`
//! ([`Ppo`]). What they share lives here once: the [`Agent`] verbs, the one list of
//! learned parts that drives saving, loading and the non-finite guard, the shared `[agent]`
//! settings ([`AgentConfig`]), exploration noise, and the critic ensemble of the off-policy
//! agents (`critics.rs`: n critics with their targets, optimisers and buffers). The replay
//! buffer and the training loop are in [`crate::agent::replay`] and [`crate::train`].

mod config;
mod critics;
mod crossq;
mod ddpg;
mod her_config;
pub mod noise;
pub mod obs_norm;
mod parts;
mod ppo;
pub mod replay;
mod sac;
mod td3;

pub use config::{AgentConfig, Algo, NoiseKind, MAX_BATCH_VALUES, MAX_BUFFER_SIZE};
pub use crossq::{Crossq, CrossqConfig, MAX_CROSSQ_CRITICS};
pub use ddpg::DdpgConfig;
pub use her_config::{HerConfig, HerStrategy, MAX_HER_K};
pub use parts::Learned;
pub use ppo::{Ppo, PpoConfig, Rollout};
pub use sac::{ActorLogStd, ActorQ, Sac, SacConfig, MAX_CRITICS};
pub use td3::{Family, Td3, Td3Config};

use crate::agent::replay::Batch;
use crate::io::checkpoint::Checkpoint;
use crate::nn::{Adam, Mlp};
use crate::Result;

/// What one gradient update measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Mean squared TD error of the critic(s).
    pub critic_loss: f64,
    /// Actor loss, when the actor was updated in this step.
    pub actor_loss: Option<f64>,
    /// SAC's entropy coefficient.
    pub alpha: Option<f64>,
    /// SAC's policy entropy estimate, -mean log pi(a|s).
    pub entropy: Option<f64>,
}

/// The verbs every agent offers. Saving, loading and the non-finite check are derived from the
/// agent's one list of learned parts ([`Learned`]).
pub trait Agent: Send + Learned {
    /// Which algorithm.
    fn algo(&self) -> Algo;
    /// Observation length.
    fn obs_dim(&self) -> usize {
        self.actor().in_features()
    }
    /// Action length.
    fn act_dim(&self) -> usize;
    /// The actor network (its output is turned into the deterministic action by the
    /// algorithm's rule: see [`crate::run::policy`]).
    fn actor(&self) -> &Mlp<f32>;
    /// Exploration action for one observation (training), in [-1, 1].
    fn act(&mut self, obs: &[f32], action: &mut [f32]);
    /// Deterministic action for one observation (evaluation, deployment), in [-1, 1].
    fn predict(&mut self, obs: &[f32], action: &mut [f32]);
    /// The running observation normalisation the actor's input goes through (PPO with
    /// `agent.ppo.norm_obs`, DDPG, TD3 and SAC with `agent.norm_obs`), if any: [`Agent::predict`] applies it; an export must too.
    fn obs_norm(&self) -> Option<&obs_norm::ObsNorm> {
        None
    }
    /// Called at the start of every training episode (resets temporally correlated noise).
    fn begin_episode(&mut self) {}

    /// Write every network, target network, optimiser state and random state to `ck`.
    fn save(&self, ck: &mut Checkpoint) {
        self.parts(&mut |name, part| part.save(ck, name));
    }

    /// Restore what [`Agent::save`] wrote; shapes must match this agent's.
    fn load(&mut self, ck: &Checkpoint) -> Result<()> {
        let mut result = Ok(());
        self.parts_mut(&mut |name, part| {
            if result.is_ok() {
                result = part.load(ck, name);
            }
        });
        result
    }

    /// The first non-finite parameter or gradient, described (network, tensor, index).
    fn first_non_finite(&self) -> Option<String> {
        let mut found = None;
        self.parts(&mut |name, part| {
            if found.is_none() {
                found = part.first_non_finite(name);
            }
        });
        found
    }
}

/// An off-policy agent: it learns from batches sampled from a replay buffer.
pub trait OffPolicy: Agent {
    /// An observation collected in training (`agent.norm_obs`: merged into the running
    /// statistics before the agent, or the warm-up, acts on it; otherwise nothing).
    fn observe(&mut self, obs: &[f32]);
    /// One gradient update on a sampled batch.
    fn update(&mut self, batch: &Batch) -> UpdateStats;
}

/// An agent with the kind of learning loop it needs, known from its construction: the
/// training loop picks its collector from it (`crate::train`), never at run time.
pub enum Learner {
    /// Learns from batches sampled from a replay buffer (DDPG, TD3, SAC).
    OffPolicy(Box<dyn OffPolicy>),
    /// Learns from fresh rollouts (PPO).
    OnPolicy(Box<Ppo>),
}

impl Learner {
    /// The agent, for what every agent does (act, evaluate, save, load).
    pub fn into_agent(self) -> Box<dyn Agent> {
        match self {
            Learner::OffPolicy(a) => a,
            Learner::OnPolicy(a) => a,
        }
    }
}

/// Build the agent the config asks for, with its kind of learning. `seed` fixes its initial
/// weights and its noise.
pub fn build_learner(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Result<Learner> {
    cfg.validate()?;
    Ok(learner_of(cfg, obs_dim, act_dim, seed))
}

/// [`build_learner`] of a section checked already (by [`crate::config::Config::resolve`]).
pub(crate) fn learner_of(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Learner {
    match off_policy_of(cfg, obs_dim, act_dim, seed) {
        Some(agent) => Learner::OffPolicy(agent),
        None => Learner::OnPolicy(Box::new(Ppo::new(cfg, obs_dim, act_dim, seed))),
    }
}

/// The off-policy agent of a checked section; `None` for an on-policy algorithm.
fn off_policy_of(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Option<Box<dyn OffPolicy>> {
    match cfg.algo {
        Algo::Ddpg => Some(Box::new(ddpg::new(cfg, obs_dim, act_dim, seed))),
        Algo::Td3 => Some(Box::new(Td3::new(cfg, obs_dim, act_dim, seed))),
        Algo::Sac => Some(Box::new(Sac::new(cfg, obs_dim, act_dim, seed))),
        Algo::Crossq => Some(Box::new(Crossq::new(cfg, obs_dim, act_dim, seed))),
        Algo::Ppo => None,
    }
}

/// Build the agent the config asks for. `seed` fixes its initial weights and its noise.
pub fn build(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Result<Box<dyn Agent>> {
    build_learner(cfg, obs_dim, act_dim, seed).map(Learner::into_agent)
}

/// Build the off-policy agent the config asks for (an error for PPO).
pub fn build_off_policy(
    cfg: &AgentConfig,
    obs_dim: usize,
    act_dim: usize,
    seed: u64,
) -> Result<Box<dyn OffPolicy>> {
    cfg.validate()?;
    off_policy_of(cfg, obs_dim, act_dim, seed).ok_or_else(|| {
        crate::Error::config("agent.algo", cfg.algo, "an off-policy algorithm here (ddpg, td3, sac, crossq)")
    })
}

/// Layer sizes `[input, hidden..., output]`.
pub(crate) fn sizes(input: usize, hidden: &[usize], output: usize) -> Vec<usize> {
    let mut s = Vec::with_capacity(hidden.len() + 2);
    s.push(input);
    s.extend_from_slice(hidden);
    s.push(output);
    s
}

/// Clip a gradient to a global L2 norm when `max_norm > 0`.
pub(crate) fn clip(grads: &mut [f32], max_norm: f64) {
    if max_norm > 0.0 {
        crate::nn::clip_grad_norm(grads, max_norm as f32);
    }
}

/// Apply one Adam step to a network from its accumulated gradients (clipped first if asked).
pub(crate) fn step(net: &mut Mlp<f32>, opt: &mut Adam<f32>, max_grad_norm: f64) {
    clip(net.grads_mut(), max_grad_norm);
    let (p, g) = net.params_and_grads();
    opt.step(p, g);
}

#[cfg(test)]
mod tests;
