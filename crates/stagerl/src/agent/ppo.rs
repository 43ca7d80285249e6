//! Proximal Policy Optimization (Schulman et al. 2017) with a clipped surrogate, as CleanRL's
//! `ppo_continuous_action`: an on-policy learner over several environments stepped together.
//!
//! Networks: a Gaussian actor `obs -> mean` (tanh hidden units, linear output) with a
//! state-independent log standard deviation `log sigma` (one learned value per joint), and a
//! critic `obs -> V(s)`. Actions are sampled unclipped, `a = mean + sigma * eps`, and the
//! environment clips them to [-1, 1]; the deterministic action is `clip(mean, -1, 1)`.
//!
//! One update on a rollout of `T` steps of `n` environments:
//! 1. GAE (Schulman et al. 2016): `delta_t = r_t + gamma (1 - done_t) V(s_{t+1}) - V(s_t)`,
//!    `A_t = delta_t + gamma lambda (1 - done_t) A_{t+1}`, returns `R_t = A_t + V(s_t)`; a step
//!    truncated by the time limit has `gamma V(s_final)` added to its reward at collection, so
//!    the time limit is bootstrapped through, not taken for a terminal state;
//! 2. for `update_epochs` passes, the shuffled rollout in `num_minibatches` minibatches, each:
//!    ratio `rho = exp(log pi(a|s) - log pi_old(a|s))`, advantages normalised in the minibatch
//!    (`norm_adv`), policy loss `L_pi = mean max(-A rho, -A clip(rho, 1 - eps, 1 + eps))`;
//! 3. value loss `L_V = 1/2 mean max((V - R)^2, (V_old + clip(V - V_old, -eps, eps) - R)^2)`
//!    (`clip_vloss`; else `1/2 mean (V - R)^2`);
//! 4. entropy of the diagonal Gaussian `H = sum_j (log sigma_j + 1/2 log(2 pi e))`;
//! 5. one Adam step (eps 1e-5) on `L_pi - ent_coef H + vf_coef L_V`, the gradient clipped to
//!    one global norm over every parameter (`[agent.ppo] max_grad_norm` > 0).
//!
//! With `norm_obs`, both networks read observations normalised by running statistics
//! ([`super::obs_norm`]), updated on each batch the policy acts on in training; the rollout
//! keeps the normalised observations, as CleanRL's does.
//!
//! Its own settings: `[agent.ppo]`, [`PpoConfig`].

use serde::{Deserialize, Serialize};

use super::obs_norm::{ObsNorm, ObsNormConfig};
use super::parts::learned_parts;
use super::{sizes, Agent, AgentConfig, Algo, UpdateStats};
use crate::base::rng::Rng;
use crate::base::validate::{at_least_one, non_negative, positive};
use crate::nn::{Activation, Adam, Mlp};
use crate::{Error, Result};

/// `[agent.ppo]`: PPO's rollouts and clipped update (defaults: CleanRL's
/// `ppo_continuous_action` where the task allows; see each field). PPO uses the shared `hidden`
/// (tanh units, as CleanRL), `actor_lr` and `critic_lr` (default 3e-4) and `gamma`; the shared
/// `max_grad_norm` (per network) and the replay settings (`batch_size`, `buffer_size`,
/// `learning_starts`, `updates_per_step`, `tau`) are the off-policy agents' and unused.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Environments stepped together (CleanRL: 1; 8 here, as a reaching episode is short).
    pub num_envs: usize,
    /// Steps per environment per rollout: a rollout is `num_envs x num_steps` transitions
    /// (CleanRL: 1 x 2048; 8 x 256 = 2048 here).
    pub num_steps: usize,
    /// Passes over each rollout.
    pub update_epochs: u32,
    /// Minibatches per pass (the rollout is split into this many).
    pub num_minibatches: usize,
    /// GAE lambda.
    pub gae_lambda: f64,
    /// Clip range epsilon of the probability ratio (and of the value change, `clip_vloss`).
    pub clip_coef: f64,
    /// Clip the value loss around the rollout's values.
    pub clip_vloss: bool,
    /// Entropy bonus coefficient.
    pub ent_coef: f64,
    /// Value loss coefficient.
    pub vf_coef: f64,
    /// Normalise the advantages of each minibatch.
    pub norm_adv: bool,
    /// Decay the learning rates linearly to 0 over the run's episodes.
    pub anneal_lr: bool,
    /// Initial log standard deviation of the (state-independent) Gaussian policy.
    pub init_log_std: f64,
    /// Clip the gradient of all PPO's parameters together to this L2 norm (CleanRL: 0.5); 0
    /// disables.
    pub max_grad_norm: f64,
    /// `norm_obs = { clip = 10.0 }`: normalise observations with running statistics
    /// ([`super::obs_norm`]; CleanRL always does); unset: off (written only when set, so that
    /// earlier runs' configs keep their hash).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub norm_obs: Option<ObsNormConfig>,
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            num_envs: 8,
            num_steps: 256,
            update_epochs: 10,
            num_minibatches: 32,
            gae_lambda: 0.95,
            clip_coef: 0.2,
            clip_vloss: true,
            ent_coef: 0.0,
            vf_coef: 0.5,
            norm_adv: true,
            anneal_lr: true,
            init_log_std: 0.0,
            max_grad_norm: 0.5,
            norm_obs: None,
        }
    }
}

/// Most environments PPO steps together.
pub const MAX_PPO_ENVS: usize = 4096;

/// Most transitions in one PPO rollout.
pub const MAX_PPO_ROLLOUT: usize = 1 << 22;

impl PpoConfig {
    /// Check every value; the error names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        if self.num_envs == 0 || self.num_envs > MAX_PPO_ENVS {
            return Err(Error::config(
                "agent.ppo.num_envs",
                self.num_envs,
                format!("an integer in 1..={MAX_PPO_ENVS}"),
            ));
        }
        let rollout = self.num_envs.saturating_mul(self.num_steps);
        if self.num_steps == 0 || rollout > MAX_PPO_ROLLOUT {
            return Err(Error::config(
                "agent.ppo.num_steps",
                self.num_steps,
                format!(
                    "an integer >= 1 with num_envs x num_steps <= {MAX_PPO_ROLLOUT} transitions a rollout"
                ),
            ));
        }
        if self.num_minibatches == 0 || self.num_minibatches > rollout {
            return Err(Error::config(
                "agent.ppo.num_minibatches",
                self.num_minibatches,
                format!("an integer in 1..={rollout} (num_envs x num_steps, the rollout's transitions)"),
            ));
        }
        at_least_one("agent.ppo.update_epochs", self.update_epochs.into())?;
        if !(self.gae_lambda.is_finite() && (0.0..=1.0).contains(&self.gae_lambda)) {
            return Err(Error::config("agent.ppo.gae_lambda", self.gae_lambda, "a number in [0, 1]"));
        }
        positive("agent.ppo.clip_coef", self.clip_coef)?;
        non_negative("agent.ppo.ent_coef", self.ent_coef)?;
        non_negative("agent.ppo.vf_coef", self.vf_coef)?;
        non_negative("agent.ppo.max_grad_norm", self.max_grad_norm)?;
        if !(self.init_log_std.is_finite() && (-20.0..=2.0).contains(&self.init_log_std)) {
            return Err(Error::config("agent.ppo.init_log_std", self.init_log_std, "a number in [-20, 2]"));
        }
        if let Some(n) = &self.norm_obs {
            n.validate("agent.ppo.norm_obs")?;
        }
        Ok(())
    }
}

/// `1/2 log(2 pi)`.
const HALF_LOG_2PI: f64 = 0.918_938_533_204_672_7;

pub struct Ppo {
    cfg: AgentConfig,
    p: PpoConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp<f32>,
    log_std: Vec<f32>,
    log_std_grad: Vec<f32>,
    critic: Mlp<f32>,
    actor_opt: Adam<f32>,
    log_std_opt: Adam<f32>,
    critic_opt: Adam<f32>,
    rng: Rng,
    /// `norm_obs`: the running observation normalisation.
    obs_norm: Option<ObsNorm>,
    /// Scratch: one normalised observation (`act`, `predict`).
    norm_buf: Vec<f32>,
    // Scratch, grown once to the minibatch size.
    idx: Vec<usize>,
    mb_obs: Vec<f32>,
    mb_act: Vec<f32>,
    mb_adv: Vec<f32>,
    d_mean: Vec<f32>,
    d_v: Vec<f32>,
    eps: Vec<f32>,
    /// sigma_j = exp(log sigma_j) of a minibatch, and z_j of one of its rows.
    sigma: Vec<f64>,
    z: Vec<f64>,
}

/// What one PPO update measured (the means over its minibatches).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PpoStats {
    pub policy_loss: f64,
    pub value_loss: f64,
    pub entropy: f64,
    /// `mean((rho - 1) - log rho)`, the estimator CleanRL logs.
    pub approx_kl: f64,
    /// Fraction of samples whose ratio was clipped.
    pub clip_fraction: f64,
    /// Gradient steps taken.
    pub steps: u64,
}

impl Ppo {
    pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Ppo {
        let mut init = Rng::derived(seed, 0x990);
        let actor = Mlp::new(
            &sizes(obs_dim, &cfg.hidden, act_dim),
            Activation::Tanh,
            Activation::Identity,
            &mut init,
        );
        let critic =
            Mlp::new(&sizes(obs_dim, &cfg.hidden, 1), Activation::Tanh, Activation::Identity, &mut init);
        let p = cfg.ppo();
        let adam = |n: usize, lr: f64| Adam::with_betas(n, lr, 0.9, 0.999, 1e-5);
        Ppo {
            actor_opt: adam(actor.num_params(), cfg.actor_lr()),
            log_std_opt: adam(act_dim, cfg.actor_lr()),
            critic_opt: adam(critic.num_params(), cfg.critic_lr()),
            log_std: vec![p.init_log_std as f32; act_dim],
            log_std_grad: vec![0.0; act_dim],
            actor,
            critic,
            rng: Rng::derived(seed, 0x991),
            obs_norm: p.norm_obs.map(|n| ObsNorm::new(obs_dim, &n)),
            norm_buf: vec![0.0; obs_dim],
            cfg: cfg.clone(),
            p,
            obs_dim,
            act_dim,
            idx: Vec::new(),
            mb_obs: Vec::new(),
            mb_act: Vec::new(),
            mb_adv: Vec::new(),
            d_mean: Vec::new(),
            d_v: Vec::new(),
            eps: Vec::new(),
            sigma: Vec::new(),
            z: Vec::new(),
        }
    }

    /// PPO's settings.
    pub fn config(&self) -> &PpoConfig {
        &self.p
    }

    /// The observations the networks read: `raw` itself, or (`norm_obs`) `raw` normalised into
    /// `buf`, the running statistics first updated with it when `update` (training collection).
    pub fn normalized<'a>(
        &mut self,
        raw: &'a [f32],
        n: usize,
        update: bool,
        buf: &'a mut Vec<f32>,
    ) -> &'a [f32] {
        match &mut self.obs_norm {
            None => raw,
            Some(norm) => {
                if update {
                    norm.update(raw, n);
                }
                buf.resize(n * self.obs_dim, 0.0);
                norm.apply(&raw[..n * self.obs_dim], buf);
                buf
            }
        }
    }

    /// Sample an action for each of the `n` observations in `obs` (row-major, as
    /// [`Ppo::normalized`] returns them): `actions` unclipped (`n x act_dim`), their
    /// log-probabilities and the critic's values.
    pub fn act_batch(
        &mut self,
        obs: &[f32],
        n: usize,
        actions: &mut [f32],
        logp: &mut [f32],
        values: &mut [f32],
    ) {
        let ad = self.act_dim;
        self.eps.resize(n * ad, 0.0);
        self.rng.fill_normal_f32(&mut self.eps);
        let mean = self.actor.predict(obs, n);
        for i in 0..n {
            let mut lp = 0.0f64;
            for j in 0..ad {
                let (e, ls) = (self.eps[i * ad + j], self.log_std[j]);
                actions[i * ad + j] = mean[i * ad + j] + ls.exp() * e;
                lp += -0.5 * f64::from(e) * f64::from(e) - f64::from(ls) - HALF_LOG_2PI;
            }
            logp[i] = lp as f32;
        }
        values[..n].copy_from_slice(self.critic.predict(obs, n));
    }

    /// The critic's values of `n` observations (as [`Ppo::normalized`] returns them).
    pub fn values(&mut self, obs: &[f32], n: usize, out: &mut [f32]) {
        out[..n].copy_from_slice(self.critic.predict(obs, n));
    }

    /// Set the learning rates to `fraction` of the configured ones (`anneal_lr`).
    pub fn set_lr_fraction(&mut self, fraction: f64) {
        self.actor_opt.lr = fraction * self.cfg.actor_lr();
        self.log_std_opt.lr = fraction * self.cfg.actor_lr();
        self.critic_opt.lr = fraction * self.cfg.critic_lr();
    }

    /// Steps 1-5 on a full rollout; `last_values` are the critic's values of the observations
    /// the environments stand at after it (one per environment).
    pub fn update(&mut self, r: &mut Rollout, last_values: &[f32]) -> PpoStats {
        // 1. GAE and returns.
        r.advantages(self.cfg.gamma, self.p.gae_lambda, last_values);
        let n = r.len();
        let m = n.div_ceil(self.p.num_minibatches);
        let mut acc = PpoStats::default();
        self.idx.clear();
        self.idx.extend(0..n);
        for _ in 0..self.p.update_epochs {
            // Fisher-Yates with the agent's stream.
            for i in (1..n).rev() {
                let j = self.rng.below(i as u64 + 1) as usize;
                self.idx.swap(i, j);
            }
            for start in (0..n).step_by(m) {
                let rows = start..(start + m).min(n);
                let s = self.minibatch(r, rows);
                acc.policy_loss += s.policy_loss;
                acc.value_loss += s.value_loss;
                acc.entropy += s.entropy;
                acc.approx_kl += s.approx_kl;
                acc.clip_fraction += s.clip_fraction;
                acc.steps += 1;
            }
        }
        let k = acc.steps.max(1) as f64;
        PpoStats {
            policy_loss: acc.policy_loss / k,
            value_loss: acc.value_loss / k,
            entropy: acc.entropy / k,
            approx_kl: acc.approx_kl / k,
            clip_fraction: acc.clip_fraction / k,
            steps: acc.steps,
        }
    }

    /// Steps 2-5 on the rollout rows `self.idx[rows]`.
    fn minibatch(&mut self, r: &Rollout, rows: std::ops::Range<usize>) -> PpoStats {
        self.gather(r, rows.clone());
        let inv_b = 1.0 / rows.len() as f64;
        let (policy_loss, approx_kl, clipped) = self.policy_gradients(r, rows.clone());
        // 4. The entropy bonus: dH/d log sigma_j = 1, the same for every row.
        let entropy: f64 = self.log_std.iter().map(|&l| f64::from(l) + HALF_LOG_2PI + 0.5).sum();
        for g in &mut self.log_std_grad {
            *g -= self.p.ent_coef as f32;
        }
        let value_loss = self.value_gradients(r, rows);
        self.apply_gradients();
        PpoStats {
            policy_loss,
            value_loss,
            entropy,
            approx_kl,
            clip_fraction: clipped as f64 * inv_b,
            steps: 1,
        }
    }

    /// The minibatch's observations, actions and (normalised, `norm_adv`) advantages.
    fn gather(&mut self, r: &Rollout, rows: std::ops::Range<usize>) {
        let (od, ad, b) = (self.obs_dim, self.act_dim, rows.len());
        self.mb_obs.clear();
        self.mb_act.clear();
        self.mb_adv.clear();
        for &k in &self.idx[rows] {
            self.mb_obs.extend_from_slice(&r.obs[k * od..(k + 1) * od]);
            self.mb_act.extend_from_slice(&r.actions[k * ad..(k + 1) * ad]);
            self.mb_adv.push(r.adv[k]);
        }
        if self.p.norm_adv && b > 1 {
            let mean = self.mb_adv.iter().map(|&a| f64::from(a)).sum::<f64>() / b as f64;
            let var =
                self.mb_adv.iter().map(|&a| (f64::from(a) - mean).powi(2)).sum::<f64>() / (b - 1) as f64;
            let sd = var.sqrt() + 1e-8;
            self.mb_adv.iter_mut().for_each(|a| *a = ((f64::from(*a) - mean) / sd) as f32);
        }
    }

    /// Step 2: the policy loss and its gradients (w.r.t. the mean, into `d_mean`, and log sigma);
    /// returns (loss, approximate KL, clipped samples).
    fn policy_gradients(&mut self, r: &Rollout, rows: std::ops::Range<usize>) -> (f64, f64, usize) {
        let (ad, b, eps) = (self.act_dim, rows.len(), self.p.clip_coef);
        let inv_b = 1.0 / b as f64;
        self.d_mean.resize(b * ad, 0.0);
        self.log_std_grad.fill(0.0);
        self.sigma.clear();
        self.sigma.extend(self.log_std.iter().map(|&l| f64::from(l).exp()));
        self.z.resize(ad, 0.0);
        let (mut pg, mut kl, mut clipped) = (0.0, 0.0, 0usize);
        let mean = self.actor.forward(&self.mb_obs, b);
        for (row, &k) in self.idx[rows].iter().enumerate() {
            // z_j = (a_j - mean_j) / sigma_j, once per row.
            for j in 0..ad {
                self.z[j] =
                    (f64::from(self.mb_act[row * ad + j]) - f64::from(mean[row * ad + j])) / self.sigma[j];
            }
            let logp: f64 = (0..ad)
                .map(|j| -0.5 * self.z[j] * self.z[j] - f64::from(self.log_std[j]) - HALF_LOG_2PI)
                .sum();
            let log_ratio = logp - f64::from(r.logp[k]);
            let ratio = log_ratio.exp();
            let adv = f64::from(self.mb_adv[row]);
            let (l1, l2) = (-adv * ratio, -adv * ratio.clamp(1.0 - eps, 1.0 + eps));
            pg += l1.max(l2) * inv_b;
            kl += ((ratio - 1.0) - log_ratio) * inv_b;
            let inside = (1.0 - eps..=1.0 + eps).contains(&ratio);
            clipped += usize::from(!inside);
            // dL/dlogp = dL/drho * rho; the clipped branch has no gradient outside the range.
            let d_logp = if l1 >= l2 || inside { -adv * ratio * inv_b } else { 0.0 };
            for j in 0..ad {
                // d logp / d mean = z / sigma; d logp / d log sigma = z^2 - 1.
                let (z, sigma) = (self.z[j], self.sigma[j]);
                self.d_mean[row * ad + j] = (d_logp * z / sigma) as f32;
                self.log_std_grad[j] += (d_logp * (z * z - 1.0)) as f32;
            }
        }
        (pg, kl, clipped)
    }

    /// Step 3: the value loss, its gradient (times `vf_coef`) into `d_v`.
    fn value_gradients(&mut self, r: &Rollout, rows: std::ops::Range<usize>) -> f64 {
        let (b, eps) = (rows.len(), self.p.clip_coef);
        let inv_b = 1.0 / b as f64;
        self.d_v.resize(b, 0.0);
        let mut vloss = 0.0;
        let v = self.critic.forward(&self.mb_obs, b);
        for (row, &k) in self.idx[rows].iter().enumerate() {
            let (v, v_old, ret) = (f64::from(v[row]), f64::from(r.values[k]), f64::from(r.returns[k]));
            let unclipped = (v - ret).powi(2);
            let clipped_v = v_old + (v - v_old).clamp(-eps, eps);
            let clipped = (clipped_v - ret).powi(2);
            let grad = if !self.p.clip_vloss || unclipped >= clipped {
                vloss += 0.5 * unclipped * inv_b;
                v - ret
            } else {
                vloss += 0.5 * clipped * inv_b;
                if (v - v_old).abs() < eps {
                    clipped_v - ret
                } else {
                    0.0
                }
            };
            self.d_v[row] = (self.p.vf_coef * grad * inv_b) as f32;
        }
        vloss
    }

    /// Step 5: backward through both networks, one global clip, Adam.
    fn apply_gradients(&mut self) {
        self.actor.zero_grad();
        self.actor.backward(&self.d_mean);
        self.critic.zero_grad();
        self.critic.backward(&self.d_v);
        if self.p.max_grad_norm > 0.0 {
            let sq = |g: &[f32]| g.iter().map(|&x| f64::from(x) * f64::from(x)).sum::<f64>();
            let norm = (sq(self.actor.grads()) + sq(self.critic.grads()) + sq(&self.log_std_grad)).sqrt();
            let coef = self.p.max_grad_norm / (norm + 1e-6);
            if coef < 1.0 {
                let c = coef as f32;
                self.actor.grads_mut().iter_mut().for_each(|g| *g *= c);
                self.critic.grads_mut().iter_mut().for_each(|g| *g *= c);
                self.log_std_grad.iter_mut().for_each(|g| *g *= c);
            }
        }
        let (p, g) = self.actor.params_and_grads();
        self.actor_opt.step(p, g);
        let (p, g) = self.critic.params_and_grads();
        self.critic_opt.step(p, g);
        self.log_std_opt.step(&mut self.log_std, &self.log_std_grad);
    }
}

impl Agent for Ppo {
    fn algo(&self) -> Algo {
        Algo::Ppo
    }
    fn act_dim(&self) -> usize {
        self.act_dim
    }
    fn actor(&self) -> &Mlp<f32> {
        &self.actor
    }
    /// A sampled action, clipped to [-1, 1] (training collects through [`Ppo::act_batch`]; the
    /// normalisation's statistics are not updated here).
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        let (mut logp, mut value) = ([0.0f32], [0.0f32]);
        let mut buf = std::mem::take(&mut self.norm_buf);
        let x = self.normalized(obs, 1, false, &mut buf);
        self.act_batch(x, 1, action, &mut logp, &mut value);
        self.norm_buf = buf;
        action.iter_mut().for_each(|a| *a = a.clamp(-1.0, 1.0));
    }
    /// `clip(mean, -1, 1)` of the (normalised) observation.
    fn predict(&mut self, obs: &[f32], action: &mut [f32]) {
        let x = match &self.obs_norm {
            None => obs,
            Some(norm) => {
                norm.apply(obs, &mut self.norm_buf);
                &self.norm_buf
            }
        };
        let mean = self.actor.predict(x, 1);
        for (a, m) in action.iter_mut().zip(mean) {
            *a = m.clamp(-1.0, 1.0);
        }
    }
    fn obs_norm(&self) -> Option<&ObsNorm> {
        self.obs_norm.as_ref()
    }
}

learned_parts!(Ppo, |s, f| {
    f("actor", P::Net(r!(s.actor)));
    f("critic", P::Net(r!(s.critic)));
    f("log_std", P::Tensor(r!(s.log_std)));
    f("actor_opt", P::Adam(r!(s.actor_opt)));
    f("critic_opt", P::Adam(r!(s.critic_opt)));
    f("log_std_opt", P::Adam(r!(s.log_std_opt)));
    f("agent_rng", P::State(r!(s.rng)));
    if let Some(n) = r!(s.obs_norm) {
        f("obs_norm", P::State(r!(*n)));
        f(super::obs_norm::MEAN_TENSOR, P::Tensor(r!(n.mean)));
        f(super::obs_norm::STD_TENSOR, P::Tensor(r!(n.std)));
    }
});

/// One rollout: `num_steps` steps of `num_envs` environments, row `t * num_envs + i` for step
/// `t` of environment `i`, filled as the environments step (`t` steps so far).
#[derive(Clone, Debug, PartialEq)]
pub struct Rollout {
    pub num_envs: usize,
    pub num_steps: usize,
    obs_dim: usize,
    act_dim: usize,
    /// Steps recorded.
    pub t: usize,
    pub obs: Vec<f32>,
    /// Sampled (unclipped) actions.
    pub actions: Vec<f32>,
    pub logp: Vec<f32>,
    pub values: Vec<f32>,
    /// Rewards (bonus included; `gamma V(s_final)` added at a truncation).
    pub rewards: Vec<f32>,
    /// 1 where the episode ended with the step (terminated or truncated).
    pub dones: Vec<f32>,
    adv: Vec<f32>,
    returns: Vec<f32>,
}

impl Rollout {
    /// Checkpoint names of the arrays kept between updates, in [`Rollout::arrays`] order.
    pub const ARRAY_NAMES: [&'static str; 6] =
        ["ppo.obs", "ppo.actions", "ppo.logp", "ppo.values", "ppo.rewards", "ppo.dones"];

    pub fn new(p: &PpoConfig, obs_dim: usize, act_dim: usize) -> Rollout {
        let n = p.num_envs * p.num_steps;
        Rollout {
            num_envs: p.num_envs,
            num_steps: p.num_steps,
            obs_dim,
            act_dim,
            t: 0,
            obs: vec![0.0; n * obs_dim],
            actions: vec![0.0; n * act_dim],
            logp: vec![0.0; n],
            values: vec![0.0; n],
            rewards: vec![0.0; n],
            dones: vec![0.0; n],
            adv: vec![0.0; n],
            returns: vec![0.0; n],
        }
    }

    /// Transitions in a full rollout.
    pub fn len(&self) -> usize {
        self.num_envs * self.num_steps
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every step recorded: time to update.
    pub fn is_full(&self) -> bool {
        self.t == self.num_steps
    }

    /// Record step `t`'s observations, actions, log-probabilities and values (one row per
    /// environment); [`Rollout::record_outcome`] completes it.
    pub fn record_step(&mut self, obs: &[f32], actions: &[f32], logp: &[f32], values: &[f32]) {
        let (n, t) = (self.num_envs, self.t);
        self.obs[t * n * self.obs_dim..(t + 1) * n * self.obs_dim].copy_from_slice(obs);
        self.actions[t * n * self.act_dim..(t + 1) * n * self.act_dim].copy_from_slice(actions);
        self.logp[t * n..(t + 1) * n].copy_from_slice(logp);
        self.values[t * n..(t + 1) * n].copy_from_slice(values);
    }

    /// Environment `i`'s reward and end at step `t`.
    pub fn record_outcome(&mut self, i: usize, reward: f64, done: bool) {
        let k = self.t * self.num_envs + i;
        self.rewards[k] = reward as f32;
        self.dones[k] = f32::from(u8::from(done));
    }

    /// Step 1: advantages and returns of the full rollout.
    fn advantages(&mut self, gamma: f64, lambda: f64, last_values: &[f32]) {
        let n = self.num_envs;
        for i in 0..n {
            let mut gae = 0.0f64;
            for t in (0..self.num_steps).rev() {
                let k = t * n + i;
                let next_v = if t + 1 == self.num_steps { last_values[i] } else { self.values[k + n] };
                let live = 1.0 - f64::from(self.dones[k]);
                let delta =
                    f64::from(self.rewards[k]) + gamma * live * f64::from(next_v) - f64::from(self.values[k]);
                gae = delta + gamma * lambda * live * gae;
                self.adv[k] = gae as f32;
                self.returns[k] = (gae + f64::from(self.values[k])) as f32;
            }
        }
    }

    /// The recorded rows of each array (for checkpoints), in [`Rollout::ARRAY_NAMES`] order.
    pub fn arrays(&self) -> [&[f32]; 6] {
        let rows = self.t * self.num_envs;
        [
            &self.obs[..rows * self.obs_dim],
            &self.actions[..rows * self.act_dim],
            &self.logp[..rows],
            &self.values[..rows],
            &self.rewards[..rows],
            &self.dones[..rows],
        ]
    }

    /// Restore `t` recorded steps from [`Rollout::arrays`]; an error if the shapes differ.
    pub fn restore(&mut self, t: usize, arrays: [&[f32]; 6]) -> crate::Result<()> {
        let rows = t * self.num_envs;
        let widths = [self.obs_dim, self.act_dim, 1, 1, 1, 1];
        if t > self.num_steps || arrays.iter().zip(widths).any(|(a, w)| a.len() != rows * w) {
            return Err(crate::Error::InvalidInput(format!(
                "PPO rollout state of {t} steps does not fit this rollout ({} steps of {} environments)",
                self.num_steps, self.num_envs
            )));
        }
        self.t = t;
        let dst: [&mut Vec<f32>; 6] = [
            &mut self.obs,
            &mut self.actions,
            &mut self.logp,
            &mut self.values,
            &mut self.rewards,
            &mut self.dones,
        ];
        for (d, a) in dst.into_iter().zip(arrays) {
            d[..a.len()].copy_from_slice(a);
        }
        Ok(())
    }
}

impl From<PpoStats> for UpdateStats {
    fn from(s: PpoStats) -> UpdateStats {
        UpdateStats {
            critic_loss: s.value_loss,
            actor_loss: Some(s.policy_loss),
            alpha: None,
            entropy: Some(s.entropy),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// GAE by hand on a two-environment rollout: an episode end stops the sum, the last step
    /// bootstraps from `last_values`.
    #[test]
    fn gae_by_hand() {
        let p = PpoConfig { num_envs: 2, num_steps: 3, ..PpoConfig::default() };
        let mut r = Rollout::new(&p, 1, 1);
        let values = [[1.0, 2.0], [0.5, 1.0], [0.0, 3.0]];
        let rewards = [[1.0, 0.0], [2.0, 1.0], [3.0, -1.0]];
        let dones = [[false, false], [true, false], [false, false]];
        for t in 0..3 {
            r.record_step(&[0.0, 0.0], &[0.0, 0.0], &[0.0, 0.0], &values[t]);
            for i in 0..2 {
                r.record_outcome(i, rewards[t][i], dones[t][i]);
            }
            r.t += 1;
        }
        let (g, l) = (0.9, 0.5);
        r.advantages(g, l, &[4.0, 2.0]);
        // Environment 0: step 2 bootstraps from 4; step 1 ended its episode; step 0 from step 1.
        let d2 = 3.0 + g * 4.0 - 0.0;
        let d1 = 2.0 - 0.5;
        let d0 = 1.0 + g * 0.5 - 1.0;
        let a0 = [d0 + g * l * d1, d1, d2];
        // Environment 1: no end.
        let e2 = -1.0 + g * 2.0 - 3.0;
        let e1 = 1.0 + g * 3.0 - 1.0;
        let e0 = 0.0 + g * 1.0 - 2.0;
        let a1 = [e0 + g * l * (e1 + g * l * e2), e1 + g * l * e2, e2];
        for t in 0..3 {
            assert!((f64::from(r.adv[2 * t]) - a0[t]).abs() < 1e-6, "env 0 step {t}");
            assert!((f64::from(r.adv[2 * t + 1]) - a1[t]).abs() < 1e-6, "env 1 step {t}");
            assert!((r.returns[2 * t] - (r.adv[2 * t] + values[t][0])).abs() < 1e-6);
        }
    }

    /// Sampled actions' log-probabilities are the diagonal Gaussian's, and the values the
    /// critic's.
    #[test]
    fn act_batch_log_probs_are_the_gaussians() {
        let cfg = AgentConfig { algo: Algo::Ppo, hidden: vec![8], ..AgentConfig::default() };
        let mut ppo = Ppo::new(&cfg, 3, 2, 1);
        ppo.log_std = vec![-0.5, 0.3];
        let obs = [0.1, -0.2, 0.3, 0.5, 0.0, -0.4];
        let (mut a, mut lp, mut v) = ([0.0; 4], [0.0; 2], [0.0; 2]);
        ppo.act_batch(&obs, 2, &mut a, &mut lp, &mut v);
        let mean = ppo.actor.predict(&obs, 2).to_vec();
        for i in 0..2 {
            let mut want = 0.0;
            for j in 0..2 {
                let s = f64::from(ppo.log_std[j]).exp();
                let z = (f64::from(a[2 * i + j]) - f64::from(mean[2 * i + j])) / s;
                want += -0.5 * z * z - s.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
            }
            assert!((f64::from(lp[i]) - want).abs() < 1e-5, "{} vs {want}", lp[i]);
        }
        assert_eq!(v.to_vec(), ppo.critic.predict(&obs, 2).to_vec());
    }
}
