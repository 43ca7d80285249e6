//! A run's config checked once and resolved against its arm ([`Config::resolve`]): what the
//! environments, the agent and the trainer are built from without checking again.
//!
//! A config reaches a run through one check: [`Config::from_toml_str`] checks the file's values
//! when it is read (a bad file is refused at once); the command line's overrides are applied to
//! the [`Config`]; then [`Config::resolve`] checks every value again with the overrides, loads
//! the arm, resolves the task's per-joint values against it and checks the task, the reward's
//! collision settings and the memory estimate for that arm. The constructors that take raw
//! parts ([`ReachEnv::new`], [`VecEnv::new`], [`crate::agent::build`]) check them, for callers
//! that assemble their own; those of [`Resolved`] do not.

use std::sync::Arc;

use super::Config;
use crate::agent::{self, Learner};
use crate::env::{ObservationLayout, ReachEnv, ResolvedTask, VecEnv};
use crate::robot::Chain;
use crate::Result;

/// A config checked and resolved against its arm.
#[derive(Clone, Debug)]
pub struct Resolved {
    config: Config,
    chain: Arc<Chain>,
    task: ResolvedTask,
}

impl Config {
    /// Check every value, load the arm (`robot.urdf`) and resolve the task against it: the one
    /// check of a run's config (see the module's documentation).
    pub fn resolve(&self) -> Result<Resolved> {
        self.validate()?;
        let chain = Arc::new(self.robot.load()?);
        // The memory estimate again, with the arm's own joint count.
        self.check_memory(chain.dof())?;
        let task = self.task.resolve_checked(&chain)?;
        crate::env::check_task_for_arm(&chain, &task)?;
        crate::env::check_clearance_settings(&chain, &task, &self.reward)?;
        crate::env::check_shield_penalty(&task, &self.reward)?;
        Ok(Resolved { config: self.clone(), chain, task })
    }
}

impl Resolved {
    /// The config, as given (its agent section with every algorithm's).
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The arm.
    pub fn chain(&self) -> &Arc<Chain> {
        &self.chain
    }

    /// The task resolved for the arm.
    pub fn task(&self) -> &ResolvedTask {
        &self.task
    }

    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        ObservationLayout::of(&self.task).dim()
    }

    /// Action length: one joint velocity per joint.
    pub fn act_dim(&self) -> usize {
        self.chain.dof()
    }

    /// An environment, its targets drawn from `seed`.
    pub fn env(&self, seed: u64) -> Result<ReachEnv> {
        ReachEnv::assemble(self.chain.clone(), self.task.clone(), self.config.reward.clone(), seed)
    }

    /// `n` environments stepped together, their targets drawn from `seed`.
    pub fn vec_env(&self, n: usize, seed: u64) -> Result<VecEnv> {
        VecEnv::assemble(n, self.chain.clone(), self.task.clone(), self.config.reward.clone(), seed)
    }

    /// The agent of `agent.algo` with its kind of learning, its initial weights and noise drawn
    /// from `seed`.
    pub fn learner(&self, seed: u64) -> Learner {
        agent::learner_of(&self.config.agent, self.obs_dim(), self.act_dim(), seed)
    }
}
