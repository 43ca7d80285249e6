//! Hindsight experience replay (HER; Andrychowicz et al., NeurIPS 2017) for the off-policy
//! agents: `agent.her = { strategy = "future", k = 4 }`, off by default.
//!
//! An episode that missed its target still shows how to reach the places the end effector did
//! reach. When an episode ends, each of its transitions is stored again with a substituted goal
//! `g`, an end-effector position of the same episode, chosen by the strategy:
//! - `future`: the position after a step `t' >= t` of the same episode, uniformly (`k` goals);
//! - `episode`: the position after any step of the episode, uniformly (`k` goals);
//! - `final`: the position after the episode's last step (one goal: `k` copies of the same goal
//!   would only weight it).
//!
//! For the substituted goal everything that depends on the target is computed again, exactly as
//! the environment computes it: the target entries of both observations
//! ([`crate::env::ObservationLayout::write_target_entries`]), the reward with the run's reward function (any of the
//! five: each is a pure function of the step's end-effector pose, joint velocities and target,
//! eqs. 1-15 and 18), the success bonus and the termination (`D_PT < beta` for `g`). The clearance
//! term (`[reward.clearance]`) and the shield's (`reward.shield_penalty`) depend on the arm's pose
//! and command, not on the goal: the step's measured clearance and the shield's change to its
//! command are logged and charged again. The real
//! transitions are stored as without HER, after every step, so that the updates of Algorithm 1
//! see them at once; the relabelled ones follow when the episode ends.
//!
//! The episode under way and the goal sampler's random state are part of the training state, so
//! a run with HER resumes bit-identically.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::agent::{HerConfig, HerStrategy};
use crate::base::rng::Rng;
use crate::env::{ObservationLayout, ResolvedTask, Step, Transition};
use crate::reward::{RewardConfig, RewardInput, RewardTerms};

/// The steps of the episode under way, as relabelling needs them: the observations and actions
/// as stored, and the end-effector poses (metres, quaternion `(x, y, z, w)`) and joint
/// velocities (rad/s) the rewards are computed from. Flat arrays, one row per step, reused
/// from episode to episode.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeLog {
    /// End-effector position at the episode's start (metres).
    start_ee: [f64; 3],
    obs: Vec<f32>,
    action: Vec<f32>,
    next_obs: Vec<f32>,
    /// End-effector position after each step (metres).
    ee: Vec<f64>,
    /// End-effector orientation after each step, `(x, y, z, w)`.
    quat: Vec<f64>,
    /// Joint velocities applied in each step (rad/s).
    joint_vel: Vec<f64>,
    /// Each step ended in contact (absent in checkpoints of older versions: no contact).
    #[serde(default)]
    contact: Vec<bool>,
    /// The arm's clearance from the obstacles after each step ([`crate::env::Step::clearance_m`];
    /// absent in checkpoints of older versions and when it is not measured).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    clearance: Vec<Option<f64>>,
    /// The shield's change to each step's command, rad/s ([`crate::env::Step::shield_change_rad_per_s`];
    /// absent in checkpoints of older versions and when the shield is off).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    shield_change: Vec<f64>,
}

impl EpisodeLog {
    /// Forget the previous episode; the next one starts with the end effector at `start_ee`.
    pub fn begin(&mut self, start_ee: Vector3<f64>) {
        self.start_ee = start_ee.into();
        for v in [&mut self.obs, &mut self.action, &mut self.next_obs] {
            v.clear();
        }
        for v in [&mut self.ee, &mut self.quat, &mut self.joint_vel] {
            v.clear();
        }
        self.contact.clear();
        self.clearance.clear();
        self.shield_change.clear();
    }

    /// Record a step of the episode (after the environment took it).
    pub fn push(&mut self, t: &Transition<'_>) {
        let pose = t.env.ee_pose();
        self.obs.extend_from_slice(t.obs);
        self.action.extend_from_slice(t.action);
        self.next_obs.extend_from_slice(t.env.observation());
        self.ee.extend_from_slice(pose.position.as_slice());
        self.quat.extend_from_slice(&pose.quaternion_xyzw());
        self.joint_vel.extend_from_slice(t.env.joint_velocities());
        self.contact.push(t.step.collision.is_some());
        if t.step.clearance_m.is_some() {
            // An infinite clearance (no obstacle near) is charged as none: JSON has no infinity.
            self.clearance.push(t.step.clearance_m.filter(|d| d.is_finite()));
        }
        if let Some(c) = t.step.shield_change_rad_per_s {
            self.shield_change.push(c);
        }
    }

    /// Steps recorded.
    pub fn len(&self) -> usize {
        self.ee.len() / 3
    }

    pub fn is_empty(&self) -> bool {
        self.ee.is_empty()
    }

    fn contact_after(&self, t: usize) -> bool {
        self.contact.get(t).copied().unwrap_or(false)
    }

    fn clearance_after(&self, t: usize) -> Option<f64> {
        self.clearance.get(t).copied().flatten()
    }

    fn shield_change_at(&self, t: usize) -> Option<f64> {
        self.shield_change.get(t).copied()
    }

    fn ee_after(&self, t: usize) -> Vector3<f64> {
        Vector3::new(self.ee[3 * t], self.ee[3 * t + 1], self.ee[3 * t + 2])
    }

    fn ee_before(&self, t: usize) -> Vector3<f64> {
        if t == 0 {
            Vector3::from(self.start_ee)
        } else {
            self.ee_after(t - 1)
        }
    }
}

/// The relabelling state of a run: the episode under way and the goal sampler's random stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HerState {
    pub rng: Rng,
    pub log: EpisodeLog,
}

impl HerState {
    /// A fresh state drawing goals from `rng`.
    pub fn new(rng: Rng) -> HerState {
        HerState { rng, log: EpisodeLog::default() }
    }
}

/// One relabelled transition, as [`relabel`] hands it over.
pub struct Relabelled<'a> {
    /// The step of the episode it relabels (0-based).
    pub step: usize,
    /// The substituted goal (metres, base frame).
    pub goal: Vector3<f64>,
    pub obs: &'a [f32],
    pub action: &'a [f32],
    pub next_obs: &'a [f32],
    /// Every reward term for `goal`; `terms.total` is the stored reward.
    pub terms: RewardTerms,
    /// `goal` was reached, or the step ended in a contact that ends episodes
    /// (`task.on_collision = "terminate"`): a terminal transition.
    pub terminal: bool,
}

/// Relabels episodes; holds the observation buffers it writes the relabelled ones in (reused).
#[derive(Clone, Debug, Default)]
pub struct Relabeller {
    obs: Vec<f32>,
    next_obs: Vec<f32>,
}

impl Relabeller {
    /// Hand every relabelled transition of the episode in `log` to `sink`, in step order, the
    /// goals of each step drawn from `rng` by `cfg`'s strategy; observations and rewards as the
    /// environment of `task` and `reward` computes them.
    pub fn relabel(
        &mut self,
        cfg: &HerConfig,
        task: &ResolvedTask,
        reward: &RewardConfig,
        log: &EpisodeLog,
        rng: &mut Rng,
        mut sink: impl FnMut(&Relabelled<'_>),
    ) {
        let steps = log.len();
        if steps == 0 {
            return;
        }
        let od = log.obs.len() / steps;
        let ad = log.action.len() / steps;
        let dof = log.joint_vel.len() / steps;
        let layout = ObservationLayout::of(task);
        for t in 0..steps {
            for _ in 0..cfg.copies() {
                let g = match cfg.strategy {
                    HerStrategy::Future => t + rng.below((steps - t) as u64) as usize,
                    HerStrategy::Episode => rng.below(steps as u64) as usize,
                    HerStrategy::Final => steps - 1,
                };
                let goal = log.ee_after(g);
                let (before, after) = (log.ee_before(t), log.ee_after(t));
                self.obs.clear();
                self.obs.extend_from_slice(&log.obs[t * od..(t + 1) * od]);
                layout.write_target_entries(&mut self.obs, task.obs_delta_scale, before, goal);
                self.next_obs.clear();
                self.next_obs.extend_from_slice(&log.next_obs[t * od..(t + 1) * od]);
                layout.write_target_entries(&mut self.next_obs, task.obs_delta_scale, after, goal);
                let q = &log.quat[4 * t..4 * t + 4];
                let input = RewardInput {
                    ee_pos: after,
                    ee_quat: [q[0], q[1], q[2], q[3]],
                    target: goal,
                    joint_vel: &log.joint_vel[t * dof..(t + 1) * dof],
                    prev_ee_pos: Some(before),
                };
                let (contact, clearance) = (log.contact_after(t), log.clearance_after(t));
                let shield = log.shield_change_at(t);
                let step = Step::outcome(task, reward, &input, contact, clearance, shield, t as u32 + 1);
                sink(&Relabelled {
                    step: t,
                    goal,
                    obs: &self.obs,
                    action: &log.action[t * ad..(t + 1) * ad],
                    next_obs: &self.next_obs,
                    terminal: step.terminated,
                    terms: step.terms,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests;
