//! Twin Delayed DDPG (Fujimoto et al. 2018), as in CleanRL, and the family it heads: as in
//! Stable-Baselines3, DDPG ([`super::ddpg`]) is this algorithm with one critic, no policy delay
//! and no target policy smoothing.
//!
//! Networks: a deterministic actor `mu: obs -> act` (tanh output), `n` critics
//! `Q_i: [obs | act] -> 1` (TD3: 2, DDPG: 1) and Polyak-averaged targets of all of them.
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

use super::noise::ActionNoise;
use super::parts::learned_parts;
use super::{fit_critic, sizes, step, Agent, AgentConfig, Algo, Learner, NoiseKind, OffPolicy, UpdateStats};
use crate::nn::{concat_cols, Activation, Adam, Mlp};
use crate::par;
use crate::replay::Batch;
use crate::rng::Rng;

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
            critics: &[["q1", "q1_target", "q1_opt"], ["q2", "q2_target", "q2_opt"]],
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
    critics: Vec<Mlp<f32>>,
    actor_target: Mlp<f32>,
    critic_targets: Vec<Mlp<f32>>,
    actor_opt: Adam<f32>,
    critic_opts: Vec<Adam<f32>>,
    noise: ActionNoise,
    rng: Rng,
    updates: u64,
    critic_in: Vec<f32>,
    a_next: Vec<f32>,
    /// Standard normal draws of the target policy smoothing (`batch x act`).
    smoothing_noise: Vec<f64>,
    y: Vec<f32>,
    dq: Vec<f32>,
    /// Per critic: its target's values and its loss gradient (the critics run at once on a
    /// pool's threads, see `stagerl::par`), and its last loss.
    scratch: Vec<CriticScratch>,
}

/// One critic's buffers for an update.
struct CriticScratch {
    q_next: Vec<f32>,
    dq: Vec<f32>,
    loss: f64,
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
        let critic_sizes = sizes(obs_dim + act_dim, &cfg.hidden, 1);
        let critics: Vec<Mlp<f32>> = (0..family.critics.len())
            .map(|_| Mlp::new(&critic_sizes, Activation::Relu, Activation::Identity, &mut init))
            .collect();
        let (kind, sigma, theta) = family.noise;
        let b = cfg.batch_size;
        Td3 {
            actor_opt: Adam::new(actor.num_params(), cfg.actor_lr()),
            critic_opts: critics.iter().map(|q| Adam::new(q.num_params(), cfg.critic_lr())).collect(),
            actor_target: actor.clone(),
            critic_targets: critics.clone(),
            noise: ActionNoise::new(kind, sigma, theta, act_dim),
            rng: Rng::derived(seed, family.salts.1),
            updates: 0,
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            a_next: vec![0.0; b * act_dim],
            smoothing_noise: vec![0.0; b * act_dim],
            y: vec![0.0; b],
            dq: vec![0.0; b],
            scratch: (0..family.critics.len())
                .map(|_| CriticScratch { q_next: vec![0.0; b], dq: vec![0.0; b], loss: 0.0 })
                .collect(),
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
        action.copy_from_slice(self.actor.predict(obs, 1));
        self.noise.perturb(&mut self.rng, action);
    }

    fn predict(&mut self, obs: &[f32], action: &mut [f32]) {
        action.copy_from_slice(self.actor.predict(obs, 1));
    }

    fn begin_episode(&mut self) {
        self.noise.reset();
    }

    fn learner(&mut self) -> Learner<'_> {
        Learner::OffPolicy(self)
    }
}

impl OffPolicy for Td3 {
    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let (b, od, ad) = (batch.size, self.obs_dim, self.act_dim);
        let gamma = self.cfg.gamma as f32;
        self.updates += 1;

        // 1. Target action, smoothed for TD3.
        let mu_next = self.actor_target.predict(&batch.next_obs, b);
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
        concat_cols(&batch.next_obs, od, a_next, ad, b, &mut self.critic_in);

        // 2. Critics, towards the smallest target critic.
        let ci = &self.critic_in;
        par::for_each_mut(&mut self.critic_targets, &mut self.scratch, &|_, t, s| {
            s.q_next[..b].copy_from_slice(t.predict(ci, b))
        });
        self.y[..b].copy_from_slice(&self.scratch[0].q_next[..b]);
        for s in &self.scratch[1..] {
            for (y, &q) in self.y[..b].iter_mut().zip(&s.q_next[..b]) {
                *y = y.min(q);
            }
        }
        for i in 0..b {
            self.y[i] = batch.reward[i] + gamma * (1.0 - batch.terminal[i]) * self.y[i];
        }
        concat_cols(&batch.obs, od, &batch.act, ad, b, &mut self.critic_in);
        let n = self.cfg.max_grad_norm;
        let (ci, y) = (&self.critic_in, &self.y[..b]);
        par::for_each_mut3(&mut self.critics, &mut self.critic_opts, &mut self.scratch, &|_, q, opt, s| {
            s.loss = fit_critic(q, opt, ci, y, &mut s.dq, n)
        });
        let mut critic_loss = 0.0;
        for s in &self.scratch {
            critic_loss += s.loss;
        }

        // 3. Delayed actor and targets.
        let mut actor_loss = None;
        if self.updates.is_multiple_of(u64::from(self.family.policy_delay)) {
            let q1 = &mut self.critics[0];
            let mu = self.actor.forward(&batch.obs, b);
            concat_cols(&batch.obs, od, mu, ad, b, &mut self.critic_in);
            let q = q1.forward(&self.critic_in, b);
            actor_loss = Some(-q.iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64);
            self.dq[..b].fill(-1.0 / b as f32);
            let da = q1.input_grad_cols(&self.dq[..b], od..od + ad);
            self.actor.zero_grad();
            self.actor.backward(da);
            step(&mut self.actor, &mut self.actor_opt, self.cfg.max_grad_norm);
            let tau = self.cfg.tau as f32;
            self.actor_target.polyak_from(&self.actor, tau);
            let critics = &self.critics;
            par::for_each_mut(&mut self.critic_targets, &mut self.scratch, &|k, t, _| {
                t.polyak_from(&critics[k], tau)
            });
        }

        let critic_loss = critic_loss / self.critics.len() as f64;
        UpdateStats { critic_loss, actor_loss, alpha: None, entropy: None }
    }
}

learned_parts!(Td3, |s, f| {
    let names = s.family.critics;
    f("actor", P::Net(r!(s.actor)));
    for (name, q) in names.iter().zip(each!(s.critics)) {
        f(name[0], P::Net(q));
    }
    f("actor_target", P::Net(r!(s.actor_target)));
    for (name, q) in names.iter().zip(each!(s.critic_targets)) {
        f(name[1], P::Net(q));
    }
    f("actor_opt", P::Adam(r!(s.actor_opt)));
    for (name, opt) in names.iter().zip(each!(s.critic_opts)) {
        f(name[2], P::Adam(opt));
    }
    f("agent_rng", P::State(r!(s.rng)));
    f("agent_noise", P::State(r!(s.noise)));
    f("agent_updates", P::State(r!(s.updates)));
});
