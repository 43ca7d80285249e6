//! Twin Delayed DDPG (Fujimoto et al. 2018), as in CleanRL.
//!
//! DDPG with three changes: twin critics and the smaller of their targets (clipped double
//! Q-learning); target policy smoothing, `a' = clip(mu'(s') + clip(N(0, sigma~), -c, c), -1, 1)`;
//! and delayed policy updates (the actor and all targets every `policy_delay` critic updates).
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. `y = r + gamma (1 - d) min(Q1', Q2')(s', a')`; each critic minimises `mean (Q_i(s, a) - y)^2`;
//! 2. every `policy_delay` updates: the actor maximises `mean Q1(s, mu(s))`, then every target
//!    network is Polyak-averaged.

use super::noise::ActionNoise;
use super::{
    find_non_finite, fit_critic, load_adam, load_mlp, save_adam, save_mlp, sizes, step, Agent, AgentConfig,
    Algo, UpdateStats,
};
use crate::checkpoint::Checkpoint;
use crate::nn::{concat_cols, Activation, Adam, Mlp};
use crate::replay::Batch;
use crate::rng::Rng;
use crate::Result;

pub struct Td3 {
    cfg: AgentConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp<f32>,
    q1: Mlp<f32>,
    q2: Mlp<f32>,
    actor_target: Mlp<f32>,
    q1_target: Mlp<f32>,
    q2_target: Mlp<f32>,
    actor_opt: Adam<f32>,
    q1_opt: Adam<f32>,
    q2_opt: Adam<f32>,
    noise: ActionNoise,
    rng: Rng,
    updates: u64,
    critic_in: Vec<f32>,
    a_next: Vec<f32>,
    y: Vec<f32>,
    dq: Vec<f32>,
}

impl Td3 {
    pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Td3 {
        let mut init = Rng::derived(seed, 0x7D3);
        let actor =
            Mlp::new(&sizes(obs_dim, &cfg.hidden, act_dim), Activation::Relu, Activation::Tanh, &mut init);
        let critic_sizes = sizes(obs_dim + act_dim, &cfg.hidden, 1);
        let q1 = Mlp::new(&critic_sizes, Activation::Relu, Activation::Identity, &mut init);
        let q2 = Mlp::new(&critic_sizes, Activation::Relu, Activation::Identity, &mut init);
        let b = cfg.batch_size;
        Td3 {
            actor_opt: Adam::new(actor.num_params(), cfg.actor_lr()),
            q1_opt: Adam::new(q1.num_params(), cfg.critic_lr()),
            q2_opt: Adam::new(q2.num_params(), cfg.critic_lr()),
            actor_target: actor.clone(),
            q1_target: q1.clone(),
            q2_target: q2.clone(),
            noise: ActionNoise::new(cfg.noise, cfg.noise_sigma(), cfg.ou_theta, act_dim),
            rng: Rng::derived(seed, 0x7D31),
            updates: 0,
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            a_next: vec![0.0; b * act_dim],
            y: vec![0.0; b],
            dq: vec![0.0; b],
            cfg: cfg.clone(),
            obs_dim,
            act_dim,
            actor,
            q1,
            q2,
        }
    }
}

impl Agent for Td3 {
    fn algo(&self) -> Algo {
        Algo::Td3
    }
    fn obs_dim(&self) -> usize {
        self.obs_dim
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

    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let (b, od, ad) = (batch.size, self.obs_dim, self.act_dim);
        let gamma = self.cfg.gamma as f32;
        self.updates += 1;

        // 1. Critics, with target policy smoothing and the smaller target.
        let mu_next = self.actor_target.predict(&batch.next_obs, b);
        let (sigma, c) = (self.cfg.target_noise, self.cfg.target_noise_clip);
        for (out, &m) in self.a_next[..b * ad].iter_mut().zip(mu_next) {
            let n = (sigma * self.rng.normal()).clamp(-c, c);
            *out = (f64::from(m) + n).clamp(-1.0, 1.0) as f32;
        }
        concat_cols(&batch.next_obs, od, &self.a_next[..b * ad], ad, b, &mut self.critic_in);
        let q1n = self.q1_target.predict(&self.critic_in, b);
        self.y[..b].copy_from_slice(q1n);
        let q2n = self.q2_target.predict(&self.critic_in, b);
        for i in 0..b {
            self.y[i] = batch.reward[i] + gamma * (1.0 - batch.terminal[i]) * self.y[i].min(q2n[i]);
        }
        concat_cols(&batch.obs, od, &batch.act, ad, b, &mut self.critic_in);
        let n = self.cfg.max_grad_norm;
        let critic_loss =
            fit_critic(&mut self.q1, &mut self.q1_opt, &self.critic_in, &self.y[..b], &mut self.dq, n)
                + fit_critic(&mut self.q2, &mut self.q2_opt, &self.critic_in, &self.y[..b], &mut self.dq, n);

        // 2. Delayed actor and targets.
        let mut actor_loss = None;
        if self.updates % u64::from(self.cfg.policy_delay) == 0 {
            let mu = self.actor.forward(&batch.obs, b);
            concat_cols(&batch.obs, od, mu, ad, b, &mut self.critic_in);
            let q = self.q1.forward(&self.critic_in, b);
            actor_loss = Some(-q.iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64);
            self.dq[..b].fill(-1.0 / b as f32);
            let da = self.q1.input_grad_cols(&self.dq[..b], od..od + ad);
            self.actor.zero_grad();
            self.actor.backward(da);
            step(&mut self.actor, &mut self.actor_opt, self.cfg.max_grad_norm);
            let tau = self.cfg.tau as f32;
            self.actor_target.polyak_from(&self.actor, tau);
            self.q1_target.polyak_from(&self.q1, tau);
            self.q2_target.polyak_from(&self.q2, tau);
        }

        UpdateStats { critic_loss: critic_loss / 2.0, actor_loss, alpha: None, entropy: None }
    }

    fn save(&self, ck: &mut Checkpoint) {
        save_mlp(ck, "actor", &self.actor);
        save_mlp(ck, "q1", &self.q1);
        save_mlp(ck, "q2", &self.q2);
        save_mlp(ck, "actor_target", &self.actor_target);
        save_mlp(ck, "q1_target", &self.q1_target);
        save_mlp(ck, "q2_target", &self.q2_target);
        save_adam(ck, "actor_opt", &self.actor_opt);
        save_adam(ck, "q1_opt", &self.q1_opt);
        save_adam(ck, "q2_opt", &self.q2_opt);
        ck.put_json("agent_rng", &self.rng);
        ck.put_json("agent_noise", &self.noise);
        ck.put_json("agent_updates", &self.updates);
    }

    fn load(&mut self, ck: &Checkpoint) -> Result<()> {
        load_mlp(ck, "actor", &mut self.actor)?;
        load_mlp(ck, "q1", &mut self.q1)?;
        load_mlp(ck, "q2", &mut self.q2)?;
        load_mlp(ck, "actor_target", &mut self.actor_target)?;
        load_mlp(ck, "q1_target", &mut self.q1_target)?;
        load_mlp(ck, "q2_target", &mut self.q2_target)?;
        load_adam(ck, "actor_opt", &mut self.actor_opt)?;
        load_adam(ck, "q1_opt", &mut self.q1_opt)?;
        load_adam(ck, "q2_opt", &mut self.q2_opt)?;
        self.rng = ck.json("agent_rng")?;
        self.noise = ck.json("agent_noise")?;
        self.updates = ck.json("agent_updates")?;
        Ok(())
    }

    fn first_non_finite(&self) -> Option<String> {
        find_non_finite(&[
            ("actor", &self.actor),
            ("q1", &self.q1),
            ("q2", &self.q2),
            ("actor_target", &self.actor_target),
            ("q1_target", &self.q1_target),
            ("q2_target", &self.q2_target),
        ])
    }
}
