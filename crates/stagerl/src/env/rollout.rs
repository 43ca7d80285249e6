//! The episode rollout of eq. 16, written once: act, step, add the step's reward (bonus included)
//! to `R_episode = sum_t r_t`, until the target is reached or the step limit hit.
//!
//! Who chooses the action and what is seen at each step is the [`Driver`]'s: the agent's
//! deterministic policy in evaluation, exploration plus the updates of Algorithm 1 in training,
//! the scripted controller in the demo. The loop allocates nothing.

use super::{ReachEnv, Step};
use crate::Result;

/// What a driver tells the rollout after a step that did not end the episode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    Continue,
    /// Leave the episode unfinished (a stop request); the environment stays mid-episode.
    Stop,
}

/// One step as a driver sees it, after the environment has taken it.
pub struct Transition<'a> {
    /// The observation the action was chosen on.
    pub obs: &'a [f32],
    pub action: &'a [f32],
    pub step: &'a Step,
    /// The environment after the step.
    pub env: &'a ReachEnv,
}

/// Who chooses the actions of a rollout and what it observes at each step.
pub trait Driver {
    /// Write the action for `env`'s current observation (`env.observation()`) into `action`.
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()>;
    /// See a step. [`Flow::Stop`] leaves the episode unfinished (ignored on its last step).
    fn on_step(&mut self, _t: &Transition<'_>) -> Result<Flow> {
        Ok(Flow::Continue)
    }
}

/// A driver of two closures: a policy and an observer that share no state.
pub struct Observed<P, O>(pub P, pub O);

impl<P, O> Driver for Observed<P, O>
where
    P: FnMut(&ReachEnv, &mut [f32]) -> Result<()>,
    O: FnMut(&Transition<'_>) -> Result<Flow>,
{
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()> {
        (self.0)(env, action)
    }
    fn on_step(&mut self, t: &Transition<'_>) -> Result<Flow> {
        (self.1)(t)
    }
}

/// A driver that only chooses actions.
pub struct Policy<P>(pub P);

impl<P: FnMut(&ReachEnv, &mut [f32]) -> Result<()>> Driver for Policy<P> {
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()> {
        (self.0)(env, action)
    }
}

/// How a rollout ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// The episode ended: `reward` is eq. 16's `R_episode` over the steps of this rollout,
    /// `last` the final step (terminated: the target was reached).
    Finished { reward: f64, last: Step },
    /// The driver stopped it mid-episode.
    Stopped,
}

/// The scratch a rollout works in (the observation an action is chosen on, the action),
/// allocated once per environment shape.
pub struct Scratch {
    obs: Vec<f32>,
    action: Vec<f32>,
}

impl Scratch {
    pub fn new(env: &ReachEnv) -> Scratch {
        Scratch { obs: vec![0.0; env.obs_dim()], action: vec![0.0; env.act_dim()] }
    }
}

/// Roll out `env` from its current state (reset it first for a new episode; a restored
/// mid-episode state continues) until the episode ends (eq. 16) or `driver` stops it.
pub fn rollout(env: &mut ReachEnv, scratch: &mut Scratch, driver: &mut impl Driver) -> Result<Outcome> {
    let mut reward = 0.0;
    loop {
        scratch.obs.copy_from_slice(env.observation());
        driver.act(env, &mut scratch.action)?;
        let step = env.step(&scratch.action)?;
        reward += step.total();
        let flow =
            driver.on_step(&Transition { obs: &scratch.obs, action: &scratch.action, step: &step, env })?;
        if step.done() {
            return Ok(Outcome::Finished { reward, last: step });
        }
        if flow == Flow::Stop {
            return Ok(Outcome::Stopped);
        }
    }
}

/// A policy that follows `waypoints` (one per control step, the first the start): the action
/// that takes the arm from where it is to the next waypoint, clipped to [-1, 1]; at rest past
/// the last.
pub fn track_waypoints(waypoints: &[Vec<f64>]) -> impl FnMut(&ReachEnv, &mut [f32]) -> Result<()> + '_ {
    move |env, action| {
        let k = (env.steps() as usize + 1).min(waypoints.len().saturating_sub(1));
        let (q, v, dt) = (env.joint_positions(), env.chain().velocity_limits(), env.task().dt_s);
        for (i, a) in action.iter_mut().enumerate() {
            let next = waypoints.get(k).map_or(q[i], |w| w[i]);
            *a = ((next - q[i]) / (v[i] * dt)).clamp(-1.0, 1.0) as f32;
        }
        Ok(())
    }
}
