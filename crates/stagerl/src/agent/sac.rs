//! Soft Actor-Critic with automatic entropy tuning (Haarnoja et al. 2018), as in CleanRL and
//! Stable-Baselines3, and its ensemble variants REDQ (Chen et al., ICLR 2021) and DroQ (Hiraoka
//! et al., ICLR 2022: dropout and layer normalisation in the critics and their targets).
//!
//! Networks: a tanh-squashed Gaussian actor `obs -> [mean | s]` (log-std `l = -5 + 3.5 (tanh s + 1)`,
//! in [-5, 2], CleanRL's; with `actor_log_std = "clip"`, `l = clamp(s, -20, 2)`, sbx's and
//! SB3's), `N = n_critics` critics `Q_i: [obs | act] -> 1` (2, SAC's twins, by default) and
//! their Polyak-averaged targets (a [`Critics`] ensemble).
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. critic target `y = r + gamma (1 - d) (min_{i in M} Q_i'(s', a') - alpha log pi(a'|s'))`,
//!    `a' ~ pi(.|s')`, `M` all the critics (SAC) or, with `critic_subset = m < N`, `m` of them
//!    drawn without replacement for this update (REDQ's in-target minimisation); each critic
//!    minimises `mean (Q_i(s, a) - y)^2`;
//! 2. actor minimises `mean (alpha log pi(a~|s) - Q(s, a~))`, `a~ ~ pi(.|s)`, reparameterised,
//!    so the gradient flows through dQ/da and the squashed Gaussian; `Q` is `min_i Q_i` (SAC) or
//!    `(1/N) sum_i Q_i` (`actor_q = "mean"`, REDQ's and DroQ's); with `bc_weight` (our addition,
//!    for `[train.demonstrations]`) plus `bc_weight * (1/B) sum_i d_i |a~_i - a_i|^2` over the
//!    batch's demonstration rows (`d_i = 1`);
//! 3. `log alpha` minimises `-log alpha * mean(log pi(a~|s) + H_target)`, `H_target = -act_dim`
//!    (times `target_entropy_per_dim`);
//!
//!    steps 2 and 3 run at every `policy_delay`-th update only (default 1: every update), the
//!    updates counted across environment steps (the `k`-th, `2k`-th, ...: sbx's
//!    `(n_updates + 1) % policy_delay` offset); skipped, they draw nothing;
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

/// How the actor's raw output `s` becomes its log standard deviation `l`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ActorLogStd {
    /// `l = -5 + 3.5 (tanh s + 1)`, in [-5, 2], smooth (CleanRL's; an untrained actor's std
    /// is about 0.22).
    #[default]
    Tanh,
    /// `l = clamp(s, -20, 2)`, gradient 1 inside and 0 outside (sbx's and SB3's `clip`; an
    /// untrained actor's std is about 1).
    Clip,
}

impl ActorLogStd {
    /// The head's bound.
    pub fn bound(self) -> LogStdBound {
        match self {
            ActorLogStd::Tanh => LogStdBound::Tanh { min: -5.0, max: 2.0 },
            ActorLogStd::Clip => LogStdBound::Clamp { min: -20.0, max: 2.0 },
        }
    }
}

/// `[agent.sac]`: SAC's entropy coefficient, its critic ensemble, its actor's log-std bound and
/// policy delay.
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
    /// The actor's log-std bound: `"tanh"` (`-5 + 3.5 (tanh s + 1)`, in [-5, 2], CleanRL's) or
    /// `"clip"` (`clamp(s, -20, 2)`, sbx's and SB3's).
    #[serde(skip_serializing_if = "is_tanh")]
    pub actor_log_std: ActorLogStd,
    /// Critic updates per actor and entropy-coefficient update, >= 1: they step at every
    /// `policy_delay`-th update, counted across environment steps (sbx's; its DroQ: the updates
    /// per step).
    #[serde(skip_serializing_if = "is_one")]
    pub policy_delay: u32,
    /// Behaviour cloning of the demonstrations (`[train.demonstrations]`, which it needs): the
    /// actor's loss adds `bc_weight * (1/B) sum_i d_i |a~_i - a_i|^2`, `d_i` 1 where row `i` of
    /// the batch is a demonstration, `a~_i` the reparameterised sample, `a_i` the demonstrated
    /// action; >= 0, 0 (the default): the demonstrations are only replayed.
    #[serde(skip_serializing_if = "is_zero")]
    pub bc_weight: f64,
}

fn is_tanh(b: &ActorLogStd) -> bool {
    *b == ActorLogStd::Tanh
}

fn is_one(n: &u32) -> bool {
    *n == 1
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
            actor_log_std: ActorLogStd::Tanh,
            policy_delay: 1,
            bc_weight: 0.0,
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
        if !(self.bc_weight.is_finite() && self.bc_weight >= 0.0 && self.bc_weight <= 1e6) {
            return Err(Error::config(
                "agent.sac.bc_weight",
                self.bc_weight,
                "a weight in [0, 1e6] (0: the demonstrations are only replayed)",
            ));
        }
        if self.policy_delay == 0 {
            return Err(Error::config(
                "agent.sac.policy_delay",
                0,
                "an integer >= 1 (critic updates per actor and entropy-coefficient update; 1: every update)",
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
    /// `policy_delay`: the actor and alpha step at every this many updates.
    policy_delay: u32,
    /// Updates so far (the policy delay counts them; in the checkpoint when it is above 1).
    updates: u64,
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
    /// `bc_weight` and dL/da~ with its term.
    bc_weight: f32,
    da_bc: Vec<f32>,
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
            head: SquashedGaussian::new(act_dim, own.actor_log_std.bound()),
            rng: Rng::derived(seed, 0x5AC1),
            norm: cfg.norm_obs.map(|n| OffPolicyNorm::new(obs_dim, &n, b)),
            subset: own.subset(),
            actor_q: own.actor_q(),
            policy_delay: own.policy_delay,
            updates: 0,
            eps: vec![0.0; b * act_dim],
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            next_act: vec![0.0; b * act_dim],
            next_logp: vec![0.0; b],
            y: vec![0.0; b],
            dlogp: vec![0.0; b],
            bc_weight: own.bc_weight as f32,
            da_bc: vec![0.0; if own.bc_weight > 0.0 { b * act_dim } else { 0 }],
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

        // 2-3. Actor and entropy coefficient, at every `policy_delay`-th update (the count
        //    runs across environment steps, as sbx's `(n_updates + 1) % policy_delay`).
        self.updates += 1;
        let actor = if self.updates.is_multiple_of(u64::from(self.policy_delay)) {
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
            let mut da = match self.actor_q {
                ActorQ::Min => self.critics.input_grad_min(-inv_b, od..od + ad),
                ActorQ::Mean => self.critics.input_grad_mean(-inv_b, od..od + ad),
            };
            if self.bc_weight > 0.0 {
                // `bc_weight`: the demonstrations' behaviour cloning term.
                let (a, c) = (self.head.action(), 2.0 * self.bc_weight * inv_b);
                let mut bc = 0.0f64;
                for (k, g) in self.da_bc[..b * ad].iter_mut().enumerate() {
                    let (d, diff) = (batch.demo[k / ad], a[k] - batch.act[k]);
                    *g = da[k] + c * d * diff;
                    bc += f64::from(d * diff * diff);
                }
                actor_loss += f64::from(self.bc_weight) * bc / b as f64;
                da = &self.da_bc[..b * ad];
            }
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
            Some((actor_loss, mean_logp))
        } else {
            None
        };

        // 4. Targets.
        self.critics.polyak(self.cfg.tau as f32);

        UpdateStats {
            critic_loss,
            actor_loss: actor.map(|a| a.0),
            alpha: Some(f64::from(alpha)),
            entropy: actor.map(|a| -a.1),
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
    // The update count of the policy delay (listed only when it is above 1).
    if s.policy_delay > 1 {
        f("agent_updates", P::State(r!(s.updates)));
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(own: SacConfig) -> AgentConfig {
        AgentConfig { hidden: vec![16, 16], batch_size: 8, sac: Some(own), ..AgentConfig::new(Algo::Sac) }
    }

    fn batch(rng: &mut Rng, b: usize, od: usize, ad: usize) -> Batch {
        let mut batch = Batch::new(b, od, ad);
        for x in batch.obs.iter_mut().chain(&mut batch.next_obs).chain(&mut batch.act) {
            *x = rng.uniform_range(-1.0, 1.0) as f32;
        }
        for (i, r) in batch.reward.iter_mut().enumerate() {
            *r = i as f32 * 0.1 - 0.3;
        }
        batch
    }

    /// `"clip"` is sbx's `jnp.clip(s, -20, 2)`: the log-std, the sample and its log-density
    /// against their formulas written out here, and dL/ds against central differences inside
    /// the range and 0 outside it; `"tanh"` stays CleanRL's map.
    #[test]
    fn the_clip_log_std_is_sbx_clip_with_its_gradient() {
        assert_eq!(ActorLogStd::default(), ActorLogStd::Tanh);
        assert_eq!(ActorLogStd::Tanh.bound(), LogStdBound::Tanh { min: -5.0, max: 2.0 });
        assert_eq!(ActorLogStd::Clip.bound(), LogStdBound::Clamp { min: -20.0, max: 2.0 });
        let bound = ActorLogStd::Clip.bound();
        // One action; s inside and on either side of [-20, 2], mean 0.3, noise 0.7.
        let (mean, eps) = (0.3f64, 0.7f64);
        for s in [-25.0f64, -20.5, -19.5, -3.0, -0.4, 0.0, 1.2, 1.99, 2.01, 2.5, 7.0] {
            let l = s.clamp(-20.0, 2.0);
            let u = mean + l.exp() * eps;
            let logp = -0.5 * eps * eps
                - l
                - 0.5 * (2.0 * std::f64::consts::PI).ln()
                - (1.0 - u.tanh().powi(2)).ln();
            let mut head = SquashedGaussian::<f64>::new(1, bound);
            let (a, lp) = head.forward(&[mean, s], &[eps], 1);
            assert!((a[0] - u.tanh()).abs() < 1e-14, "s = {s}");
            assert!((lp[0] - logp).abs() < 1e-9 * logp.abs().max(1.0), "s = {s}: {} vs {logp}", lp[0]);
            // L = 0.6 a - 1.3 log p; its derivative in s through the head's backward pass.
            let g = head.backward(&[0.6], &[-1.3])[1];
            let loss = |s: f64| {
                let mut h = SquashedGaussian::<f64>::new(1, bound);
                let (a, lp) = h.forward(&[mean, s], &[eps], 1);
                0.6 * a[0] - 1.3 * lp[0]
            };
            let inside = (-20.0..=2.0).contains(&s);
            if inside {
                let h = 1e-6;
                let num = (loss(s + h) - loss(s - h)) / (2.0 * h);
                assert!((g - num).abs() < 1e-6 * num.abs().max(1.0), "s = {s}: {g} vs {num}");
                // dl/ds = 1: dL/ds = dL/du std eps - dL/dlogp (independent formula).
                let dl_du = 0.6 * (1.0 - u.tanh().powi(2)) - 1.3 * 2.0 * u.tanh();
                assert!((g - (dl_du * l.exp() * eps + 1.3)).abs() < 1e-12, "s = {s}");
            } else {
                assert_eq!(g, 0.0, "s = {s}: no gradient outside the clip");
                assert_eq!(loss(s), loss(s + 0.25 * s.signum()), "s = {s}: flat outside");
            }
        }
    }

    /// With `policy_delay = 3` the actor and alpha step at the 3rd, 6th, ... update only,
    /// counted across calls (environment steps), and the count is a learned part; with 1 (the
    /// default) at every update, and no count is saved.
    #[test]
    fn the_actor_and_alpha_step_every_policy_delay_updates() {
        let (od, ad, b) = (5, 2, 8);
        let mut rng = Rng::new(4);
        let batch = batch(&mut rng, b, od, ad);
        let obs = [0.3f32; 5];
        for delay in [1u32, 3] {
            let own =
                SacConfig { policy_delay: delay, actor_log_std: ActorLogStd::Clip, ..SacConfig::default() };
            own.validate().unwrap();
            let mut agent = Sac::new(&cfg(own), od, ad, 3);
            assert_eq!(agent.head.bound(), LogStdBound::Clamp { min: -20.0, max: 2.0 });
            let (mut before, mut after) = ([0.0f32; 2], [0.0f32; 2]);
            for k in 1..=7u64 {
                agent.predict(&obs, &mut before);
                let alpha = agent.alpha();
                let s = agent.update(&batch);
                agent.predict(&obs, &mut after);
                let due = k % u64::from(delay) == 0;
                assert_eq!(
                    (s.actor_loss.is_some(), s.entropy.is_some()),
                    (due, due),
                    "delay {delay}, update {k}"
                );
                assert_eq!(
                    before != after,
                    due,
                    "delay {delay}, update {k}: the actor moves only at its steps"
                );
                assert_eq!(agent.alpha() != alpha, due, "delay {delay}, update {k}: alpha too");
            }
            let mut names = Vec::new();
            crate::agent::parts::Learned::parts(&agent, &mut |name, _| names.push(name.to_string()));
            assert_eq!(names.iter().any(|n| n == "agent_updates"), delay > 1, "{names:?}");
        }
        let bad = SacConfig { policy_delay: 0, ..SacConfig::default() }.validate().unwrap_err().to_string();
        assert!(bad.contains("agent.sac.policy_delay") && bad.contains('0') && bad.contains(">= 1"), "{bad}");
        // The defaults are left out of a written config; the others are written.
        let written = toml::to_string(&SacConfig::default()).unwrap();
        assert!(!written.contains("actor_log_std") && !written.contains("policy_delay"), "{written}");
        let own = SacConfig { policy_delay: 20, actor_log_std: ActorLogStd::Clip, ..SacConfig::default() };
        let written = toml::to_string(&own).unwrap();
        assert!(
            written.contains("actor_log_std = \"clip\"") && written.contains("policy_delay = 20"),
            "{written}"
        );
        assert_eq!(toml::from_str::<SacConfig>(&written).unwrap(), own);
        let e = toml::from_str::<SacConfig>("actor_log_std = \"softplus\"\n").unwrap_err().to_string();
        assert!(e.contains("actor_log_std") && e.contains("softplus") && e.contains("clip"), "{e}");
    }
}
