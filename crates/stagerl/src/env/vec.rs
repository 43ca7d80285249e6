//! A batch of reaching environments stepped together, with automatic reset.

use std::sync::Arc;

use super::ResolvedTask;
use super::{ReachEnv, Step};
use crate::reward::RewardConfig;
use crate::rng::Rng;
use crate::robot::Chain;
use crate::{Error, Result};

/// `n` environments with flat, row-major observation and action buffers.
///
/// [`VecEnv::step`] steps every environment; one whose episode ends is reset at once (its next
/// episode's first observation goes to [`VecEnv::observations`]) and the observation it ended on is
/// kept in [`VecEnv::final_observations`], as bootstrapping through a truncation needs it.
/// Environment `i` draws its targets from `Rng::derived(seed, i)`.
#[derive(Clone, Debug)]
pub struct VecEnv {
    envs: Vec<ReachEnv>,
    obs: Vec<f32>,
    final_obs: Vec<f32>,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    steps: Vec<Step>,
}

impl VecEnv {
    /// `n >= 1` environments on one arm; each is reset.
    pub fn new(
        n: usize,
        chain: Arc<Chain>,
        task: ResolvedTask,
        reward: RewardConfig,
        seed: u64,
    ) -> Result<VecEnv> {
        if n == 0 {
            return Err(Error::InvalidInput("a vector env needs at least one environment".into()));
        }
        let mut envs = Vec::with_capacity(n);
        for i in 0..n {
            let mut e = ReachEnv::new(chain.clone(), task.clone(), reward.clone(), 0)?;
            e.set_rng(Rng::derived(seed, i as u64));
            e.reset();
            envs.push(e);
        }
        let d = envs[0].obs_dim();
        let mut v = VecEnv {
            obs: vec![0.0; n * d],
            final_obs: vec![0.0; n * d],
            rewards: vec![0.0; n],
            terminated: vec![false; n],
            truncated: vec![false; n],
            steps: vec![Step { terms: Default::default(), terminated: false, truncated: false }; n],
            envs,
        };
        for i in 0..n {
            v.obs[i * d..(i + 1) * d].copy_from_slice(v.envs[i].observation());
        }
        Ok(v)
    }

    /// Step every environment with `actions` (`len() * act_dim()` values, row-major).
    /// Allocation-free. On an error (bad action) no environment has been stepped.
    pub fn step(&mut self, actions: &[f32]) -> Result<()> {
        let (n, a, d) = (self.envs.len(), self.act_dim(), self.obs_dim());
        if actions.len() != n * a {
            return Err(Error::InvalidInput(format!(
                "actions has {} values, expected {n} environments x {a} joints = {}",
                actions.len(),
                n * a
            )));
        }
        if let Some(k) = actions.iter().position(|x| !x.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "action {k} (environment {}, joint {}) = {} is not finite",
                k / a,
                k % a,
                actions[k]
            )));
        }
        for (i, env) in self.envs.iter_mut().enumerate() {
            let s = env.step(&actions[i * a..(i + 1) * a])?;
            self.rewards[i] = s.total();
            self.terminated[i] = s.terminated;
            self.truncated[i] = s.truncated;
            self.steps[i] = s;
            let row = i * d..(i + 1) * d;
            self.final_obs[row.clone()].copy_from_slice(env.observation());
            if s.done() {
                env.reset();
            }
            self.obs[row].copy_from_slice(env.observation());
        }
        Ok(())
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }
    /// Always false: a vector env holds at least one environment.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }
    pub fn obs_dim(&self) -> usize {
        self.envs[0].obs_dim()
    }
    pub fn act_dim(&self) -> usize {
        self.envs[0].act_dim()
    }
    /// Current observations (after any automatic reset), `len() x obs_dim()`.
    pub fn observations(&self) -> &[f32] {
        &self.obs
    }
    /// The observations each environment reached in the last step, before any reset.
    pub fn final_observations(&self) -> &[f32] {
        &self.final_obs
    }
    /// Rewards of the last step (bonus included).
    pub fn rewards(&self) -> &[f64] {
        &self.rewards
    }
    pub fn terminated(&self) -> &[bool] {
        &self.terminated
    }
    pub fn truncated(&self) -> &[bool] {
        &self.truncated
    }
    /// Every reward term of the last step, per environment.
    pub fn last_steps(&self) -> &[Step] {
        &self.steps
    }
    /// The environments themselves.
    pub fn envs(&self) -> &[ReachEnv] {
        &self.envs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ur5_vec(n: usize, seed: u64) -> Result<VecEnv> {
        let chain = Arc::new(Chain::ur5());
        let task = super::super::TaskConfig::default().resolve(&chain).unwrap();
        VecEnv::new(n, chain, task, RewardConfig::default(), seed)
    }

    #[test]
    fn matches_independent_envs_and_autoresets() {
        let n = 3;
        let mut v = ur5_vec(n, 5).unwrap();
        let mut singles: Vec<ReachEnv> = (0..n)
            .map(|i| {
                let mut e = crate::env::tests::ur5_env(RewardConfig::default(), 0);
                e.set_rng(Rng::derived(5, i as u64));
                e.reset();
                e
            })
            .collect();
        assert_eq!(v.observations().len(), n * 16);
        let mut rng = Rng::new(1);
        let mut resets = 0;
        for _ in 0..120 {
            let actions: Vec<f32> = (0..n * 6).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
            v.step(&actions).unwrap();
            for (i, e) in singles.iter_mut().enumerate() {
                let s = e.step(&actions[i * 6..(i + 1) * 6]).unwrap();
                assert_eq!(v.rewards()[i], s.total());
                assert_eq!(v.truncated()[i], s.truncated);
                assert_eq!(&v.final_observations()[i * 16..(i + 1) * 16], e.observation());
                if s.done() {
                    e.reset();
                    resets += 1;
                }
                assert_eq!(&v.observations()[i * 16..(i + 1) * 16], e.observation());
            }
        }
        assert!(resets >= 6, "120 steps of 3 envs hold at least 6 episode ends, saw {resets}");
        // Environments draw different targets.
        assert_ne!(v.envs()[0].target(), v.envs()[1].target());
    }

    #[test]
    fn rejects_bad_actions_before_stepping_any_env() {
        let mut v = ur5_vec(2, 1).unwrap();
        assert!(v.step(&[0.0; 11]).is_err());
        let mut a = [0.0f32; 12];
        a[8] = f32::NAN;
        let e = v.step(&a).unwrap_err().to_string();
        assert!(e.contains("environment 1, joint 2"), "{e}");
        assert!(v.envs().iter().all(|e| e.steps() == 0));
        assert!(ur5_vec(0, 1).is_err());
    }
}
