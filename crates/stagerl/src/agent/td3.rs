//! Twin Delayed DDPG (Fujimoto et al. 2018), as in CleanRL, and the family it heads: as in
//! Stable-Baselines3, DDPG ([`super::ddpg`]) is this algorithm with one critic, no policy delay
//! and no target policy smoothing.
//!
//! Networks: a deterministic actor `mu: obs -> act` (tanh output), `n` critics
//! `Q_i: [obs | act] -> 1` (TD3: 2, DDPG: 1; a [`Critics`] ensemble) and Polyak-averaged targets
//! of all of them.
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. target action `a' = mu'(s')`, smoothed (TD3 only):
//!    `a' = clip(mu'(s') + clip(N(0, sigma~), -c, c), -1, 1)`;
//! 2. critic target `y = r + gamma (1 - d) min_i Q_i'(s', a')` (clipped double Q-learning; with
//!    one critic, DDPG's `Q'(s', a')`); each critic minimises `mean (Q_i(s, a) - y)^2`;
//! 3. every `policy_delay` updates (DDPG: every update): the actor maximises `mean Q_1(s, mu(s))`,
//!    its gradient dQ_1/da back-propagated through mu; then every target network is
//!    Polyak-averaged, `theta' <- (1 - tau) theta' + tau theta`.
//!
//! Exploration: Gaussian or Ornstein-Uhlenbeck noise added to `mu(s)`, clipped to [-1, 1].
//!
//! With `agent.norm_obs`, the actor, the critics and their targets read observations
//! normalised by running statistics ([`super::obs_norm`]: updated as observations are
//! collected, applied to each sampled batch).
//!
//! Its own settings: `[agent.td3]`, [`Td3Config`] (exploration, policy delay, target policy
//! smoothing).

use serde::{Deserialize, Serialize};

use super::config::validate_noise;
use super::critics::{self, Critics, TargetSide, TWIN};
use super::ddpg::DdpgConfig;
use super::noise::ActionNoise;
use super::obs_norm::{batch_inputs, one_input, ObsNorm, OffPolicyNorm};
use super::parts::learned_parts;
use super::{sizes, step, Agent, AgentConfig, Algo, NoiseKind, OffPolicy, UpdateStats};
use crate::agent::replay::Batch;
use crate::base::rng::Rng;
use crate::base::validate::{at_least_one, non_negative};
use crate::nn::{concat_cols, Activation, Adam, Mlp};
use crate::Result;

/// `[agent.td3]`: TD3's exploration, policy delay and target policy smoothing.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Td3Config {
    /// Exploration noise kind.
    pub noise: NoiseKind,
    /// Exploration noise scale sigma (action units, actions in [-1, 1]).
    pub noise_sigma: f64,
    /// Ornstein-Uhlenbeck mean-reversion rate theta (per step).
    pub ou_theta: f64,
    /// Actor and target updates every this many critic updates.
    pub policy_delay: u32,
    /// Target policy smoothing noise sigma (action units).
    pub target_noise: f64,
    /// Clip of the smoothing noise (action units).
    pub target_noise_clip: f64,
}

impl Default for Td3Config {
    fn default() -> Self {
        let DdpgConfig { noise, noise_sigma, ou_theta } = DdpgConfig::default();
        Td3Config { noise, noise_sigma, ou_theta, policy_delay: 2, target_noise: 0.2, target_noise_clip: 0.5 }
    }
}

impl Td3Config {
    /// Check every value; the error names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        validate_noise("agent.td3", self.noise_sigma, self.ou_theta)?;
        at_least_one("agent.td3.policy_delay", self.policy_delay.into())?;
        non_negative("agent.td3.target_noise", self.target_noise)?;
        non_negative("agent.td3.target_noise_clip", self.target_noise_clip)
    }
}

/// What sets a member of the TD3 family apart.
#[derive(Clone, Debug, PartialEq)]
pub struct Family {
    pub algo: Algo,
    /// Checkpoint names of each critic: `[critic, its target, its optimiser]`. Their number is
    /// the number of critics.
    pub critics: &'static [[&'static str; 3]],
    /// Actor and target updates every this many critic updates (>= 1).
    pub policy_delay: u32,
    /// Target policy smoothing `(sigma~, c)`, action units; `None`: `a' = mu'(s')`, and no
    /// random numbers are drawn for it.
    pub target_smoothing: Option<(f64, f64)>,
    /// Exploration noise: kind, sigma (action units), OU theta (per step).
    pub noise: (NoiseKind, f64, f64),
    /// Salts of the random streams of the initial weights and of the agent (noise, smoothing).
    pub salts: (u64, u64),
}

impl Family {
    /// TD3 with the config's settings.
    pub fn td3(cfg: &AgentConfig) -> Family {
        let t = cfg.td3();
        Family {
            algo: Algo::Td3,
            critics: TWIN,
            policy_delay: t.policy_delay,
            target_smoothing: Some((t.target_noise, t.target_noise_clip)),
            noise: (t.noise, t.noise_sigma, t.ou_theta),
            salts: (0x7D3, 0x7D31),
        }
    }
}

pub struct Td3 {
    family: Family,
    cfg: AgentConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp<f32>,
    /// The critics (named by `family.critics`), their targets and optimisers.
    critics: Critics,
    actor_target: Mlp<f32>,
    actor_opt: Adam<f32>,
    noise: ActionNoise,
    rng: Rng,
    updates: u64,
    /// `agent.norm_obs`: the running observation normalisation.
    norm: Option<OffPolicyNorm>,
    /// `[s | a]` rows for the critics (the target side has its own, `critic_in_next`).
    critic_in: Vec<f32>,
    critic_in_next: Vec<f32>,
    a_next: Vec<f32>,
    /// Standard normal draws of the target policy smoothing (`batch x act`).
    smoothing_noise: Vec<f64>,
    y: Vec<f32>,
}

impl Td3 {
    /// TD3 as the config describes it.
    pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Td3 {
        Td3::with_family(Family::td3(cfg), cfg, obs_dim, act_dim, seed)
    }

    /// A member of the family: networks drawn in the order actor, critic 1, ..., critic n.
    pub fn with_family(family: Family, cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Td3 {
        let mut init = Rng::derived(seed, family.salts.0);
        let actor =
            Mlp::new(&sizes(obs_dim, &cfg.hidden, act_dim), Activation::Relu, Activation::Tanh, &mut init);
        let b = cfg.batch_size;
        let critic_sizes = sizes(obs_dim + act_dim, &cfg.hidden, 1);
        let critics = Critics::new(family.critics, &critic_sizes, cfg.critic_lr(), &mut init, b, act_dim);
        let (kind, sigma, theta) = family.noise;
        Td3 {
            actor_opt: Adam::new(actor.num_params(), cfg.actor_lr()),
            actor_target: actor.clone(),
            noise: ActionNoise::new(kind, sigma, theta, act_dim),
            rng: Rng::derived(seed, family.salts.1),
            updates: 0,
            norm: cfg.norm_obs.map(|n| OffPolicyNorm::new(obs_dim, &n, b)),
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            critic_in_next: vec![0.0; b * (obs_dim + act_dim)],
            a_next: vec![0.0; b * act_dim],
            smoothing_noise: vec![0.0; b * act_dim],
            y: vec![0.0; b],
            family,
            cfg: cfg.clone(),
            obs_dim,
            act_dim,
            actor,
            critics,
        }
    }

    /// The number of critics.
    pub fn num_critics(&self) -> usize {
        self.critics.len()
    }
}

impl Agent for Td3 {
    fn algo(&self) -> Algo {
        self.family.algo
    }
    fn actor(&self) -> &Mlp<f32> {
        &self.actor
    }
    fn act_dim(&self) -> usize {
        self.act_dim
    }

    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        action.copy_from_slice(self.actor.predict(one_input(&mut self.norm, obs), 1));
        self.noise.perturb(&mut self.rng, action);
    }

    fn predict(&mut self, obs: &[f32], action: &mut [f32]) {
        action.copy_from_slice(self.actor.predict(one_input(&mut self.norm, obs), 1));
    }

    fn obs_norm(&self) -> Option<&ObsNorm> {
        self.norm.as_ref().map(|n| &n.norm)
    }

    fn begin_episode(&mut self) {
        self.noise.reset();
    }
}

impl OffPolicy for Td3 {
    fn observe(&mut self, obs: &[f32]) {
        if let Some(n) = &mut self.norm {
            n.observe(obs);
        }
    }

    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let b = batch.size;
        self.updates += 1;
        let actor_due = self.updates.is_multiple_of(u64::from(self.family.policy_delay));
        let (od, ad) = (self.obs_dim, self.act_dim);
        let (obs, next_obs) = batch_inputs(&mut self.norm, &batch.obs, &batch.next_obs, b);

        // 1-2. The targets y (steps 1 and 2's target), while the critics' forward passes on
        // (s, a) run on a second thread (with a pool; the results do not depend on it).
        concat_cols(obs, od, &batch.act, ad, b, &mut self.critic_in);
        let mut targets = Targets {
            family: &self.family,
            gamma: self.cfg.gamma as f32,
            actor: &mut self.actor_target,
            rng: &mut self.rng,
            smoothing_noise: &mut self.smoothing_noise,
            a_next: &mut self.a_next,
            critic_in: &mut self.critic_in_next,
            y: &mut self.y,
        };
        let target_side = |critics: TargetSide<'_>| targets.compute(batch, next_obs, od, ad, critics);
        self.critics.forward_alongside(&self.critic_in, b, target_side);

        // 2. Each critic minimises its error. A lone critic shares the step with the actor's
        // forward pass mu(s) when the actor is due.
        let n = self.cfg.max_grad_norm;
        let actor = &mut self.actor;
        let actor_forward = || {
            if actor_due {
                actor.forward(obs, b);
            }
        };
        let critic_loss = critics::mean(self.critics.fit_forwarded(&self.y[..b], n, actor_forward));

        // 3. Delayed actor and targets.
        let mut actor_loss = None;
        if actor_due {
            concat_cols(obs, od, actor.output(), ad, b, &mut self.critic_in);
            let q = self.critics.forward_first(&self.critic_in, b);
            actor_loss = Some(-q.iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64);
            let da = self.critics.input_grad_first(-1.0 / b as f32, od..od + ad);
            actor.zero_grad();
            actor.backward(da);
            step(actor, &mut self.actor_opt, n);
            let tau = self.cfg.tau as f32;
            self.actor_target.polyak_from(actor, tau);
            self.critics.polyak(tau);
        }

        UpdateStats { critic_loss, actor_loss, alpha: None, entropy: None }
    }
}

/// The target side of an update: the target actor and the buffers of the target.
struct Targets<'a> {
    family: &'a Family,
    gamma: f32,
    actor: &'a mut Mlp<f32>,
    rng: &'a mut Rng,
    smoothing_noise: &'a mut [f64],
    a_next: &'a mut [f32],
    critic_in: &'a mut Vec<f32>,
    y: &'a mut [f32],
}

impl Targets<'_> {
    /// Steps 1 and 2's target: `y = r + gamma (1 - d) min_i Q_i'(s', a')`, `s'` as the networks
    /// read it (`next_obs`: the batch's, normalised with `agent.norm_obs`).
    fn compute(
        &mut self,
        batch: &Batch,
        next_obs: &[f32],
        od: usize,
        ad: usize,
        mut critics: TargetSide<'_>,
    ) {
        let b = batch.size;
        // 1. Target action, smoothed for TD3.
        let mu_next = self.actor.predict(next_obs, b);
        let a_next = match self.family.target_smoothing {
            Some((sigma, c)) => {
                let z = &mut self.smoothing_noise[..b * ad];
                self.rng.fill_normal(z);
                for ((out, &m), &z) in self.a_next[..b * ad].iter_mut().zip(mu_next).zip(z.iter()) {
                    let n = (sigma * z).clamp(-c, c);
                    *out = (f64::from(m) + n).clamp(-1.0, 1.0) as f32;
                }
                &self.a_next[..b * ad]
            }
            None => mu_next,
        };
        concat_cols(next_obs, od, a_next, ad, b, self.critic_in);

        // 2. Towards the smallest target critic.
        let y = &mut self.y[..b];
        critics.min(self.critic_in, b, y);
        for i in 0..b {
            y[i] = batch.reward[i] + self.gamma * (1.0 - batch.terminal[i]) * y[i];
        }
    }
}

learned_parts!(Td3, |s, f| {
    let names = s.critics.names();
    f("actor", P::Net(r!(s.actor)));
    for (name, q) in names.iter().zip(each!(s.critics.nets)) {
        f(name[0], P::Net(q));
    }
    f("actor_target", P::Net(r!(s.actor_target)));
    for (name, q) in names.iter().zip(each!(s.critics.targets)) {
        f(name[1], P::Net(q));
    }
    f("actor_opt", P::Adam(r!(s.actor_opt)));
    for (name, opt) in names.iter().zip(each!(s.critics.opts)) {
        f(name[2], P::Adam(opt));
    }
    f("agent_rng", P::State(r!(s.rng)));
    f("agent_noise", P::State(r!(s.noise)));
    f("agent_updates", P::State(r!(s.updates)));
    // `agent.norm_obs`: the statistics (listed only when set).
    if let Some(n) = r!(s.norm) {
        f("obs_norm", P::State(r!(n.norm)));
        f(super::obs_norm::MEAN_TENSOR, P::Tensor(r!(n.norm.mean)));
        f(super::obs_norm::STD_TENSOR, P::Tensor(r!(n.norm.std)));
    }
});
