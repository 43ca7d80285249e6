//! Soft Actor-Critic with automatic entropy tuning (Haarnoja et al. 2018), as in CleanRL and
//! Stable-Baselines3, and its ensemble variants REDQ (Chen et al., ICLR 2021) and DroQ (Hiraoka
//! et al., ICLR 2022: dropout and layer normalisation in the critics and their targets).
//!
//! Networks: a tanh-squashed Gaussian actor `obs -> [mean | s]` (log-std `l = -5 + 3.5 (tanh s + 1)`,
//! in [-5, 2]), `N = n_critics` critics `Q_i: [obs | act] -> 1` (2, SAC's twins, by default) and
//! their Polyak-averaged targets (a [`Critics`] ensemble).
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. critic target `y = r + gamma (1 - d) (min_{i in M} Q_i'(s', a') - alpha log pi(a'|s'))`,
//!    `a' ~ pi(.|s')`, `M` all the critics (SAC) or, with `critic_subset = m < N`, `m` of them
//!    drawn without replacement for this update (REDQ's in-target minimisation); each critic
//!    minimises `mean (Q_i(s, a) - y)^2`;
//! 2. actor minimises `mean (alpha log pi(a~|s) - Q(s, a~))`, `a~ ~ pi(.|s)`, reparameterised,
//!    so the gradient flows through dQ/da and the squashed Gaussian; `Q` is `min_i Q_i` (SAC) or
//!    `(1/N) sum_i Q_i` (`actor_q = "mean"`, REDQ's and DroQ's);
//! 3. `log alpha` minimises `-log alpha * mean(log pi(a~|s) + H_target)`, `H_target = -act_dim`
//!    (times `target_entropy_per_dim`);
//! 4. targets `theta' <- (1 - tau) theta' + tau theta`.
//!
//! REDQ is `n_critics = 10`, `critic_subset = 2` with `agent.updates_per_step = 20`; DroQ is
//! `critic_dropout = 0.01`, `critic_layer_norm = true`, `actor_q = "mean"` with
//! `agent.updates_per_step = 20` (each critic's hidden layers `relu(LN(dropout(x W^T + b)))`,
//! [`crate::nn::HiddenNorm`]; the critics, their targets and the actor's critics all drop out,
//! each from its own stream).
//!
//! With `agent.norm_obs`, the actor and the critics read observations normalised by running
//! statistics ([`super::obs_norm`]: updated as observations are collected, applied to each
//! sampled batch).
//!
//! Its own settings: `[agent.sac]`, [`SacConfig`] (the entropy coefficient, the ensemble).

use serde::{Deserialize, Serialize};

use super::critics::{self, Critics, DROPOUT_RNG, ENSEMBLE};
use super::obs_norm::{batch_inputs, one_input, ObsNorm, OffPolicyNorm};
use super::parts::learned_parts;
use super::{sizes, step, Agent, AgentConfig, Algo, OffPolicy, UpdateStats};
use crate::agent::replay::Batch;
use crate::base::rng::Rng;
use crate::base::validate::{finite, positive};
use crate::nn::{concat_cols, Activation, Adam, HiddenNorm, LogStdBound, Mlp, SquashedGaussian};
use crate::{Error, Result};

/// Most critics of an ensemble (`agent.sac.n_critics`).
pub const MAX_CRITICS: usize = ENSEMBLE.len();

/// What the actor maximises of the critics' values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ActorQ {
    /// The smallest of the critics' values, per row (SAC's `min(Q1, Q2)`).
    Min,
    /// The mean of every critic's value (REDQ's and DroQ's).
    Mean,
}

/// `[agent.sac]`: SAC's entropy coefficient and its critic ensemble.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SacConfig {
    /// Learning rate of log(alpha).
    pub alpha_lr: f64,
    /// Initial entropy coefficient alpha.
    pub init_alpha: f64,
    /// Target entropy per action dimension (the usual choice: -1, i.e. -act_dim in total).
    pub target_entropy_per_dim: f64,
    /// Fix alpha at `init_alpha` instead of tuning it.
    pub fixed_alpha: bool,
    /// Critics in the ensemble, 1..=20 (SAC: 2; REDQ: 10). Checkpoint names `q1` .. `qN`.
    #[serde(skip_serializing_if = "is_two")]
    pub n_critics: usize,
    /// Critics whose minimum makes each update's target, drawn anew per update (REDQ: 2 of 10);
    /// unset: all of them (SAC).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub critic_subset: Option<usize>,
    /// What the actor maximises: `"min"` (the critics' smallest value, SAC's) or `"mean"` (their
    /// mean, REDQ's); unset: `"mean"` when `critic_subset` is below `n_critics` (REDQ), else `"min"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actor_q: Option<ActorQ>,
    /// Dropout probability after each critic's hidden layers, in [0, 1) (DroQ: 0.01); 0: none.
    #[serde(skip_serializing_if = "is_zero")]
    pub critic_dropout: f64,
    /// Layer normalisation (learned scale and bias) after each critic's hidden layers, after
    /// dropout (DroQ's).
    #[serde(skip_serializing_if = "is_false")]
    pub critic_layer_norm: bool,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn is_false(b: &bool) -> bool {
    !*b
}

fn is_two(n: &usize) -> bool {
    *n == 2
}

impl Default for SacConfig {
    fn default() -> Self {
        SacConfig {
            alpha_lr: 3e-4,
            init_alpha: 1.0,
            target_entropy_per_dim: -1.0,
            fixed_alpha: false,
            n_critics: 2,
            critic_subset: None,
            actor_q: None,
            critic_dropout: 0.0,
            critic_layer_norm: false,
        }
    }
}

impl SacConfig {
    /// Check every value; the error names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        positive("agent.sac.alpha_lr", self.alpha_lr)?;
        positive("agent.sac.init_alpha", self.init_alpha)?;
        finite("agent.sac.target_entropy_per_dim", self.target_entropy_per_dim)?;
        if !(1..=MAX_CRITICS).contains(&self.n_critics) {
            return Err(Error::config(
                "agent.sac.n_critics",
                self.n_critics,
                format!("an integer in 1..={MAX_CRITICS} (critics in the ensemble)"),
            ));
        }
        if let Some(m) = self.critic_subset.filter(|m| !(1..=self.n_critics).contains(m)) {
            return Err(Error::config(
                "agent.sac.critic_subset",
                m,
                format!(
                    "an integer in 1..={} (at most agent.sac.n_critics = {}), or unset for all of them",
                    self.n_critics, self.n_critics
                ),
            ));
        }
        if !(self.critic_dropout.is_finite() && (0.0..1.0).contains(&self.critic_dropout)) {
            return Err(Error::config(
                "agent.sac.critic_dropout",
                self.critic_dropout,
                "a probability in [0, 1) (0: no dropout; DroQ: 0.01)",
            ));
        }
        Ok(())
    }

    /// The critics' dropout and layer normalisation, if any.
    pub fn critic_norm(&self) -> Option<HiddenNorm> {
        (self.critic_dropout > 0.0 || self.critic_layer_norm)
            .then_some(HiddenNorm { dropout: self.critic_dropout, layer_norm: self.critic_layer_norm })
    }

    /// Critics whose minimum makes the target: `critic_subset`, else all.
    pub fn subset(&self) -> usize {
        self.critic_subset.unwrap_or(self.n_critics)
    }

    /// What the actor maximises: `actor_q`, else the mean for REDQ (a subset below all the
    /// critics) and the minimum otherwise.
    pub fn actor_q(&self) -> ActorQ {
        self.actor_q.unwrap_or(if self.subset() < self.n_critics { ActorQ::Mean } else { ActorQ::Min })
    }
}

/// The log-std range of the actor (CleanRL's).
const LOG_STD: LogStdBound = LogStdBound::Tanh { min: -5.0, max: 2.0 };

pub struct Sac {
    cfg: AgentConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp<f32>,
    head: SquashedGaussian<f32>,
    /// The critics `q1` .. `qN`, their targets and optimisers.
    critics: Critics,
    /// Critics in each update's target (`N`: all, no draw).
    subset: usize,
    actor_q: ActorQ,
    actor_opt: Adam<f32>,
    log_alpha: [f32; 1],
    alpha_opt: Adam<f32>,
    target_entropy: f32,
    rng: Rng,
    /// `agent.norm_obs`: the running observation normalisation.
    norm: Option<OffPolicyNorm>,
    // Scratch, grown once to the batch size.
    eps: Vec<f32>,
    critic_in: Vec<f32>,
    next_act: Vec<f32>,
    next_logp: Vec<f32>,
    y: Vec<f32>,
    dlogp: Vec<f32>,
}

impl Sac {
    pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Sac {
        let mut init = Rng::derived(seed, 0x5AC);
        let actor = Mlp::new(
            &sizes(obs_dim, &cfg.hidden, 2 * act_dim),
            Activation::Relu,
            Activation::Identity,
            &mut init,
        );
        let (b, own) = (cfg.batch_size, cfg.sac());
        let critic_sizes = sizes(obs_dim + act_dim, &cfg.hidden, 1);
        let names = &ENSEMBLE[..own.n_critics];
        let norm = own.critic_norm();
        let critics =
            Critics::with_norm(names, &critic_sizes, cfg.critic_lr(), &mut init, (b, act_dim), norm);
        Sac {
            actor_opt: Adam::new(actor.num_params(), cfg.actor_lr()),
            log_alpha: [own.init_alpha.ln() as f32],
            alpha_opt: Adam::new(1, own.alpha_lr),
            target_entropy: (own.target_entropy_per_dim * act_dim as f64) as f32,
            head: SquashedGaussian::new(act_dim, LOG_STD),
            rng: Rng::derived(seed, 0x5AC1),
            norm: cfg.norm_obs.map(|n| OffPolicyNorm::new(obs_dim, &n, b)),
            subset: own.subset(),
            actor_q: own.actor_q(),
            eps: vec![0.0; b * act_dim],
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            next_act: vec![0.0; b * act_dim],
            next_logp: vec![0.0; b],
            y: vec![0.0; b],
            dlogp: vec![0.0; b],
            cfg: cfg.clone(),
            obs_dim,
            act_dim,
            actor,
            critics,
        }
    }

    /// The entropy coefficient alpha.
    pub fn alpha(&self) -> f32 {
        crate::base::math::exp_f32(self.log_alpha[0])
    }

    fn fill_normal(rng: &mut Rng, out: &mut [f32]) {
        rng.fill_normal_f32(out);
    }
}

impl Agent for Sac {
    fn algo(&self) -> Algo {
        Algo::Sac
    }
    fn actor(&self) -> &Mlp<f32> {
        &self.actor
    }
    fn act_dim(&self) -> usize {
        self.act_dim
    }

    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        let raw = self.actor.predict(one_input(&mut self.norm, obs), 1);
        let eps = &mut self.eps[..self.act_dim];
        Self::fill_normal(&mut self.rng, eps);
        let (a, _) = self.head.forward(raw, eps, 1);
        action.copy_from_slice(a);
    }

    fn predict(&mut self, obs: &[f32], action: &mut [f32]) {
        let raw = self.actor.predict(one_input(&mut self.norm, obs), 1);
        self.head.deterministic(raw, 1, action);
    }

    fn obs_norm(&self) -> Option<&ObsNorm> {
        self.norm.as_ref().map(|n| &n.norm)
    }
}

impl OffPolicy for Sac {
    fn observe(&mut self, obs: &[f32]) {
        if let Some(n) = &mut self.norm {
            n.observe(obs);
        }
    }

    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let (b, od, ad) = (batch.size, self.obs_dim, self.act_dim);
        let alpha = self.alpha();
        let gamma = self.cfg.gamma as f32;
        let (obs, next_obs) = batch_inputs(&mut self.norm, &batch.obs, &batch.next_obs, b);

        // 1. Critics.
        let raw_next = self.actor.predict(next_obs, b);
        Self::fill_normal(&mut self.rng, &mut self.eps[..b * ad]);
        let (a_next, logp_next) = self.head.forward(raw_next, &self.eps[..b * ad], b);
        self.next_act[..b * ad].copy_from_slice(a_next);
        self.next_logp[..b].copy_from_slice(logp_next);
        concat_cols(next_obs, od, &self.next_act[..b * ad], ad, b, &mut self.critic_in);
        if self.subset < self.critics.len() {
            self.critics.choose_targets(self.subset, &mut self.rng);
        }
        self.critics.target_min(&self.critic_in, b, &mut self.y);
        for i in 0..b {
            let soft_v = self.y[i] - alpha * self.next_logp[i];
            self.y[i] = batch.reward[i] + gamma * (1.0 - batch.terminal[i]) * soft_v;
        }
        concat_cols(obs, od, &batch.act, ad, b, &mut self.critic_in);
        let losses = self.critics.fit(&self.critic_in, &self.y[..b], self.cfg.max_grad_norm);
        let critic_loss = critics::mean(losses);

        // 2. Actor, through the reparameterised sample and dQ/da of the smallest critic per row
        //    (or of every critic, weighted 1/N, for their mean).
        let raw = self.actor.forward(obs, b);
        Self::fill_normal(&mut self.rng, &mut self.eps[..b * ad]);
        let (a, logp) = self.head.forward(raw, &self.eps[..b * ad], b);
        self.next_logp[..b].copy_from_slice(logp); // reuse: log pi(a~|s)
        concat_cols(obs, od, a, ad, b, &mut self.critic_in);
        let q = match self.actor_q {
            ActorQ::Min => self.critics.forward_min(&self.critic_in, b),
            ActorQ::Mean => self.critics.forward_mean(&self.critic_in, b),
        };
        let inv_b = 1.0 / b as f32;
        let mut actor_loss = 0.0f64;
        for i in 0..b {
            actor_loss += f64::from(alpha * self.next_logp[i] - q[i]);
            self.dlogp[i] = alpha * inv_b;
        }
        actor_loss /= b as f64;
        let da = match self.actor_q {
            ActorQ::Min => self.critics.input_grad_min(-inv_b, od..od + ad),
            ActorQ::Mean => self.critics.input_grad_mean(-inv_b, od..od + ad),
        };
        let d_raw = self.head.backward(da, &self.dlogp[..b]);
        self.actor.zero_grad();
        self.actor.backward(d_raw);
        step(&mut self.actor, &mut self.actor_opt, self.cfg.max_grad_norm);

        // 3. Entropy coefficient.
        let mean_logp = self.next_logp[..b].iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64;
        if !self.cfg.sac().fixed_alpha {
            let grad = [-(mean_logp as f32 + self.target_entropy)];
            self.alpha_opt.step(&mut self.log_alpha, &grad);
        }

        // 4. Targets.
        self.critics.polyak(self.cfg.tau as f32);

        UpdateStats {
            critic_loss,
            actor_loss: Some(actor_loss),
            alpha: Some(f64::from(alpha)),
            entropy: Some(-mean_logp),
        }
    }
}

learned_parts!(Sac, |s, f| {
    let names = s.critics.names();
    f("actor", P::Net(r!(s.actor)));
    for (name, q) in names.iter().zip(each!(s.critics.nets)) {
        f(name[0], P::Net(q));
    }
    for (name, q) in names.iter().zip(each!(s.critics.targets)) {
        f(name[1], P::Net(q));
    }
    f("log_alpha", P::Tensor(r!(s.log_alpha)));
    f("actor_opt", P::Adam(r!(s.actor_opt)));
    for (name, opt) in names.iter().zip(each!(s.critics.opts)) {
        f(name[2], P::Adam(opt));
    }
    f("alpha_opt", P::Adam(r!(s.alpha_opt)));
    f("agent_rng", P::State(r!(s.rng)));
    // DroQ: the dropout streams (listed only when the critics drop out).
    let drops = s.critics.drops_out();
    for (name, c) in DROPOUT_RNG.iter().zip(each!(s.critics.scratch)).filter(|_| drops) {
        f(name[0], P::State(r!(c.drop)));
    }
    for (name, t) in DROPOUT_RNG.iter().zip(each!(s.critics.target_drop)).filter(|_| drops) {
        f(name[1], P::State(t));
    }
    // `agent.norm_obs`: the statistics (listed only when set).
    if let Some(n) = r!(s.norm) {
        f("obs_norm", P::State(r!(n.norm)));
        f(super::obs_norm::MEAN_TENSOR, P::Tensor(r!(n.norm.mean)));
        f(super::obs_norm::STD_TENSOR, P::Tensor(r!(n.norm.std)));
    }
});
