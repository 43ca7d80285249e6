//! The on-policy collector (PPO): `num_envs` environments stepped together ([`VecEnv`],
//! same-step autoreset), their steps recorded into a [`Rollout`], an update when it is full, and
//! the episodes they end handed to the loop one at a time, so that the episode log, the periodic
//! evaluations, the best checkpoint and the stops are those of every agent. It keeps no replay
//! buffer.
//!
//! Everything it holds (the environments mid-episode, the rollout so far, the episodes ended but
//! not yet logged) is saved in `latest.safetensors`, so a resumed PPO run is bit-identical to an
//! uninterrupted one, as the off-policy runs are. A stop is honoured between environment steps
//! (one update, milliseconds at the default sizes, runs to its end).

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

use std::path::Path;

use super::{Collector, Counters, EpisodeEnd};
use crate::agent::{Agent, Ppo, Rollout, UpdateStats};
use crate::base::rng::Rng;
use crate::config::Resolved;
use crate::env::{EnvState, VecEnv};
use crate::io::checkpoint::Checkpoint;
use crate::{Error, Result};

/// The saved state of [`OnPolicyCollector`]: the field `on_policy` of the training state, as in
/// every earlier version.
#[derive(Serialize, Deserialize)]
struct Saved {
    on_policy: OnPolicyState,
}

/// The state of the environments and the rollout (with the rollout's arrays as tensors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct OnPolicyState {
    envs: Vec<EnvState>,
    /// Each environment's episode under way: reward so far (eq. 16) and steps.
    episode_reward: Vec<f64>,
    episode_steps: Vec<u32>,
    /// Steps that ended in contact (empty in a checkpoint of an older version: none counted).
    #[serde(default)]
    episode_collisions: Vec<u32>,
    /// Episodes ended, not yet handed to the loop.
    ended: Vec<EpisodeEnd>,
    /// Steps recorded in the rollout.
    rollout_steps: usize,
}

/// PPO, its environments and its rollout.
pub(super) struct OnPolicyCollector {
    ppo: Box<Ppo>,
    vec: VecEnv,
    rollout: Rollout,
    episode_reward: Vec<f64>,
    episode_steps: Vec<u32>,
    episode_collisions: Vec<u32>,
    /// The arm has collision shapes: contacts are counted (else episodes record none).
    collisions_checked: bool,
    ended: VecDeque<EpisodeEnd>,
    gamma: f64,
    anneal_lr: bool,
    /// The run's schedule (PPO's learning rate anneals over its progress).
    schedule: crate::config::TrainConfig,
    // Scratch.
    actions: Vec<f32>,
    logp: Vec<f32>,
    values: Vec<f32>,
    final_values: Vec<f32>,
    /// Normalised observations (`norm_obs`).
    obs_buf: Vec<f32>,
}

impl OnPolicyCollector {
    /// The collector of run `run`: `ppo` trained on its environments, their targets drawn from
    /// the run's seed.
    pub(super) fn new(run: &Resolved, ppo: Box<Ppo>) -> Result<OnPolicyCollector> {
        let cfg = run.config();
        let p = cfg.agent.ppo();
        let seed = Rng::derived(cfg.train.seed, 5).next_u64();
        let mut vec = run.vec_env(p.num_envs, seed)?;
        vec.set_obstacles_in_path(cfg.train.obstacles_in_path)?;
        let (n, ad) = (p.num_envs, run.act_dim());
        Ok(OnPolicyCollector {
            ppo,
            rollout: Rollout::new(&p, run.obs_dim(), ad),
            vec,
            episode_reward: vec![0.0; n],
            episode_steps: vec![0; n],
            episode_collisions: vec![0; n],
            collisions_checked: !run.chain().collision_shapes().is_empty(),
            ended: VecDeque::new(),
            gamma: cfg.agent.gamma,
            anneal_lr: p.anneal_lr,
            schedule: cfg.train.clone(),
            actions: vec![0.0; n * ad],
            logp: vec![0.0; n],
            values: vec![0.0; n],
            final_values: vec![0.0; n],
            obs_buf: Vec::new(),
        })
    }

    /// One step of every environment, recorded; the update when the rollout is full.
    fn step(&mut self, st: &mut Counters, last_stats: &mut Option<UpdateStats>) -> Result<()> {
        let (n, ppo) = (self.vec.len(), self.ppo.as_mut());
        let obs = ppo.normalized(self.vec.observations(), n, true, &mut self.obs_buf);
        ppo.act_batch(obs, n, &mut self.actions, &mut self.logp, &mut self.values);
        if let Some(i) = self.actions.iter().position(|a| !a.is_finite()) {
            return Err(Error::NumericalFault(format!(
                "the policy's action value {i} = {} at episode {} (update {}); the last good checkpoint is left in place",
                self.actions[i],
                st.episode + 1,
                st.updates
            )));
        }
        self.rollout.record_step(obs, &self.actions, &self.logp, &self.values);
        self.vec.step(&self.actions)?;
        // A time limit is bootstrapped through: gamma V(s_final) joins the reward.
        if self.vec.truncated().iter().any(|&t| t) {
            let obs = ppo.normalized(self.vec.final_observations(), n, false, &mut self.obs_buf);
            ppo.values(obs, n, &mut self.final_values);
        }
        for i in 0..n {
            let (r, term, trunc) = (self.vec.rewards()[i], self.vec.terminated()[i], self.vec.truncated()[i]);
            self.episode_reward[i] += r;
            self.episode_steps[i] += 1;
            self.episode_collisions[i] += u32::from(self.vec.last_steps()[i].collision.is_some());
            let boot = if trunc { self.gamma * f64::from(self.final_values[i]) } else { 0.0 };
            self.rollout.record_outcome(i, r + boot, term || trunc);
            if term || trunc {
                self.ended.push_back(EpisodeEnd {
                    reward: self.episode_reward[i],
                    steps: self.episode_steps[i],
                    success: self.vec.last_steps()[i].reached(),
                    final_distance_m: self.vec.last_steps()[i].terms.distance,
                    collision_steps: self.collisions_checked.then_some(self.episode_collisions[i]),
                    shield: None,
                    curriculum_stage: None,
                    advance: None,
                    demonstrations: None,
                });
                self.episode_reward[i] = 0.0;
                self.episode_steps[i] = 0;
                self.episode_collisions[i] = 0;
            }
        }
        self.rollout.t += 1;
        st.env_steps += n as u64;
        if self.rollout.is_full() {
            let obs = ppo.normalized(self.vec.observations(), n, false, &mut self.obs_buf);
            ppo.values(obs, n, &mut self.values);
            if self.anneal_lr {
                ppo.set_lr_fraction(1.0 - self.schedule.progress(st.episode, st.env_steps));
            }
            let stats = ppo.update(&mut self.rollout, &self.values);
            self.rollout.t = 0;
            st.updates += stats.steps;
            for (what, v) in [("value loss", stats.value_loss), ("policy loss", stats.policy_loss)] {
                if !v.is_finite() {
                    return Err(Error::NumericalFault(format!(
                        "{what} = {v} at episode {} (update {}); the last good checkpoint is left in place",
                        st.episode + 1,
                        st.updates
                    )));
                }
            }
            *last_stats = Some(stats.into());
        }
        Ok(())
    }

    /// Restore the state [`Collector::save`] wrote.
    fn restore_state(&mut self, ck: &Checkpoint, s: &OnPolicyState) -> Result<()> {
        let n = self.vec.len();
        if s.episode_reward.len() != n || s.episode_steps.len() != n {
            return Err(Error::InvalidInput(format!(
                "PPO state for {} environments, the config has agent.ppo.num_envs = {n}",
                s.episode_reward.len()
            )));
        }
        self.vec.restore(&s.envs)?;
        let data: Vec<&[f32]> =
            Rollout::ARRAY_NAMES.iter().map(|name| ck.tensor(name).map(|(_, d)| d)).collect::<Result<_>>()?;
        self.rollout.restore(s.rollout_steps, [data[0], data[1], data[2], data[3], data[4], data[5]])?;
        self.episode_reward.copy_from_slice(&s.episode_reward);
        self.episode_steps.copy_from_slice(&s.episode_steps);
        match s.episode_collisions.len() {
            0 => self.episode_collisions.fill(0),
            k if k == n => self.episode_collisions.copy_from_slice(&s.episode_collisions),
            k => {
                return Err(Error::InvalidInput(format!(
                    "PPO state counts contacts for {k} environments, the config has agent.ppo.num_envs = {n}"
                )))
            }
        }
        self.ended = s.ended.iter().copied().collect();
        Ok(())
    }
}

impl Collector for OnPolicyCollector {
    fn agent(&self) -> &dyn Agent {
        self.ppo.as_ref()
    }

    fn agent_mut(&mut self) -> &mut dyn Agent {
        self.ppo.as_mut()
    }

    /// The next ended episode, stepping the environments (and updating) until one ends.
    fn next_episode(
        &mut self,
        n: &mut Counters,
        last_stats: &mut Option<UpdateStats>,
        stop_requested: &dyn Fn() -> bool,
    ) -> Result<Option<EpisodeEnd>> {
        loop {
            if let Some(e) = self.ended.pop_front() {
                return Ok(Some(e));
            }
            if stop_requested() {
                return Ok(None);
            }
            self.step(n, last_stats)?;
        }
    }

    /// The loop logs whole episodes only; the environments' episodes under way are in the state.
    fn mid_episode(&self) -> bool {
        false
    }

    fn save(&mut self, ck: &mut Checkpoint) -> serde_json::Value {
        for (name, data) in Rollout::ARRAY_NAMES.iter().zip(self.rollout.arrays()) {
            ck.put_tensor(name, &[data.len()], data);
        }
        let on_policy = OnPolicyState {
            envs: self.vec.states(),
            episode_reward: self.episode_reward.clone(),
            episode_steps: self.episode_steps.clone(),
            episode_collisions: self.episode_collisions.clone(),
            ended: self.ended.iter().copied().collect(),
            rollout_steps: self.rollout.t,
        };
        serde_json::to_value(Saved { on_policy }).expect("the state serialises")
    }

    fn restore(&mut self, ck: &Checkpoint, path: &Path) -> Result<()> {
        let state: serde_json::Value = ck.json(super::TRAIN_STATE)?;
        if state.get("on_policy").is_none_or(serde_json::Value::is_null) {
            return Err(Error::InvalidInput(format!(
                "{}: its training state holds no PPO environments and rollout (`on_policy`): \
                 not a checkpoint of an on-policy run",
                path.display()
            )));
        }
        let saved: Saved = ck.json(super::TRAIN_STATE)?;
        self.restore_state(ck, &saved.on_policy)
    }
}
