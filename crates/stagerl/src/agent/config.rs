//! Agent hyper-parameters: the `[agent]` section holds what every algorithm shares, and
//! `[agent.ddpg]`, `[agent.td3]`, `[agent.sac]`, `[agent.ppo]` what is each algorithm's own
//! (each defined, with its defaults and its checks, in that algorithm's file). A run's config
//! holds at most its own algorithm's section (absent: that algorithm's defaults); a sweep preset
//! may hold one for each algorithm of its sweep, and each run keeps only its own
//! ([`AgentConfig::for_algo`]).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

use super::crossq::CrossqConfig;
use super::ddpg::DdpgConfig;
use super::obs_norm::ObsNormConfig;
use super::ppo::PpoConfig;
use super::sac::SacConfig;
use super::td3::Td3Config;
use crate::agent::HerConfig;
use crate::base::validate::{at_least_one, non_negative, positive};
use crate::{Error, Result};

/// The learning algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Algo {
    /// Deep Deterministic Policy Gradient (Lillicrap et al. 2015), the paper's first method.
    Ddpg,
    /// Twin Delayed DDPG (Fujimoto et al. 2018).
    Td3,
    /// Soft Actor-Critic with automatic entropy tuning (Haarnoja et al. 2018), the paper's second.
    Sac,
    /// Proximal Policy Optimization (Schulman et al. 2017), on-policy, as CleanRL's
    /// `ppo_continuous_action`.
    Ppo,
    /// CrossQ (Bhatt et al., ICLR 2024), as sbx's: SAC without target networks, with batch
    /// renormalisation and a joint forward pass of the current and next state-actions.
    Crossq,
}

impl Algo {
    pub const ALL: [Algo; 5] = [Algo::Ddpg, Algo::Td3, Algo::Sac, Algo::Ppo, Algo::Crossq];
    pub fn name(self) -> &'static str {
        match self {
            Algo::Ddpg => "ddpg",
            Algo::Td3 => "td3",
            Algo::Sac => "sac",
            Algo::Ppo => "ppo",
            Algo::Crossq => "crossq",
        }
    }

    /// Learns from a replay buffer (DDPG, TD3, SAC, CrossQ), not from fresh rollouts (PPO).
    pub fn is_off_policy(self) -> bool {
        self != Algo::Ppo
    }
}

impl fmt::Display for Algo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Algo {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Algo::ALL
            .into_iter()
            .find(|a| a.name() == s)
            .ok_or_else(|| Error::config("agent.algo", s, "one of ddpg, td3, sac, ppo, crossq"))
    }
}

/// Exploration noise of DDPG and TD3.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum NoiseKind {
    /// Independent N(0, sigma^2) per step and joint.
    Gaussian,
    /// Ornstein-Uhlenbeck process, reset every episode.
    Ou,
}

/// Largest replay capacity, transitions (the paper's 10000 episodes make at most 500000).
pub const MAX_BUFFER_SIZE: usize = 100_000_000;

/// Largest `batch_size x widest hidden layer`: 2^28 f32 values, 1 GiB per activation matrix.
pub const MAX_BATCH_VALUES: usize = 1 << 28;

/// Hyper-parameters of the agents: the `[agent]` section.
#[derive(Clone, Debug, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct AgentConfig {
    pub algo: Algo,
    /// Hidden layer widths of every network (actor and critics).
    pub hidden: Vec<usize>,
    /// Actor learning rate; unset: the algorithm's default ([`AgentConfig::actor_lr`]).
    pub actor_lr: Option<f64>,
    /// Critic learning rate; unset: the algorithm's default ([`AgentConfig::critic_lr`]).
    pub critic_lr: Option<f64>,
    /// Discount factor. Default 0.95, measured on the reaching task (hidden 64, SAR): with 0.99
    /// DDPG peaked at 73 % success and collapsed, with 0.95 it reached 99.0 %; SAC went from
    /// 95.8 % to 99.8 % (500 trials). A successful episode lasts about 6 steps, so a 20-step
    /// horizon loses nothing.
    pub gamma: f64,
    /// Polyak coefficient of the target networks.
    pub tau: f64,
    /// Transitions per update; `batch_size x widest hidden layer` at most [`MAX_BATCH_VALUES`].
    pub batch_size: usize,
    /// Replay capacity, transitions, at most [`MAX_BUFFER_SIZE`] (preallocated).
    pub buffer_size: usize,
    /// Environment steps of uniform random actions before learning starts.
    pub learning_starts: u64,
    /// Gradient updates per environment step (update-to-data ratio).
    pub updates_per_step: u32,
    /// Clip each network's gradient to this global L2 norm; 0 disables.
    pub max_grad_norm: f64,
    /// `[agent.ddpg]`; unset: [`DdpgConfig::default`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ddpg: Option<DdpgConfig>,
    /// `[agent.td3]`; unset: [`Td3Config::default`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub td3: Option<Td3Config>,
    /// `[agent.sac]`; unset: [`SacConfig::default`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sac: Option<SacConfig>,
    /// `[agent.ppo]`; unset: [`PpoConfig::default`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ppo: Option<PpoConfig>,
    /// `[agent.crossq]`; unset: [`CrossqConfig::default`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crossq: Option<CrossqConfig>,
    /// `agent.her = { strategy = "future" | "final" | "episode", k = 4 }`: hindsight experience
    /// replay ([`crate::train::her`]); unset: off (the paper's agents).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub her: Option<HerConfig>,
    /// `agent.norm_obs = { clip = 10.0 }`: running observation normalisation of the off-policy
    /// agents (DDPG, TD3, SAC; PPO's is `agent.ppo.norm_obs`), as Stable-Baselines3's
    /// `VecNormalize` with an off-policy algorithm ([`crate::agent::obs_norm`]); unset: off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub norm_obs: Option<ObsNormConfig>,
}

impl Default for AgentConfig {
    fn default() -> Self {
        AgentConfig {
            algo: Algo::Sac,
            hidden: vec![64, 64],
            actor_lr: None,
            critic_lr: None,
            gamma: 0.95,
            tau: 0.005,
            batch_size: 256,
            buffer_size: 1_000_000,
            learning_starts: 1000,
            updates_per_step: 1,
            max_grad_norm: 0.0,
            ddpg: None,
            td3: None,
            sac: None,
            ppo: None,
            crossq: None,
            her: None,
            norm_obs: None,
        }
    }
}

impl PartialEq for AgentConfig {
    /// Equal when they describe the same agents: an absent section equals its defaults. (Every
    /// field is compared; a new field must be added here.)
    fn eq(&self, other: &Self) -> bool {
        let shared = |c: &Self| {
            (
                c.algo,
                c.hidden.clone(),
                (c.actor_lr, c.critic_lr, c.gamma, c.tau),
                (c.batch_size, c.buffer_size, c.learning_starts, c.updates_per_step, c.max_grad_norm),
            )
        };
        shared(self) == shared(other)
            && (self.ddpg(), self.td3(), self.sac(), self.ppo())
                == (other.ddpg(), other.td3(), other.sac(), other.ppo())
            && self.crossq() == other.crossq()
            && self.her == other.her
            && self.norm_obs == other.norm_obs
    }
}

/// Keys that moved from `[agent]` into an algorithm's section, and where they belong.
const MOVED_KEYS: [(&str, &str); 21] = [
    ("noise", "[agent.ddpg] or [agent.td3]"),
    ("noise_sigma", "[agent.ddpg] or [agent.td3]"),
    ("ou_theta", "[agent.ddpg] or [agent.td3]"),
    ("policy_delay", "[agent.td3], [agent.sac] or [agent.crossq]"),
    ("target_noise", "[agent.td3]"),
    ("target_noise_clip", "[agent.td3]"),
    ("alpha_lr", "[agent.sac]"),
    ("init_alpha", "[agent.sac]"),
    ("target_entropy_per_dim", "[agent.sac]"),
    ("fixed_alpha", "[agent.sac]"),
    ("num_envs", "[agent.ppo]"),
    ("num_steps", "[agent.ppo]"),
    ("update_epochs", "[agent.ppo]"),
    ("num_minibatches", "[agent.ppo]"),
    ("gae_lambda", "[agent.ppo]"),
    ("clip_coef", "[agent.ppo]"),
    ("clip_vloss", "[agent.ppo]"),
    ("ent_coef", "[agent.ppo]"),
    ("vf_coef", "[agent.ppo]"),
    ("norm_adv", "[agent.ppo]"),
    ("anneal_lr", "[agent.ppo]"),
];

impl AgentConfig {
    /// The default config of `algo`.
    pub fn new(algo: Algo) -> AgentConfig {
        AgentConfig { algo, ..AgentConfig::default() }
    }

    /// The actor's learning rate: as set, else 1e-3 for SAC and CrossQ (sbx's) and 3e-4 for DDPG and TD3 (measured
    /// on the reaching task: SAC at 3e-4 learns about twice as slowly; DDPG at 1e-3 diverges)
    /// and PPO (CleanRL's).
    pub fn actor_lr(&self) -> f64 {
        self.actor_lr.unwrap_or(match self.algo {
            Algo::Sac | Algo::Crossq => 1e-3,
            Algo::Ddpg | Algo::Td3 | Algo::Ppo => 3e-4,
        })
    }

    /// The critics' learning rate: as set, else as [`AgentConfig::actor_lr`]'s default.
    pub fn critic_lr(&self) -> f64 {
        self.critic_lr.unwrap_or(match self.algo {
            Algo::Sac | Algo::Crossq => 1e-3,
            Algo::Ddpg | Algo::Td3 | Algo::Ppo => 3e-4,
        })
    }

    /// DDPG's settings: `[agent.ddpg]`, else its defaults.
    pub fn ddpg(&self) -> DdpgConfig {
        self.ddpg.unwrap_or_default()
    }

    /// TD3's settings: `[agent.td3]`, else its defaults.
    pub fn td3(&self) -> Td3Config {
        self.td3.unwrap_or_default()
    }

    /// SAC's settings: `[agent.sac]`, else its defaults.
    pub fn sac(&self) -> SacConfig {
        self.sac.unwrap_or_default()
    }

    /// PPO's settings: `[agent.ppo]`, else its defaults.
    pub fn ppo(&self) -> PpoConfig {
        self.ppo.unwrap_or_default()
    }

    /// CrossQ's settings: `[agent.crossq]`, else its defaults.
    pub fn crossq(&self) -> CrossqConfig {
        self.crossq.clone().unwrap_or_default()
    }

    /// The config of one run of `algo` from a preset's: only that algorithm's section is kept.
    pub fn for_algo(&self, algo: Algo) -> AgentConfig {
        let mut c =
            AgentConfig { algo, ddpg: None, td3: None, sac: None, ppo: None, crossq: None, ..self.clone() };
        match algo {
            Algo::Ddpg => c.ddpg = self.ddpg,
            Algo::Td3 => c.td3 = self.td3,
            Algo::Sac => c.sac = self.sac,
            Algo::Crossq => c.crossq = self.crossq.clone(),
            Algo::Ppo => {
                c.ppo = self.ppo;
                // Relabelling needs a replay buffer: a preset's `[agent.her]` is for its
                // off-policy agents, and so is its `agent.norm_obs` (PPO's is its own).
                c.her = None;
                c.norm_obs = None;
            }
        }
        c
    }

    /// The config written out (a run's `config.toml`, `stagerl config`): the run's algorithm's
    /// section with every value, no other.
    pub fn resolved(&self) -> AgentConfig {
        let mut c = self.for_algo(self.algo);
        match self.algo {
            Algo::Ddpg => c.ddpg = Some(self.ddpg()),
            Algo::Td3 => c.td3 = Some(self.td3()),
            Algo::Sac => c.sac = Some(self.sac()),
            Algo::Ppo => c.ppo = Some(self.ppo()),
            Algo::Crossq => c.crossq = Some(self.crossq()),
        }
        c
    }

    /// The algorithms whose sections are set.
    pub fn sections(&self) -> Vec<Algo> {
        let set = [
            self.ddpg.is_some(),
            self.td3.is_some(),
            self.sac.is_some(),
            self.ppo.is_some(),
            self.crossq.is_some(),
        ];
        Algo::ALL.into_iter().zip(set).filter(|(_, s)| *s).map(|(a, _)| a).collect()
    }

    /// For a parse error of a config file: when its `[agent]` table (`agent`) holds a key that
    /// belongs in an algorithm's section, an error saying where it belongs.
    pub fn misplaced_key(agent: &toml::Table) -> Option<String> {
        let (key, home) = MOVED_KEYS.iter().find(|(k, _)| agent.contains_key(*k))?;
        Some(format!(
            "unknown field `{key}` in [agent] (= {}): it is an algorithm's own setting and belongs in {home}",
            agent[*key]
        ))
    }

    /// Check every value and that no section of another algorithm than `algo` is set; the error
    /// names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        self.validate_values()?;
        if self.algo == Algo::Crossq {
            // Its defaults too: the joint pass of its (wide) critics is checked against the batch.
            self.crossq().validate(self.batch_size)?;
        }
        if self.algo == Algo::Ppo && self.her.is_some() {
            return Err(Error::config(
                "agent.her",
                "a hindsight relabelling setting",
                "none with agent.algo = \"ppo\": relabelling rewrites a replay buffer, and PPO learns from fresh rollouts (use ddpg, td3 or sac)",
            ));
        }
        if self.algo == Algo::Ppo && self.norm_obs.is_some() {
            return Err(Error::config(
                "agent.norm_obs",
                "an observation normalisation setting",
                "none with agent.algo = \"ppo\": PPO's is agent.ppo.norm_obs (agent.norm_obs is the off-policy agents')",
            ));
        }
        match self.sections().into_iter().find(|&a| a != self.algo) {
            Some(other) => Err(Error::config(
                format!("agent.{other}"),
                format!("a [agent.{other}] section"),
                format!(
                    "only [agent.{algo}], the section of this run's algorithm (agent.algo = \"{algo}\"): \
                     remove [agent.{other}] or run {other}",
                    algo = self.algo
                ),
            )),
            None => Ok(()),
        }
    }

    /// Check every value, of the shared settings and of each section set (of any algorithm).
    pub fn validate_values(&self) -> Result<()> {
        if self.hidden.is_empty() || self.hidden.iter().any(|&h| h == 0 || h > 16384) {
            return Err(Error::config(
                "agent.hidden",
                format!("{:?}", self.hidden),
                "one or more layer widths, each in 1..=16384",
            ));
        }
        positive("agent.actor_lr", self.actor_lr())?;
        positive("agent.critic_lr", self.critic_lr())?;
        if !(self.gamma.is_finite() && (0.0..=1.0).contains(&self.gamma)) {
            return Err(Error::config("agent.gamma", self.gamma, "a number in [0, 1]"));
        }
        if !(self.tau.is_finite() && self.tau > 0.0 && self.tau <= 1.0) {
            return Err(Error::config("agent.tau", self.tau, "a number in (0, 1]"));
        }
        // Both are preallocated: an absurd size must be refused here, not abort the process when
        // the allocation fails (or overflow computing its length).
        let widest = self.hidden.iter().copied().max().unwrap_or(1);
        if self.batch_size == 0 || self.batch_size.saturating_mul(widest) > MAX_BATCH_VALUES {
            return Err(Error::config(
                "agent.batch_size",
                self.batch_size,
                format!(
                    "an integer >= 1 with batch_size x widest hidden layer ({widest}) <= {MAX_BATCH_VALUES} \
                     (one activation matrix of 1 GiB)"
                ),
            ));
        }
        if self.buffer_size == 0 || self.buffer_size > MAX_BUFFER_SIZE {
            return Err(Error::config(
                "agent.buffer_size",
                self.buffer_size,
                format!("an integer in 1..={MAX_BUFFER_SIZE} (transitions; the buffer is preallocated)"),
            ));
        }
        at_least_one("agent.updates_per_step", self.updates_per_step.into())?;
        non_negative("agent.max_grad_norm", self.max_grad_norm)?;
        if let Some(d) = &self.ddpg {
            d.validate()?;
        }
        if let Some(t) = &self.td3 {
            t.validate()?;
        }
        if let Some(s) = &self.sac {
            s.validate()?;
        }
        if let Some(p) = &self.ppo {
            p.validate()?;
        }
        if let Some(c) = &self.crossq {
            c.validate(self.batch_size)?;
        }
        if let Some(h) = &self.her {
            h.validate()?;
        }
        if let Some(n) = &self.norm_obs {
            n.validate("agent.norm_obs")?;
        }
        Ok(())
    }
}

/// The exploration noise of `[agent.ddpg]` or `[agent.td3]` (`section`).
pub(super) fn validate_noise(section: &str, sigma: f64, theta: f64) -> Result<()> {
    non_negative(&format!("{section}.noise_sigma"), sigma)?;
    non_negative(&format!("{section}.ou_theta"), theta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::{SacConfig, Td3Config};

    #[test]
    fn an_absent_section_equals_its_defaults_and_only_the_runs_own_is_allowed() {
        let td3 = AgentConfig::new(Algo::Td3);
        let explicit = AgentConfig { td3: Some(Td3Config::default()), ..td3.clone() };
        assert_eq!(td3, explicit);
        let delayed =
            AgentConfig { td3: Some(Td3Config { policy_delay: 3, ..Td3Config::default() }), ..td3.clone() };
        assert_ne!(td3, delayed);
        assert_ne!(td3, AgentConfig { gamma: 0.9, ..td3.clone() });
        assert_ne!(td3, AgentConfig::new(Algo::Ddpg));
        delayed.validate().unwrap();
        // A SAC config with TD3's section is refused, naming both.
        let sac = AgentConfig { algo: Algo::Sac, ..delayed.clone() };
        let e = sac.validate().unwrap_err().to_string();
        assert!(
            e.contains("`agent.td3`") && e.contains("[agent.sac]") && e.contains("agent.algo = \"sac\""),
            "{e}"
        );
        sac.validate_values().unwrap();
        // A run of a preset keeps its own section and drops the others.
        let preset =
            AgentConfig { sac: Some(SacConfig { fixed_alpha: true, ..SacConfig::default() }), ..sac };
        let run = preset.for_algo(Algo::Td3);
        assert_eq!((run.algo, run.sections()), (Algo::Td3, vec![Algo::Td3]));
        assert_eq!(run.td3().policy_delay, 3);
        let run = preset.for_algo(Algo::Ddpg);
        assert_eq!(run.sections(), vec![]);
        assert_eq!(run.resolved().sections(), vec![Algo::Ddpg]);
    }

    #[test]
    fn an_ensemble_is_checked_and_its_actor_objective_follows_redq() {
        let sac = |n, m, q| SacConfig { n_critics: n, critic_subset: m, actor_q: q, ..SacConfig::default() };
        for (bad, field, allowed) in [
            (sac(0, None, None), "agent.sac.n_critics", "1..=20"),
            (sac(21, None, None), "agent.sac.n_critics", "1..=20"),
            (sac(10, Some(0), None), "agent.sac.critic_subset", "1..=10"),
            (sac(2, Some(3), None), "agent.sac.critic_subset", "at most agent.sac.n_critics = 2"),
            (SacConfig { critic_dropout: 1.0, ..SacConfig::default() }, "agent.sac.critic_dropout", "[0, 1)"),
            (
                SacConfig { critic_dropout: -0.1, ..SacConfig::default() },
                "agent.sac.critic_dropout",
                "[0, 1)",
            ),
            (
                SacConfig { critic_dropout: f64::NAN, ..SacConfig::default() },
                "agent.sac.critic_dropout",
                "[0, 1)",
            ),
        ] {
            let e = bad.validate().unwrap_err().to_string();
            assert!(e.contains(field) && e.contains(allowed), "{e}");
        }
        assert_eq!(SacConfig::default().actor_q(), crate::agent::ActorQ::Min);
        assert_eq!(sac(10, Some(2), None).actor_q(), crate::agent::ActorQ::Mean);
        assert_eq!(sac(10, None, None).actor_q(), crate::agent::ActorQ::Min);
        assert_eq!(sac(10, Some(10), None).actor_q(), crate::agent::ActorQ::Min);
        assert_eq!(sac(2, None, Some(crate::agent::ActorQ::Mean)).actor_q(), crate::agent::ActorQ::Mean);
        // The defaults are left out of a written config (runs from before read the same).
        let written = toml::to_string(&SacConfig::default()).unwrap();
        assert!(!written.contains("n_critics") && !written.contains("critic_"), "{written}");
        assert_eq!(SacConfig::default().critic_norm(), None);
        let back: SacConfig = toml::from_str("n_critics = 10\ncritic_subset = 2\n").unwrap();
        assert_eq!((back.n_critics, back.subset()), (10, 2));
        assert!(toml::from_str::<SacConfig>("actor_q = \"max\"\n").unwrap_err().to_string().contains("max"));
    }

    #[test]
    fn a_moved_key_says_where_it_belongs() {
        for (key, home) in MOVED_KEYS {
            let table: toml::Table = toml::from_str(&format!("{key} = 1\n")).unwrap();
            let m = AgentConfig::misplaced_key(&table).unwrap();
            assert!(m.contains(&format!("`{key}` in [agent]")) && m.contains(home), "{m}");
        }
        let shared: toml::Table = toml::from_str("gamma = 0.9\nhidden = [8]\n").unwrap();
        assert_eq!(AgentConfig::misplaced_key(&shared), None);
    }
}
