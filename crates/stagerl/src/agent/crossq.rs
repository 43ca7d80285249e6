//! CrossQ (Bhatt et al., ICLR 2024), as sbx's `sbx/crossq` (JAX Stable-Baselines): SAC without
//! target networks, with batch renormalisation in the critics and the actor, and the current and
//! next state-actions in one joint forward pass of each critic.
//!
//! Networks, as sbx's `sbx/crossq/policies.py` builds them ([`BrnMlp`]: a batch renormalisation
//! on the input, then per hidden layer `relu(x W^T + b)` and a batch renormalisation; then the
//! output layer): a tanh-squashed Gaussian actor `obs -> [mean | s]` (log-std `clamp(s, -20, 2)`,
//! sbx's), hidden `agent.hidden`; `N = n_critics` critics `Q_i: [obs | act] -> 1`, hidden
//! `critic_hidden`. No target networks (`agent.tau` is unused).
//!
//! One update on a batch `(s, a, r, s', d)` (sbx's `update_critic`, `update_actor`,
//! `update_temperature`):
//! 1. next actions from the actor's inference (running statistics, sbx's `train=False`):
//!    `a' ~ pi(.|s')`, `log pi(a'|s')`;
//! 2. each critic runs ONE training pass on the `2B` rows `[(s, a); (s', a')]`, so that its batch
//!    statistics cover both halves (and its running statistics move once); with the first half
//!    `Q_i(s, a)` and the second `Q_i(s', a')`, the target
//!    `y = r + gamma (1 - d) (min_i Q_i(s', a') - alpha log pi(a'|s'))` is held constant and each
//!    critic minimises `mean_B (Q_i(s, a) - y)^2` (the gradient reaches the parameters through
//!    both halves' shares of the batch statistics; the second half's outputs get none); one
//!    Adam step each;
//! 3. every `policy_delay`-th update (the 3rd, 6th, ...: sbx's `(n_updates + 1) % policy_delay`
//!    offset), the actor and the entropy coefficient: the actor runs a training pass on `s`
//!    (batch statistics, running statistics moved), `a~ ~ pi(.|s)` reparameterised, and minimises
//!    `mean (alpha log pi(a~|s) - min_i Q_i(s, a~))` with the critics in inference (running
//!    statistics, sbx's `train=False`), the gradient through dQ/da of the smallest critic per row
//!    and the squashed Gaussian; then `log alpha` minimises
//!    `-log alpha * mean(log pi(a~|s) + H_target)`, `H_target = -act_dim` (times
//!    `target_entropy_per_dim`).
//!
//! Inference of a batch-renormalised network is affine per norm, so it folds into a plain MLP
//! ([`BrnMlp::fold_into`]): the actor's inference, `actor` in the checkpoint (refolded after each
//! actor step), is what acting, evaluation, the portable policy spec and the ONNX export see,
//! an MLP of `agent.hidden` like SAC's (rule `tanh_of_mean`); the trained actor with its norms is
//! `actor_bn`. The critics are folded the same way for step 3.
//!
//! Defaults (`[agent.crossq]`, [`CrossqConfig`]), from sbx's `CrossQ` and `CrossQPolicy`:
//! `critic_hidden = [1024, 1024]` (sbx's `net_arch_qf`; the paper's 2048 wide); `n_critics = 2`;
//! `policy_delay = 3`; `adam_beta1 = 0.5` for the actor's and the critics' Adam (sbx's and the
//! original's; beta2 0.999, eps 1e-8 as optax's), the entropy coefficient's Adam the usual 0.9
//! (sbx's `optax.adam` default); `bn_momentum = 0.99` and `renorm_warmup_steps = 100 000` (sbx's
//! `batch_norm_momentum`, `renorm_warmup_steps`; epsilon 1e-3, r_max 3, d_max 5 fixed as sbx's
//! `BatchRenorm`); batch renormalisation in the actor too (sbx's `batch_norm_actor = True`);
//! `alpha_lr = 1e-3` (sbx's ent_coef optimiser runs at the learning rate), `init_alpha = 1`
//! (sbx's `"auto"`), `target_entropy_per_dim = -1`. Learning rates: `agent.actor_lr` and
//! `agent.critic_lr` default to 1e-3 (sbx's `learning_rate`; `qf_learning_rate` unset). Kept
//! from this project rather than sbx: `agent.hidden` (the actor: 64 x 64, sbx 256 x 256),
//! `agent.gamma` 0.95 (sbx 0.99; see [`AgentConfig::gamma`]), `agent.learning_starts` 1000 (sbx
//! 100), PyTorch's layer initialisation (flax's is lecun-normal weights and zero biases), and
//! the critic loss `mean (Q - y)^2` summed over the critics (sbx's `0.5 mean`; Adam does not see
//! the factor).
//!
//! With `agent.norm_obs`, the actor and the critics read observations normalised by running
//! statistics ([`super::obs_norm`]), as SAC's.

use serde::{Deserialize, Serialize};

use super::critics::ENSEMBLE;
use super::obs_norm::{batch_inputs, one_input, ObsNorm, OffPolicyNorm};
use super::parts::learned_parts;
use super::{clip, sizes, Agent, AgentConfig, Algo, OffPolicy, UpdateStats, MAX_BATCH_VALUES};
use crate::agent::replay::Batch;
use crate::base::par;
use crate::base::rng::Rng;
use crate::base::validate::{finite, positive};
use crate::nn::{
    concat_cols, Activation, Adam, BatchRenormSettings, BrnMlp, LogStdBound, Mlp, SquashedGaussian,
};
use crate::{Error, Result};

/// Most critics (`agent.crossq.n_critics`).
pub const MAX_CROSSQ_CRITICS: usize = ENSEMBLE.len();

/// `[agent.crossq]`: CrossQ's own settings (defaults: sbx's `sbx/crossq`, see docs/training.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CrossqConfig {
    /// Hidden layer widths of each critic (sbx's [1024, 1024]; the paper's 2048 wide); the
    /// actor's are agent.hidden.
    pub critic_hidden: Vec<usize>,
    /// Critics, 1..=20 (sbx: 2); the target and the actor take their minimum.
    pub n_critics: usize,
    /// Critic updates per actor and entropy-coefficient update (sbx: 3).
    pub policy_delay: u32,
    /// Adam's beta1 of the actor and the critics, in [0, 1) (sbx and the paper: 0.5).
    pub adam_beta1: f64,
    /// Momentum of the batch renormalisation's running statistics, in [0, 1) (sbx: 0.99).
    pub bn_momentum: f64,
    /// Training passes of each batch-renormalisation layer as plain batch normalisation before
    /// its corrections apply (sbx: 100000).
    pub renorm_warmup_steps: u64,
    /// Learning rate of log(alpha) (sbx: the learning rate, 1e-3).
    pub alpha_lr: f64,
    /// Initial entropy coefficient alpha.
    pub init_alpha: f64,
    /// Target entropy per action dimension (-1: -act_dim in total, sbx's "auto").
    pub target_entropy_per_dim: f64,
    /// Fix alpha at `init_alpha` instead of tuning it.
    pub fixed_alpha: bool,
}

impl Default for CrossqConfig {
    fn default() -> Self {
        CrossqConfig {
            critic_hidden: vec![1024, 1024],
            n_critics: 2,
            policy_delay: 3,
            adam_beta1: 0.5,
            bn_momentum: 0.99,
            renorm_warmup_steps: 100_000,
            alpha_lr: 1e-3,
            init_alpha: 1.0,
            target_entropy_per_dim: -1.0,
            fixed_alpha: false,
        }
    }
}

impl CrossqConfig {
    /// Check every value against a batch of `batch_size` (the critics' joint pass is twice
    /// that); the error names the field, the value and what is allowed.
    pub fn validate(&self, batch_size: usize) -> Result<()> {
        let h = &self.critic_hidden;
        if h.is_empty() || h.iter().any(|&w| w == 0 || w > 16384) {
            let allowed = "one or more layer widths, each in 1..=16384";
            return Err(Error::config("agent.crossq.critic_hidden", format!("{h:?}"), allowed));
        }
        let widest = h.iter().copied().max().unwrap_or(1);
        if batch_size.saturating_mul(2).saturating_mul(widest) > MAX_BATCH_VALUES {
            return Err(Error::config(
                "agent.batch_size",
                batch_size,
                format!(
                    "an integer with 2 x batch_size x widest critic layer ({widest}) <= {MAX_BATCH_VALUES} \
                     with agent.algo = \"crossq\" (its critics' joint pass of (s, a) and (s', a'))"
                ),
            ));
        }
        if !(1..=MAX_CROSSQ_CRITICS).contains(&self.n_critics) {
            return Err(Error::config(
                "agent.crossq.n_critics",
                self.n_critics,
                format!("an integer in 1..={MAX_CROSSQ_CRITICS}"),
            ));
        }
        if self.policy_delay == 0 {
            let allowed = "an integer >= 1 (critic updates per actor update; sbx: 3)";
            return Err(Error::config("agent.crossq.policy_delay", 0, allowed));
        }
        for (field, v, sbx) in [("adam_beta1", self.adam_beta1, 0.5), ("bn_momentum", self.bn_momentum, 0.99)]
        {
            if !(v.is_finite() && (0.0..1.0).contains(&v)) {
                let allowed = format!("a number in [0, 1) (sbx: {sbx})");
                return Err(Error::config(format!("agent.crossq.{field}"), v, allowed));
            }
        }
        positive("agent.crossq.alpha_lr", self.alpha_lr)?;
        positive("agent.crossq.init_alpha", self.init_alpha)?;
        finite("agent.crossq.target_entropy_per_dim", self.target_entropy_per_dim)
    }

    /// The settings of every batch-renormalisation layer.
    pub fn renorm(&self) -> BatchRenormSettings {
        BatchRenormSettings {
            momentum: self.bn_momentum,
            warmup_steps: self.renorm_warmup_steps,
            ..BatchRenormSettings::default()
        }
    }
}

/// The log-std range of the actor (sbx's `log_std_min`, `log_std_max`).
const LOG_STD: LogStdBound = LogStdBound::Clamp { min: -20.0, max: 2.0 };

/// One critic: the trained network, its inference (folded, for the actor's step), its
/// optimiser and buffers.
struct Critic {
    net: BrnMlp<f32>,
    eval: Mlp<f32>,
    opt: Adam<f32>,
    /// dL/dQ per row of the joint pass (`2B`), then of the actor's side (`B`).
    dq: Vec<f32>,
    /// dQ/da of the actor's side (`B x act`).
    da: Vec<f32>,
    loss: f64,
}

pub struct Crossq {
    cfg: AgentConfig,
    own: CrossqConfig,
    obs_dim: usize,
    act_dim: usize,
    /// The trained actor (`actor_bn`) and its inference (`actor`, folded from it).
    actor_bn: BrnMlp<f32>,
    actor: Mlp<f32>,
    head: SquashedGaussian<f32>,
    critics: Vec<Critic>,
    actor_opt: Adam<f32>,
    log_alpha: [f32; 1],
    alpha_opt: Adam<f32>,
    target_entropy: f32,
    rng: Rng,
    /// Updates so far (the policy delay counts them).
    updates: u64,
    /// `agent.norm_obs`: the running observation normalisation.
    norm: Option<OffPolicyNorm>,
    // Scratch, grown once to the batch size.
    eps: Vec<f32>,
    joint: Vec<f32>,
    next_act: Vec<f32>,
    logp: Vec<f32>,
    y: Vec<f32>,
    dlogp: Vec<f32>,
    argmin: Vec<u32>,
    min: Vec<f32>,
}

impl Crossq {
    pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Crossq {
        let own = cfg.crossq();
        let (b, in_q) = (cfg.batch_size, obs_dim + act_dim);
        let mut init = Rng::derived(seed, 0xC205);
        let actor_sizes = sizes(obs_dim, &cfg.hidden, 2 * act_dim);
        let mut actor_bn = BrnMlp::new(&actor_sizes, own.renorm(), &mut init);
        actor_bn.reserve(b);
        let mut actor = Mlp::new(&actor_sizes, Activation::Relu, Activation::Identity, &mut Rng::new(0));
        actor_bn.fold_into(&mut actor);
        let adam = |n, lr| Adam::with_betas(n, lr, own.adam_beta1, 0.999, 1e-8);
        let critic_sizes = sizes(in_q, &own.critic_hidden, 1);
        let critics = (0..own.n_critics)
            .map(|_| {
                let mut net = BrnMlp::new(&critic_sizes, own.renorm(), &mut init);
                net.reserve(2 * b);
                let mut eval =
                    Mlp::new(&critic_sizes, Activation::Relu, Activation::Identity, &mut Rng::new(0));
                eval.reserve(b);
                let opt = adam(net.num_params(), cfg.critic_lr());
                Critic { net, eval, opt, dq: vec![0.0; 2 * b], da: vec![0.0; b * act_dim], loss: 0.0 }
            })
            .collect();
        Crossq {
            actor_opt: adam(actor_bn.num_params(), cfg.actor_lr()),
            log_alpha: [own.init_alpha.ln() as f32],
            alpha_opt: Adam::new(1, own.alpha_lr),
            target_entropy: (own.target_entropy_per_dim * act_dim as f64) as f32,
            head: SquashedGaussian::new(act_dim, LOG_STD),
            rng: Rng::derived(seed, 0xC2051),
            updates: 0,
            norm: cfg.norm_obs.map(|n| OffPolicyNorm::new(obs_dim, &n, b)),
            eps: vec![0.0; b * act_dim],
            joint: vec![0.0; 2 * b * in_q],
            next_act: vec![0.0; b * act_dim],
            logp: vec![0.0; b],
            y: vec![0.0; b],
            dlogp: vec![0.0; b],
            argmin: vec![0; b],
            min: vec![0.0; b],
            cfg: cfg.clone(),
            own,
            obs_dim,
            act_dim,
            actor_bn,
            actor,
            critics,
        }
    }

    /// The entropy coefficient alpha.
    pub fn alpha(&self) -> f32 {
        crate::base::math::exp_f32(self.log_alpha[0])
    }

    /// Steps 1-2: the critics' joint pass and fit on `obs`, `next_obs` (normalised) of `batch`;
    /// returns the mean of their losses.
    fn critic_step(&mut self, obs: &[f32], next_obs: &[f32], batch: &Batch) -> f64 {
        let (b, od, ad) = (batch.size, self.obs_dim, self.act_dim);
        let (alpha, gamma) = (self.alpha(), self.cfg.gamma as f32);
        // 1. Next actions from the actor's inference.
        let raw_next = self.actor.predict(next_obs, b);
        self.rng.fill_normal_f32(&mut self.eps[..b * ad]);
        let (a_next, logp_next) = self.head.forward(raw_next, &self.eps[..b * ad], b);
        self.next_act[..b * ad].copy_from_slice(a_next);
        self.logp[..b].copy_from_slice(logp_next);
        // 2. The joint pass: (s, a) in the first b rows, (s', a') in the next b.
        let half = b * (od + ad);
        let (cur, next) = self.joint[..2 * half].split_at_mut(half);
        concat_cols(obs, od, &batch.act[..b * ad], ad, b, cur);
        concat_cols(next_obs, od, &self.next_act[..b * ad], ad, b, next);
        let joint = &self.joint[..2 * half];
        let mut units = vec![(); self.critics.len()];
        par::for_each_mut(&mut self.critics, &mut units, &|_, c, _| {
            c.net.forward_train(joint, 2 * b);
        });
        let y = &mut self.y[..b];
        y.copy_from_slice(&self.critics[0].net.output()[b..2 * b]);
        for c in &self.critics[1..] {
            for (m, &q) in y.iter_mut().zip(&c.net.output()[b..2 * b]) {
                *m = m.min(q);
            }
        }
        for (i, y) in y.iter_mut().enumerate() {
            let soft_v = *y - alpha * self.logp[i];
            *y = batch.reward[i] + gamma * (1.0 - batch.terminal[i]) * soft_v;
        }
        let (y, max_norm) = (&self.y[..b], self.cfg.max_grad_norm);
        par::for_each_mut(&mut self.critics, &mut units, &|_, c, _| {
            let (cur, next) = c.dq[..2 * b].split_at_mut(b);
            c.loss = f64::from(crate::nn::mse_loss(&c.net.output()[..b], y, cur));
            next.fill(0.0);
            c.net.zero_grad();
            c.net.backward(&c.dq[..2 * b]);
            clip(c.net.grads_mut(), max_norm);
            let (p, g) = c.net.params_and_grads();
            c.opt.step(p, g);
        });
        self.critics.iter().map(|c| c.loss).sum::<f64>() / self.critics.len() as f64
    }

    /// Step 3: the actor (a training pass) against the critics' inference, and the entropy
    /// coefficient; returns the actor's loss and the mean log-probability.
    fn actor_step(&mut self, obs: &[f32], b: usize) -> (f64, f64) {
        let (od, ad, alpha) = (self.obs_dim, self.act_dim, self.alpha());
        let raw = self.actor_bn.forward_train(obs, b);
        self.rng.fill_normal_f32(&mut self.eps[..b * ad]);
        let (a, logp) = self.head.forward(raw, &self.eps[..b * ad], b);
        self.logp[..b].copy_from_slice(logp);
        let input = &mut self.joint[..b * (od + ad)];
        concat_cols(obs, od, a, ad, b, input);
        let input = &self.joint[..b * (od + ad)];
        let mut units = vec![(); self.critics.len()];
        par::for_each_mut(&mut self.critics, &mut units, &|_, c, _| {
            c.net.fold_into(&mut c.eval);
            c.eval.forward(input, b);
        });
        // min_i Q_i per row (of equal values the first critic's, as SAC's).
        let (argmin, min) = (&mut self.argmin[..b], &mut self.min[..b]);
        argmin.fill(0);
        min.copy_from_slice(&self.critics[0].eval.output()[..b]);
        for (k, c) in self.critics.iter().enumerate().skip(1) {
            for ((best, m), &v) in argmin.iter_mut().zip(min.iter_mut()).zip(c.eval.output()) {
                // Kept while `m <= v` (NaN included), as SAC's `Critics::forward_min`.
                let keep = *m <= v;
                if !keep {
                    (*best, *m) = (k as u32, v);
                }
            }
        }
        let inv_b = 1.0 / b as f32;
        let mut actor_loss = 0.0f64;
        for i in 0..b {
            actor_loss += f64::from(alpha * self.logp[i] - self.min[i]);
            self.dlogp[i] = alpha * inv_b;
        }
        let argmin = &self.argmin[..b];
        par::for_each_mut(&mut self.critics, &mut units, &|k, c, _| {
            for (g, &best) in c.dq[..b].iter_mut().zip(argmin) {
                *g = if best as usize == k { -inv_b } else { 0.0 };
            }
            c.da[..b * ad].copy_from_slice(c.eval.input_grad_cols(&c.dq[..b], od..od + ad));
        });
        let (first, rest) = self.critics.split_at_mut(1);
        let da = &mut first[0].da[..b * ad];
        for c in rest.iter() {
            for (x, y) in da.iter_mut().zip(&c.da[..b * ad]) {
                *x += y;
            }
        }
        let d_raw = self.head.backward(da, &self.dlogp[..b]);
        self.actor_bn.zero_grad();
        self.actor_bn.backward(d_raw);
        clip(self.actor_bn.grads_mut(), self.cfg.max_grad_norm);
        let (p, g) = self.actor_bn.params_and_grads();
        self.actor_opt.step(p, g);
        self.actor_bn.fold_into(&mut self.actor);
        let mean_logp = self.logp[..b].iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64;
        if !self.own.fixed_alpha {
            let grad = [-(mean_logp as f32 + self.target_entropy)];
            self.alpha_opt.step(&mut self.log_alpha, &grad);
        }
        (actor_loss / b as f64, mean_logp)
    }
}

impl Agent for Crossq {
    fn algo(&self) -> Algo {
        Algo::Crossq
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
        self.rng.fill_normal_f32(eps);
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

impl OffPolicy for Crossq {
    fn observe(&mut self, obs: &[f32]) {
        if let Some(n) = &mut self.norm {
            n.observe(obs);
        }
    }

    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let b = batch.size;
        let alpha = self.alpha();
        // The normalised observations are copied out of the normaliser's buffers only when
        // set; otherwise the batch's own are read.
        let mut norm = self.norm.take();
        let (obs, next_obs) = batch_inputs(&mut norm, &batch.obs, &batch.next_obs, b);
        let critic_loss = self.critic_step(obs, next_obs, batch);
        self.updates += 1;
        let actor =
            self.updates.is_multiple_of(u64::from(self.own.policy_delay)).then(|| self.actor_step(obs, b));
        self.norm = norm;
        UpdateStats {
            critic_loss,
            actor_loss: actor.map(|a| a.0),
            alpha: Some(f64::from(alpha)),
            entropy: actor.map(|a| -a.1),
        }
    }
}

learned_parts!(Crossq, |s, f| {
    let names = &ENSEMBLE[..s.critics.len()];
    // The actor's inference (a plain MLP: the policy spec's and the export's) and the trained
    // actor with its batch renormalisation (parameters and running statistics).
    f("actor", P::Net(r!(s.actor)));
    f("actor_bn", P::BnNet(r!(s.actor_bn)));
    for (name, c) in names.iter().zip(each!(s.critics)) {
        f(name[0], P::BnNet(r!(c.net)));
    }
    f("log_alpha", P::Tensor(r!(s.log_alpha)));
    f("actor_opt", P::Adam(r!(s.actor_opt)));
    for (name, c) in names.iter().zip(each!(s.critics)) {
        f(name[2], P::Adam(r!(c.opt)));
    }
    f("alpha_opt", P::Adam(r!(s.alpha_opt)));
    f("agent_rng", P::State(r!(s.rng)));
    f("agent_updates", P::State(r!(s.updates)));
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
    use crate::agent::{AgentConfig, Algo};

    fn small(own: CrossqConfig) -> AgentConfig {
        AgentConfig {
            algo: Algo::Crossq,
            hidden: vec![16, 16],
            batch_size: 8,
            crossq: Some(own),
            ..AgentConfig::default()
        }
    }

    #[test]
    fn bad_settings_are_refused_naming_the_field_the_value_and_what_is_allowed() {
        let d = CrossqConfig::default;
        for (bad, field, value, allowed) in [
            (CrossqConfig { bn_momentum: 1.5, ..d() }, "agent.crossq.bn_momentum", "1.5", "[0, 1)"),
            (CrossqConfig { bn_momentum: f64::NAN, ..d() }, "agent.crossq.bn_momentum", "NaN", "[0, 1)"),
            (CrossqConfig { adam_beta1: 1.0, ..d() }, "agent.crossq.adam_beta1", "1", "[0, 1)"),
            (CrossqConfig { adam_beta1: -0.5, ..d() }, "agent.crossq.adam_beta1", "-0.5", "[0, 1)"),
            (CrossqConfig { policy_delay: 0, ..d() }, "agent.crossq.policy_delay", "0", ">= 1"),
            (CrossqConfig { n_critics: 0, ..d() }, "agent.crossq.n_critics", "0", "1..=20"),
            (CrossqConfig { n_critics: 21, ..d() }, "agent.crossq.n_critics", "21", "1..=20"),
            (CrossqConfig { critic_hidden: vec![], ..d() }, "agent.crossq.critic_hidden", "[]", "1..=16384"),
            (
                CrossqConfig { critic_hidden: vec![64, 0], ..d() },
                "agent.crossq.critic_hidden",
                "[64, 0]",
                "1..=16384",
            ),
            (CrossqConfig { alpha_lr: 0.0, ..d() }, "agent.crossq.alpha_lr", "0", ""),
            (CrossqConfig { init_alpha: -1.0, ..d() }, "agent.crossq.init_alpha", "-1", ""),
            (
                CrossqConfig { target_entropy_per_dim: f64::INFINITY, ..d() },
                "agent.crossq.target_entropy_per_dim",
                "inf",
                "",
            ),
        ] {
            let e = small(bad).validate().unwrap_err().to_string();
            assert!(e.contains(field) && e.contains(value) && e.contains(allowed), "{e}");
        }
        // The joint pass is twice the batch: refused by the batch size, at CrossQ's defaults too.
        let big = AgentConfig { batch_size: 200_000, ..AgentConfig::new(Algo::Crossq) };
        let e = big.validate().unwrap_err().to_string();
        assert!(
            e.contains("agent.batch_size") && e.contains("2 x batch_size x widest critic layer (1024)"),
            "{e}"
        );
        AgentConfig { batch_size: 200_000, ..AgentConfig::new(Algo::Sac) }.validate().unwrap();
        // From an `[agent]` table: the field named; another algorithm's run refuses the section.
        let parse = |t: &str| toml::from_str::<AgentConfig>(t).map_err(|e| e.to_string());
        let e = parse("algo = \"crossq\"\n[crossq]\nbn_momentum = 1.5\n")
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("agent.crossq.bn_momentum") && e.contains("1.5") && e.contains("[0, 1)"), "{e}");
        let e = parse("algo = \"sac\"\n[crossq]\npolicy_delay = 2\n")
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("agent.crossq") && e.contains("[agent.sac]"), "{e}");
        let e = parse("algo = \"crossq\"\n[crossq]\ntau = 0.1\n").unwrap_err();
        assert!(e.contains("tau"), "{e}");
        let e = "crossqq".parse::<Algo>().unwrap_err().to_string();
        assert!(e.contains("crossq"), "{e}");
        // The defaults: sbx's.
        let c = CrossqConfig::default();
        assert_eq!((c.critic_hidden, c.n_critics, c.policy_delay), (vec![1024, 1024], 2, 3));
        assert_eq!((c.adam_beta1, c.bn_momentum, c.renorm_warmup_steps), (0.5, 0.99, 100_000));
        assert_eq!(AgentConfig::new(Algo::Crossq).actor_lr(), 1e-3);
    }

    #[test]
    fn the_critics_pass_once_per_update_over_both_halves_and_the_actor_every_policy_delay() {
        let own = CrossqConfig { critic_hidden: vec![32, 32], ..CrossqConfig::default() };
        let cfg = small(own);
        let (od, ad, b) = (5, 2, 8);
        let mut agent = Crossq::new(&cfg, od, ad, 3);
        let mut rng = Rng::new(4);
        let mut batch = Batch::new(b, od, ad);
        for x in batch.obs.iter_mut().chain(&mut batch.next_obs).chain(&mut batch.act) {
            *x = rng.uniform_range(-1.0, 1.0) as f32;
        }
        // The next observations far from the current ones: the joint statistics are the mean of
        // both halves' (the first norm sees the inputs themselves).
        for x in &mut batch.next_obs {
            *x += 10.0;
        }
        let obs = [0.3f32; 5];
        let (mut before, mut after) = ([0.0f32; 2], [0.0f32; 2]);
        for k in 1..=7u64 {
            agent.predict(&obs, &mut before);
            let s = agent.update(&batch);
            agent.predict(&obs, &mut after);
            let actor_step = k % 3 == 0;
            assert_eq!(s.actor_loss.is_some(), actor_step, "update {k}");
            assert_eq!(before != after, actor_step, "update {k}: the actor moves only at its steps");
            for c in &agent.critics {
                assert!(c.net.norms.iter().all(|n| n.stats.steps == k), "one critic pass per update");
            }
            assert!(agent.actor_bn.norms.iter().all(|n| n.stats.steps == k / 3), "update {k}");
        }
        // The first norm's running mean after 7 passes from 0 at momentum 0.99: 1 - 0.99^7 of the
        // joint batch mean of observation 0 (current and next halves).
        let n = b as f64;
        let joint: f64 =
            (0..b).map(|r| f64::from(batch.obs[r * od]) + f64::from(batch.next_obs[r * od])).sum::<f64>()
                / (2.0 * n);
        let ra = agent.critics[0].net.norms[0].stats.mean[0];
        assert!((ra - (1.0 - 0.99f64.powi(7)) * joint).abs() < 1e-9, "{ra} vs {joint}");
    }
}
