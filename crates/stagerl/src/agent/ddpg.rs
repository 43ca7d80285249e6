//! Deep Deterministic Policy Gradient (Lillicrap et al. 2015), the paper's first method, as in
//! CleanRL.
//!
//! Networks: a deterministic actor `mu: obs -> act` (tanh output), a critic `Q: [obs | act] -> 1`,
//! and Polyak-averaged targets of both.
//!
//! One update on a batch `(s, a, r, s', d)`:
//! 1. critic target `y = r + gamma (1 - d) Q'(s', mu'(s'))`; the critic minimises
//!    `mean (Q(s, a) - y)^2`;
//! 2. the actor maximises `mean Q(s, mu(s))`: its gradient is dQ/da back-propagated through mu;
//! 3. targets `theta' <- (1 - tau) theta' + tau theta`.
//!
//! Exploration: Gaussian or Ornstein-Uhlenbeck noise added to `mu(s)`, clipped to [-1, 1].

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

pub struct Ddpg {
    cfg: AgentConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp<f32>,
    critic: Mlp<f32>,
    actor_target: Mlp<f32>,
    critic_target: Mlp<f32>,
    actor_opt: Adam<f32>,
    critic_opt: Adam<f32>,
    noise: ActionNoise,
    rng: Rng,
    critic_in: Vec<f32>,
    y: Vec<f32>,
    dq: Vec<f32>,
}

impl Ddpg {
    pub fn new(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Ddpg {
        let mut init = Rng::derived(seed, 0xDD96);
        let actor =
            Mlp::new(&sizes(obs_dim, &cfg.hidden, act_dim), Activation::Relu, Activation::Tanh, &mut init);
        let critic = Mlp::new(
            &sizes(obs_dim + act_dim, &cfg.hidden, 1),
            Activation::Relu,
            Activation::Identity,
            &mut init,
        );
        let b = cfg.batch_size;
        Ddpg {
            actor_opt: Adam::new(actor.num_params(), cfg.actor_lr()),
            critic_opt: Adam::new(critic.num_params(), cfg.critic_lr()),
            actor_target: actor.clone(),
            critic_target: critic.clone(),
            noise: ActionNoise::new(cfg.noise, cfg.noise_sigma(), cfg.ou_theta, act_dim),
            rng: Rng::derived(seed, 0xDD961),
            critic_in: vec![0.0; b * (obs_dim + act_dim)],
            y: vec![0.0; b],
            dq: vec![0.0; b],
            cfg: cfg.clone(),
            obs_dim,
            act_dim,
            actor,
            critic,
        }
    }
}

impl Agent for Ddpg {
    fn algo(&self) -> Algo {
        Algo::Ddpg
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

        // 1. Critic.
        let a_next = self.actor_target.predict(&batch.next_obs, b);
        concat_cols(&batch.next_obs, od, a_next, ad, b, &mut self.critic_in);
        let q_next = self.critic_target.predict(&self.critic_in, b);
        for i in 0..b {
            self.y[i] = batch.reward[i] + gamma * (1.0 - batch.terminal[i]) * q_next[i];
        }
        concat_cols(&batch.obs, od, &batch.act, ad, b, &mut self.critic_in);
        let critic_loss = fit_critic(
            &mut self.critic,
            &mut self.critic_opt,
            &self.critic_in,
            &self.y[..b],
            &mut self.dq,
            self.cfg.max_grad_norm,
        );

        // 2. Actor: descend on -mean Q(s, mu(s)).
        let mu = self.actor.forward(&batch.obs, b);
        concat_cols(&batch.obs, od, mu, ad, b, &mut self.critic_in);
        let q = self.critic.forward(&self.critic_in, b);
        let actor_loss = -q.iter().map(|&x| f64::from(x)).sum::<f64>() / b as f64;
        self.dq[..b].fill(-1.0 / b as f32);
        let da = self.critic.input_grad_cols(&self.dq[..b], od..od + ad);
        self.actor.zero_grad();
        self.actor.backward(da);
        step(&mut self.actor, &mut self.actor_opt, self.cfg.max_grad_norm);

        // 3. Targets.
        let tau = self.cfg.tau as f32;
        self.actor_target.polyak_from(&self.actor, tau);
        self.critic_target.polyak_from(&self.critic, tau);

        UpdateStats { critic_loss, actor_loss: Some(actor_loss), alpha: None, entropy: None }
    }

    fn save(&self, ck: &mut Checkpoint) {
        save_mlp(ck, "actor", &self.actor);
        save_mlp(ck, "critic", &self.critic);
        save_mlp(ck, "actor_target", &self.actor_target);
        save_mlp(ck, "critic_target", &self.critic_target);
        save_adam(ck, "actor_opt", &self.actor_opt);
        save_adam(ck, "critic_opt", &self.critic_opt);
        ck.put_json("agent_rng", &self.rng);
        ck.put_json("agent_noise", &self.noise);
    }

    fn load(&mut self, ck: &Checkpoint) -> Result<()> {
        load_mlp(ck, "actor", &mut self.actor)?;
        load_mlp(ck, "critic", &mut self.critic)?;
        load_mlp(ck, "actor_target", &mut self.actor_target)?;
        load_mlp(ck, "critic_target", &mut self.critic_target)?;
        load_adam(ck, "actor_opt", &mut self.actor_opt)?;
        load_adam(ck, "critic_opt", &mut self.critic_opt)?;
        self.rng = ck.json("agent_rng")?;
        self.noise = ck.json("agent_noise")?;
        Ok(())
    }

    fn first_non_finite(&self) -> Option<String> {
        find_non_finite(&[
            ("actor", &self.actor),
            ("critic", &self.critic),
            ("actor_target", &self.actor_target),
            ("critic_target", &self.critic_target),
        ])
    }
}
