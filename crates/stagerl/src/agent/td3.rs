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
use super::{
    fit_forwarded, sizes, step, Agent, AgentConfig, Algo, Learner, NoiseKind, OffPolicy, UpdateStats,
};
use crate::agent::replay::Batch;
use crate::base::par;
use crate::base::rng::Rng;
use crate::nn::{concat_cols, Activation, Adam, Mlp};

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
    /// `[s | a]` rows for the critics (the target side has its own, `critic_in_next`).
    critic_in: Vec<f32>,
    critic_in_next: Vec<f32>,
    a_next: Vec<f32>,
    /// Standard normal draws of the target policy smoothing (`batch x act`).
    smoothing_noise: Vec<f64>,
    y: Vec<f32>,
    dq: Vec<f32>,
    /// Per critic: its target's values on the batch.
    q_next: Vec<Vec<f32>>,
    /// Per critic: its loss gradient (the critics run at once on a pool's threads, see
    /// `stagerl::base::par`) and its last loss.
    scratch: Vec<CriticScratch>,
}

/// One critic's buffers for an update.
struct CriticScratch {
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
            critic_in_next: vec![0.0; b * (obs_dim + act_dim)],
            a_next: vec![0.0; b * act_dim],
            smoothing_noise: vec![0.0; b * act_dim],
            y: vec![0.0; b],
            dq: vec![0.0; b],
            q_next: vec![vec![0.0; b]; family.critics.len()],
            scratch: (0..family.critics.len())
                .map(|_| CriticScratch { dq: vec![0.0; b], loss: 0.0 })
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
        let b = batch.size;
        self.updates += 1;
        let actor_due = self.updates.is_multiple_of(u64::from(self.family.policy_delay));
        let Td3 { actor, critics, critic_opts, scratch, critic_in, .. } = self;

        // 1-2. The targets y (steps 1 and 2's target), while the critics' forward passes on
        // (s, a) run on a second thread (with a pool; the results do not depend on it).
        let (od, ad) = (self.obs_dim, self.act_dim);
        let mut targets = Targets {
            family: &self.family,
            gamma: self.cfg.gamma as f32,
            actor: &mut self.actor_target,
            critics: &mut self.critic_targets,
            rng: &mut self.rng,
            smoothing_noise: &mut self.smoothing_noise,
            a_next: &mut self.a_next,
            critic_in: &mut self.critic_in_next,
            q_next: &mut self.q_next,
            y: &mut self.y,
        };
        par::join(
            || targets.compute(batch, od, ad),
            || {
                concat_cols(&batch.obs, od, &batch.act, ad, b, critic_in);
                for q in critics.iter_mut() {
                    q.forward(critic_in, b);
                }
            },
        );

        // 2. Each critic minimises its error. One critic shares the step with the actor's forward
        // pass mu(s) when the actor is due; two run at once.
        let n = self.cfg.max_grad_norm;
        let y = &self.y[..b];
        let mut mu_done = false;
        if let ([q], [opt], [s]) = (&mut critics[..], &mut critic_opts[..], &mut scratch[..]) {
            let actor_forward = || {
                if actor_due {
                    actor.forward(&batch.obs, b);
                    mu_done = true;
                }
            };
            par::join(|| s.loss = fit_forwarded(q, opt, y, &mut s.dq, n), actor_forward);
        } else {
            par::for_each_mut3(critics, critic_opts, scratch, &|_, q, opt, s| {
                s.loss = fit_forwarded(q, opt, y, &mut s.dq, n)
            });
        }
        let mut critic_loss = 0.0;
        for s in scratch.iter() {
            critic_loss += s.loss;
        }

        // 3. Delayed actor and targets.
        let mut actor_loss = None;
        if actor_due {
            if !mu_done {
                actor.forward(&batch.obs, b);
            }
            concat_cols(&batch.obs, od, actor.output(), ad, b, critic_in);
            let q1 = &mut critics[0];
            let q = q1.forward(critic_in, b);
            actor_loss = Some(-q.iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64);
            self.dq[..b].fill(-1.0 / b as f32);
            let da = q1.input_grad_cols(&self.dq[..b], od..od + ad);
            actor.zero_grad();
            actor.backward(da);
            step(actor, &mut self.actor_opt, n);
            let tau = self.cfg.tau as f32;
            self.actor_target.polyak_from(actor, tau);
            let critics = &*critics;
            par::for_each_mut(&mut self.critic_targets, &mut scratch[..], &|k, t, _| {
                t.polyak_from(&critics[k], tau)
            });
        }

        let critic_loss = critic_loss / critics.len() as f64;
        UpdateStats { critic_loss, actor_loss, alpha: None, entropy: None }
    }
}

/// The target side of an update: the target networks and their buffers.
struct Targets<'a> {
    family: &'a Family,
    gamma: f32,
    actor: &'a mut Mlp<f32>,
    critics: &'a mut [Mlp<f32>],
    rng: &'a mut Rng,
    smoothing_noise: &'a mut [f64],
    a_next: &'a mut [f32],
    critic_in: &'a mut Vec<f32>,
    /// Per target critic: its values on the batch.
    q_next: &'a mut [Vec<f32>],
    y: &'a mut [f32],
}

impl Targets<'_> {
    /// Steps 1 and 2's target: `y = r + gamma (1 - d) min_i Q_i'(s', a')`.
    fn compute(&mut self, batch: &Batch, od: usize, ad: usize) {
        let b = batch.size;
        // 1. Target action, smoothed for TD3.
        let mu_next = self.actor.predict(&batch.next_obs, b);
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
        concat_cols(&batch.next_obs, od, a_next, ad, b, self.critic_in);

        // 2. Towards the smallest target critic.
        let ci = &*self.critic_in;
        par::for_each_mut(self.critics, self.q_next, &|_, t, q| q[..b].copy_from_slice(t.predict(ci, b)));
        let y = &mut self.y[..b];
        y.copy_from_slice(&self.q_next[0][..b]);
        for q in &self.q_next[1..] {
            for (y, &q) in y.iter_mut().zip(&q[..b]) {
                *y = y.min(q);
            }
        }
        for i in 0..b {
            y[i] = batch.reward[i] + self.gamma * (1.0 - batch.terminal[i]) * y[i];
        }
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
