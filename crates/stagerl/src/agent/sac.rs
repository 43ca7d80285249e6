//! Soft Actor-Critic with automatic entropy tuning (Haarnoja et al. 2018), as in CleanRL and
//! Stable-Baselines3.
//!
//! Networks: a tanh-squashed Gaussian actor `obs -> [mean | s]` (log-std `l = -5 + 3.5 (tanh s + 1)`,
//! in [-5, 2]), twin critics `Q1, Q2: [obs | act] -> 1` and their Polyak-averaged targets.
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. critic target `y = r + gamma (1 - d) (min(Q1', Q2')(s', a') - alpha log pi(a'|s'))`,
//!    `a' ~ pi(.|s')`; each critic minimises `mean (Q_i(s, a) - y)^2`;
//! 2. actor minimises `mean (alpha log pi(a~|s) - min(Q1, Q2)(s, a~))`, `a~ ~ pi(.|s)`,
//!    reparameterised, so the gradient flows through dQ/da and the squashed Gaussian;
//! 3. `log alpha` minimises `-log alpha * mean(log pi(a~|s) + H_target)`, `H_target = -act_dim`
//!    (times `target_entropy_per_dim`);
//! 4. targets `theta' <- (1 - tau) theta' + tau theta`.

use super::parts::learned_parts;
use super::{fit_critic, sizes, step, Agent, AgentConfig, Algo, Learner, OffPolicy, UpdateStats};
use crate::agent::replay::Batch;
use crate::base::par;
use crate::base::rng::Rng;
use crate::nn::{concat_cols, Activation, Adam, LogStdBound, Mlp, SquashedGaussian};

/// The log-std range of the actor (CleanRL's).
const LOG_STD: LogStdBound = LogStdBound::Tanh { min: -5.0, max: 2.0 };

pub struct Sac {
    cfg: AgentConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp<f32>,
    head: SquashedGaussian<f32>,
    q1: Mlp<f32>,
    q2: Mlp<f32>,
    q1_target: Mlp<f32>,
    q2_target: Mlp<f32>,
    actor_opt: Adam<f32>,
    q1_opt: Adam<f32>,
    q2_opt: Adam<f32>,
    log_alpha: [f32; 1],
    alpha_opt: Adam<f32>,
    target_entropy: f32,
    rng: Rng,
    // Scratch, grown once to the batch size.
    eps: Vec<f32>,
    critic_in: Vec<f32>,
    next_act: Vec<f32>,
    next_logp: Vec<f32>,
    y: Vec<f32>,
    /// The second critic's values where the first's go to `y`, `dq`, `q1v`, `da` (the twin
    /// critics run at once on two threads, see `stagerl::base::par`).
    q2n: Vec<f32>,
    dq: Vec<f32>,
    dq2: Vec<f32>,
    q1v: Vec<f32>,
    q2v: Vec<f32>,
    da2: Vec<f32>,
    g1: Vec<f32>,
    g2: Vec<f32>,
    da: Vec<f32>,
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
        let critic_sizes = sizes(obs_dim + act_dim, &cfg.hidden, 1);
        let q1 = Mlp::new(&critic_sizes, Activation::Relu, Activation::Identity, &mut init);
        let q2 = Mlp::new(&critic_sizes, Activation::Relu, Activation::Identity, &mut init);
        let (q1_target, q2_target) = (q1.clone(), q2.clone());
        let (b, own) = (cfg.batch_size, cfg.sac());
        Sac {
            actor_opt: Adam::new(actor.num_params(), cfg.actor_lr()),
            q1_opt: Adam::new(q1.num_params(), cfg.critic_lr()),
            q2_opt: Adam::new(q2.num_params(), cfg.critic_lr()),
            log_alpha: [own.init_alpha.ln() as f32],
            alpha_opt: Adam::new(1, own.alpha_lr),
            target_entropy: (own.target_entropy_per_dim * act_dim as f64) as f32,
            head: SquashedGaussian::new(act_dim, LOG_STD),
            rng: Rng::derived(seed, 0x5AC1),
            eps: vec![0.0; b * act_dim],
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            next_act: vec![0.0; b * act_dim],
            next_logp: vec![0.0; b],
            y: vec![0.0; b],
            dq: vec![0.0; b],
            q2n: vec![0.0; b],
            dq2: vec![0.0; b],
            q1v: vec![0.0; b],
            q2v: vec![0.0; b],
            da2: vec![0.0; b * act_dim],
            g1: vec![0.0; b],
            g2: vec![0.0; b],
            da: vec![0.0; b * act_dim],
            dlogp: vec![0.0; b],
            cfg: cfg.clone(),
            obs_dim,
            act_dim,
            actor,
            q1,
            q2,
            q1_target,
            q2_target,
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
        let raw = self.actor.predict(obs, 1);
        let eps = &mut self.eps[..self.act_dim];
        Self::fill_normal(&mut self.rng, eps);
        let (a, _) = self.head.forward(raw, eps, 1);
        action.copy_from_slice(a);
    }

    fn predict(&mut self, obs: &[f32], action: &mut [f32]) {
        let raw = self.actor.predict(obs, 1);
        self.head.deterministic(raw, 1, action);
    }

    fn learner(&mut self) -> Learner<'_> {
        Learner::OffPolicy(self)
    }
}

impl OffPolicy for Sac {
    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let (b, od, ad) = (batch.size, self.obs_dim, self.act_dim);
        let alpha = self.alpha();
        let gamma = self.cfg.gamma as f32;

        // 1. Critics.
        let raw_next = self.actor.predict(&batch.next_obs, b);
        Self::fill_normal(&mut self.rng, &mut self.eps[..b * ad]);
        let (a_next, logp_next) = self.head.forward(raw_next, &self.eps[..b * ad], b);
        self.next_act[..b * ad].copy_from_slice(a_next);
        self.next_logp[..b].copy_from_slice(logp_next);
        concat_cols(&batch.next_obs, od, &self.next_act[..b * ad], ad, b, &mut self.critic_in);
        // The twin critics' passes run at once (on two threads with a pool; the same bits).
        let (ci, y, q2n) = (&self.critic_in, &mut self.y, &mut self.q2n);
        let (q1t, q2t) = (&mut self.q1_target, &mut self.q2_target);
        par::join(
            || y[..b].copy_from_slice(q1t.predict(ci, b)),
            || q2n[..b].copy_from_slice(q2t.predict(ci, b)),
        );
        for i in 0..b {
            let soft_v = self.y[i].min(self.q2n[i]) - alpha * self.next_logp[i];
            self.y[i] = batch.reward[i] + gamma * (1.0 - batch.terminal[i]) * soft_v;
        }
        concat_cols(&batch.obs, od, &batch.act, ad, b, &mut self.critic_in);
        let n = self.cfg.max_grad_norm;
        let (ci, y) = (&self.critic_in, &self.y[..b]);
        let (mut l1, mut l2) = (0.0, 0.0);
        let (q1, q1_opt, dq) = (&mut self.q1, &mut self.q1_opt, &mut self.dq);
        let (q2, q2_opt, dq2) = (&mut self.q2, &mut self.q2_opt, &mut self.dq2);
        par::join(
            || l1 = fit_critic(q1, q1_opt, ci, y, dq, n),
            || l2 = fit_critic(q2, q2_opt, ci, y, dq2, n),
        );
        let critic_loss = l1 + l2;

        // 2. Actor, through the reparameterised sample and dQ/da of the smaller critic.
        let raw = self.actor.forward(&batch.obs, b);
        Self::fill_normal(&mut self.rng, &mut self.eps[..b * ad]);
        let (a, logp) = self.head.forward(raw, &self.eps[..b * ad], b);
        self.next_logp[..b].copy_from_slice(logp); // reuse: log pi(a~|s)
        concat_cols(&batch.obs, od, a, ad, b, &mut self.critic_in);
        let ci = &self.critic_in;
        let (q1, q1v, q2, q2v) = (&mut self.q1, &mut self.q1v, &mut self.q2, &mut self.q2v);
        par::join(
            || q1v[..b].copy_from_slice(q1.forward(ci, b)),
            || q2v[..b].copy_from_slice(q2.forward(ci, b)),
        );
        let inv_b = 1.0 / b as f32;
        let mut actor_loss = 0.0f64;
        for i in 0..b {
            let first = self.q1v[i] <= self.q2v[i];
            let qmin = if first { self.q1v[i] } else { self.q2v[i] };
            actor_loss += f64::from(alpha * self.next_logp[i] - qmin);
            self.g1[i] = if first { -inv_b } else { 0.0 };
            self.g2[i] = if first { 0.0 } else { -inv_b };
            self.dlogp[i] = alpha * inv_b;
        }
        actor_loss /= b as f64;
        let cols = od..od + ad;
        let (q1, g1, da) = (&mut self.q1, &self.g1[..b], &mut self.da[..b * ad]);
        let (q2, g2, da2) = (&mut self.q2, &self.g2[..b], &mut self.da2[..b * ad]);
        par::join(
            || da.copy_from_slice(q1.input_grad_cols(g1, cols.clone())),
            || da2.copy_from_slice(q2.input_grad_cols(g2, cols.clone())),
        );
        for (x, y) in self.da[..b * ad].iter_mut().zip(&self.da2[..b * ad]) {
            *x += y;
        }
        let d_raw = self.head.backward(&self.da[..b * ad], &self.dlogp[..b]);
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
        let tau = self.cfg.tau as f32;
        let (q1t, q1, q2t, q2) = (&mut self.q1_target, &self.q1, &mut self.q2_target, &self.q2);
        par::join(|| q1t.polyak_from(q1, tau), || q2t.polyak_from(q2, tau));

        UpdateStats {
            critic_loss: critic_loss / 2.0,
            actor_loss: Some(actor_loss),
            alpha: Some(f64::from(alpha)),
            entropy: Some(-mean_logp),
        }
    }
}

learned_parts!(Sac, |s, f| {
    f("actor", P::Net(r!(s.actor)));
    f("q1", P::Net(r!(s.q1)));
    f("q2", P::Net(r!(s.q2)));
    f("q1_target", P::Net(r!(s.q1_target)));
    f("q2_target", P::Net(r!(s.q2_target)));
    f("log_alpha", P::Tensor(r!(s.log_alpha)));
    f("actor_opt", P::Adam(r!(s.actor_opt)));
    f("q1_opt", P::Adam(r!(s.q1_opt)));
    f("q2_opt", P::Adam(r!(s.q2_opt)));
    f("alpha_opt", P::Adam(r!(s.alpha_opt)));
    f("agent_rng", P::State(r!(s.rng)));
});
