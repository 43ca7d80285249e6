//! A batch of reaching environments stepped together, with automatic reset.

use std::sync::Arc;

use super::ResolvedTask;
use super::{ReachEnv, Step};
use crate::base::rng::Rng;
use crate::reward::RewardConfig;
use crate::robot::Chain;
use crate::{Error, Result};

/// `n` environments with flat, row-major observation and action buffers.
///
/// [`VecEnv::step`] steps every environment; one whose episode ends is reset at once (its next
/// episode's first observation goes to [`VecEnv::observations`]) and the observation it ended on is
/// kept in [`VecEnv::final_observations`], as bootstrapping through a truncation needs it.
/// Environment `i` draws its targets from `Rng::derived(seed, i)`.
///
/// [`VecEnv::step_next_step_reset`] steps with Gymnasium's next-step autoreset instead: an
/// environment whose episode ended stays at its last observation until the next call, which
/// resets it (with a seed given by the caller) instead of stepping it.
#[derive(Clone, Debug)]
pub struct VecEnv {
    envs: Vec<ReachEnv>,
    obs: Vec<f32>,
    final_obs: Vec<f32>,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    steps: Vec<Step>,
    autoreset: Vec<bool>,
}

/// The most environments one [`VecEnv`] holds: 65 536 (checked before any is allocated; a
/// PPO run uses at most `agent::ppo::MAX_PPO_ENVS`).
pub const MAX_VEC_ENVS: usize = 1 << 16;

impl VecEnv {
    /// `n >= 1` environments on one arm; each is reset.
    pub fn new(
        n: usize,
        chain: Arc<Chain>,
        task: ResolvedTask,
        reward: RewardConfig,
        seed: u64,
    ) -> Result<VecEnv> {
        super::check_parts(&chain, &task, &reward)?;
        VecEnv::assemble(n, chain, task, reward, seed)
    }

    /// [`VecEnv::new`] of parts checked already.
    pub(crate) fn assemble(
        n: usize,
        chain: Arc<Chain>,
        task: ResolvedTask,
        reward: RewardConfig,
        seed: u64,
    ) -> Result<VecEnv> {
        if n == 0 || n > MAX_VEC_ENVS {
            return Err(Error::config(
                "num_envs",
                n,
                format!(
                    "1 to {MAX_VEC_ENVS} environments in one vector env (each holds its own arm and scene)"
                ),
            ));
        }
        let mut envs = Vec::with_capacity(n);
        for i in 0..n {
            let mut e = ReachEnv::assemble(chain.clone(), task.clone(), reward.clone(), 0)?;
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
            steps: vec![Step::default(); n],
            autoreset: vec![false; n],
            envs,
        };
        for i in 0..n {
            v.obs[i * d..(i + 1) * d].copy_from_slice(v.envs[i].observation());
        }
        Ok(v)
    }

    /// [`ReachEnv::set_obstacles_in_path`] for every environment, from its next episode on
    /// (each environment's first episode was drawn by [`VecEnv::new`]).
    pub fn set_obstacles_in_path(&mut self, fraction: f64) -> Result<()> {
        self.envs.iter_mut().try_for_each(|e| e.set_obstacles_in_path(fraction))
    }

    /// Step every environment with `actions` (`len() * act_dim()` values, row-major).
    /// Allocation-free. On an error (bad action) no environment has been stepped.
    pub fn step(&mut self, actions: &[f32]) -> Result<()> {
        self.step_with(actions, None)
    }

    /// One step with Gymnasium's next-step autoreset: an environment whose episode ended in the
    /// previous call is not stepped but reset with `reset_seeds[i]` (its target stream reseeded,
    /// as [`ReachEnv::reset_with_seed`]; its reward 0, terminated and truncated false, marked in
    /// [`VecEnv::autoreset`]); every other environment is stepped, and one whose episode ends
    /// keeps its last observation. `reset_seeds` holds one seed per environment (read only for
    /// those reset). Allocation-free; on an error no environment has been stepped.
    pub fn step_next_step_reset(&mut self, actions: &[f32], reset_seeds: &[u64]) -> Result<()> {
        if reset_seeds.len() != self.envs.len() {
            return Err(Error::InvalidInput(format!(
                "reset_seeds has {} values, expected one per environment ({})",
                reset_seeds.len(),
                self.envs.len()
            )));
        }
        self.step_with(actions, Some(reset_seeds))
    }

    /// [`VecEnv::step`] (`reset_seeds` None: same-step autoreset from each environment's own
    /// stream) or [`VecEnv::step_next_step_reset`]. The environments are split into contiguous
    /// ranges over the pool installed on this thread ([`crate::base::par::split`]; serially
    /// without one or below [`PAR_MIN_ENVS`]): each environment's step is the same sequence of
    /// operations on any thread, so the results do not depend on the thread count. On an error
    /// of a simulator, the error of the lowest environment index is returned (the others were
    /// stepped).
    fn step_with(&mut self, actions: &[f32], reset_seeds: Option<&[u64]>) -> Result<()> {
        self.check_actions(actions)?;
        let n = self.envs.len();
        let out = Lanes {
            envs: self.envs.as_mut_ptr(),
            obs: self.obs.as_mut_ptr(),
            final_obs: self.final_obs.as_mut_ptr(),
            rewards: self.rewards.as_mut_ptr(),
            terminated: self.terminated.as_mut_ptr(),
            truncated: self.truncated.as_mut_ptr(),
            steps: self.steps.as_mut_ptr(),
            autoreset: self.autoreset.as_mut_ptr(),
            d: self.obs_dim(),
        };
        let (out, a) = (&out, self.act_dim());
        let first_error: std::sync::Mutex<Option<(usize, Error)>> = std::sync::Mutex::new(None);
        crate::base::par::split(n, 1, 1, PAR_MIN_ENVS, &|r: std::ops::Range<usize>| {
            // SAFETY: `split` hands out disjoint ranges of 0..n, so each range's lanes are
            // borrowed by this call alone, while `self` stays borrowed mutably until it returns.
            let mut lanes = unsafe { out.range(r.clone()) };
            if let Err((i, e)) = lanes.step(r.start, &actions[r.start * a..r.end * a], a, reset_seeds) {
                let mut first = first_error.lock().unwrap_or_else(|p| p.into_inner());
                if first.as_ref().is_none_or(|(j, _)| i < *j) {
                    *first = Some((i, e));
                }
            }
        });
        match first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
            Some((_, e)) => Err(e),
            None => Ok(()),
        }
    }

    /// `len() * act_dim()` finite values, or an error naming the first bad one.
    fn check_actions(&self, actions: &[f32]) -> Result<()> {
        let (n, a) = (self.envs.len(), self.act_dim());
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
        Ok(())
    }

    /// Reseed environment `i`'s target stream with `seed` and start its next episode (as
    /// [`ReachEnv::reset_with_seed`]); its observation row is updated.
    pub fn reset_env_with_seed(&mut self, i: usize, seed: u64) -> Result<()> {
        let d = self.obs_dim();
        let env = env_at(&mut self.envs, i)?;
        env.reset_with_seed(seed);
        self.obs[i * d..(i + 1) * d].copy_from_slice(env.observation());
        self.final_obs[i * d..(i + 1) * d].copy_from_slice(env.observation());
        self.autoreset[i] = false;
        Ok(())
    }

    /// From environment `i`'s next reset on, the scene of a request (see
    /// [`ReachEnv::set_request_obstacles`]; checked by the caller); `None` goes back to the
    /// task's scene.
    pub fn set_request_obstacles(
        &mut self,
        i: usize,
        obstacles: Option<&[crate::sim::scene::Obstacle]>,
    ) -> Result<()> {
        env_at(&mut self.envs, i)?.set_request_obstacles(obstacles);
        Ok(())
    }

    /// Every environment's state (for checkpoints).
    pub fn states(&self) -> Vec<super::EnvState> {
        self.envs.iter().map(ReachEnv::state).collect()
    }

    /// Restore the states of [`VecEnv::states`], one per environment; the observations follow.
    pub fn restore(&mut self, states: &[super::EnvState]) -> Result<()> {
        if states.len() != self.envs.len() {
            return Err(Error::InvalidInput(format!(
                "{} environment states for a vector env of {}",
                states.len(),
                self.envs.len()
            )));
        }
        let d = self.obs_dim();
        for (i, (env, s)) in self.envs.iter_mut().zip(states).enumerate() {
            env.restore(s)?;
            self.obs[i * d..(i + 1) * d].copy_from_slice(env.observation());
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
    /// Which environments the last [`VecEnv::step_next_step_reset`] reset instead of stepping
    /// (all false after [`VecEnv::step`]).
    pub fn autoreset(&self) -> &[bool] {
        &self.autoreset
    }
    /// The environments themselves.
    pub fn envs(&self) -> &[ReachEnv] {
        &self.envs
    }
}

/// Fewer environments than this are stepped on the calling thread alone (a step of the UR5
/// with its checks takes about a microsecond; waking a worker, a few).
pub const PAR_MIN_ENVS: usize = 16;

/// The start of each of a [`VecEnv`]'s buffers, for the ranges [`VecEnv::step_with`] splits
/// them into.
struct Lanes {
    envs: *mut ReachEnv,
    obs: *mut f32,
    final_obs: *mut f32,
    rewards: *mut f64,
    terminated: *mut bool,
    truncated: *mut bool,
    steps: *mut Step,
    autoreset: *mut bool,
    /// Observation values per environment.
    d: usize,
}

/// `ReachEnv` moves between threads in [`VecEnv::step_with`] (checked here, at compile time).
const _: fn() = || {
    fn send<T: Send>() {}
    send::<ReachEnv>();
};

// SAFETY: the pointers are only turned into slices of disjoint ranges (`Lanes::range`), one per
// task, while the `VecEnv` they point into is borrowed mutably by `step_with`; `ReachEnv` is `Send`.
unsafe impl Sync for Lanes {}

/// Environments `start..start + envs.len()` of a [`VecEnv`] with their rows of every buffer.
struct LaneRange<'a> {
    /// Observation values per environment.
    d: usize,
    envs: &'a mut [ReachEnv],
    obs: &'a mut [f32],
    final_obs: &'a mut [f32],
    rewards: &'a mut [f64],
    terminated: &'a mut [bool],
    truncated: &'a mut [bool],
    steps: &'a mut [Step],
    autoreset: &'a mut [bool],
}

impl Lanes {
    /// The lanes of environments `r`.
    ///
    /// # Safety
    /// `r` lies inside the vector env, and no other slice of these lanes overlapping `r` is
    /// alive while the result is.
    unsafe fn range(&self, r: std::ops::Range<usize>) -> LaneRange<'_> {
        use std::slice::from_raw_parts_mut as part;
        let (k, len, d) = (r.start, r.len(), self.d);
        LaneRange {
            d,
            envs: part(self.envs.add(k), len),
            obs: part(self.obs.add(k * d), len * d),
            final_obs: part(self.final_obs.add(k * d), len * d),
            rewards: part(self.rewards.add(k), len),
            terminated: part(self.terminated.add(k), len),
            truncated: part(self.truncated.add(k), len),
            steps: part(self.steps.add(k), len),
            autoreset: part(self.autoreset.add(k), len),
        }
    }
}

impl LaneRange<'_> {
    /// Step (or, with `reset_seeds`, reset the ended) environments of this range, the first
    /// being environment `start`; `actions` holds this range's rows (`a` values each). Stops at
    /// the first error, returned with its environment's index.
    fn step(
        &mut self,
        start: usize,
        actions: &[f32],
        a: usize,
        reset_seeds: Option<&[u64]>,
    ) -> std::result::Result<(), (usize, Error)> {
        let d = self.d;
        for (j, env) in self.envs.iter_mut().enumerate() {
            let row = j * d..(j + 1) * d;
            let reset_seed = reset_seeds.filter(|_| env.is_done()).map(|s| s[start + j]);
            self.autoreset[j] = reset_seed.is_some();
            if let Some(seed) = reset_seed {
                env.reset_with_seed(seed);
                self.rewards[j] = 0.0;
                self.terminated[j] = false;
                self.truncated[j] = false;
                self.steps[j] = Step::default();
                self.final_obs[row.clone()].copy_from_slice(env.observation());
                self.obs[row].copy_from_slice(env.observation());
                continue;
            }
            let s = env.step(&actions[j * a..(j + 1) * a]).map_err(|e| (start + j, e))?;
            self.rewards[j] = s.total();
            self.terminated[j] = s.terminated;
            self.truncated[j] = s.truncated;
            self.steps[j] = s;
            self.final_obs[row.clone()].copy_from_slice(env.observation());
            if s.done() && reset_seeds.is_none() {
                env.reset();
            }
            self.obs[row].copy_from_slice(env.observation());
        }
        Ok(())
    }
}

/// Environment `i` of `envs`, or an error naming the indices that exist.
fn env_at(envs: &mut [ReachEnv], i: usize) -> Result<&mut ReachEnv> {
    let n = envs.len();
    envs.get_mut(i).ok_or_else(|| {
        Error::InvalidInput(format!(
            "environment {i} does not exist: the vector env holds {n} (0 to {})",
            n - 1
        ))
    })
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
    fn next_step_autoreset_resets_ended_envs_on_the_next_call() {
        let n = 3;
        let mut v = ur5_vec(n, 2).unwrap();
        let mut singles: Vec<ReachEnv> = (0..n).map(|i| v.envs()[i].clone()).collect();
        let mut rng = Rng::new(4);
        let (mut ends, mut autoresets) = (0, 0);
        for k in 0..150u64 {
            let actions: Vec<f32> = (0..n * 6).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
            let seeds: Vec<u64> = (0..n as u64).map(|i| 1000 * k + i).collect();
            let was_done: Vec<bool> = v.envs().iter().map(ReachEnv::is_done).collect();
            v.step_next_step_reset(&actions, &seeds).unwrap();
            for (i, e) in singles.iter_mut().enumerate() {
                assert_eq!(v.autoreset()[i], was_done[i]);
                if was_done[i] {
                    e.reset_with_seed(seeds[i]);
                    autoresets += 1;
                    assert_eq!((v.rewards()[i], v.terminated()[i], v.truncated()[i]), (0.0, false, false));
                } else {
                    let s = e.step(&actions[i * 6..(i + 1) * 6]).unwrap();
                    assert_eq!(v.rewards()[i], s.total());
                    assert_eq!((v.terminated()[i], v.truncated()[i]), (s.terminated, s.truncated));
                    ends += usize::from(s.done());
                }
                // An ended episode keeps its last observation until the next call.
                assert_eq!(&v.observations()[i * 16..(i + 1) * 16], e.observation());
                assert_eq!(v.envs()[i].target(), e.target());
            }
        }
        assert!(ends >= 6 && autoresets >= ends - n, "{ends} episode ends, {autoresets} autoresets");
        assert!(v.step_next_step_reset(&[0.0; 18], &[0; 2]).is_err());
        v.reset_env_with_seed(1, 9).unwrap();
        singles[1].reset_with_seed(9);
        assert_eq!(&v.observations()[16..32], singles[1].observation());
        assert!(v.reset_env_with_seed(3, 0).unwrap_err().to_string().contains("environment 3"));
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

    /// Split over pools of 2 and 3 threads (with random obstacles, their observation and
    /// contacts ending episodes), both autoreset modes give the serial run's bits, step by step.
    #[test]
    fn threads_do_not_change_a_step() {
        let chain = Arc::new(Chain::ur5());
        let task = super::super::TaskConfig {
            random_obstacles: Some(crate::sim::scene::RandomObstacles::default()),
            observe_obstacles: true,
            on_collision: crate::env::OnCollision::Terminate,
            ..Default::default()
        };
        let task = task.resolve(&chain).unwrap();
        let n = 3 * PAR_MIN_ENVS + 5;
        let run = |threads: usize, next_step: bool| {
            let pool = crate::base::par::Pool::new(threads).unwrap();
            let mut v = VecEnv::new(n, chain.clone(), task.clone(), RewardConfig::default(), 7).unwrap();
            let mut rng = Rng::new(3);
            let mut trace: Vec<u64> = Vec::new();
            crate::base::par::install(Some(&pool), || {
                for k in 0..150u64 {
                    let actions: Vec<f32> = (0..n * 6).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
                    if next_step {
                        let seeds: Vec<u64> = (0..n as u64).map(|i| 1000 * k + i).collect();
                        v.step_next_step_reset(&actions, &seeds).unwrap();
                    } else {
                        v.step(&actions).unwrap();
                    }
                    trace.extend(v.observations().iter().map(|x| u64::from(x.to_bits())));
                    trace.extend(v.final_observations().iter().map(|x| u64::from(x.to_bits())));
                    trace.extend(v.rewards().iter().map(|x| x.to_bits()));
                    trace.extend(
                        v.terminated()
                            .iter()
                            .zip(v.truncated())
                            .map(|(&a, &b)| u64::from(a) + 2 * u64::from(b)),
                    );
                    trace.extend(v.autoreset().iter().map(|&a| u64::from(a)));
                    trace.extend(
                        v.last_steps().iter().map(|s| s.total().to_bits() ^ u64::from(s.collision.is_some())),
                    );
                }
            });
            trace
        };
        for next_step in [false, true] {
            let split = crate::base::par::split_jobs();
            let serial = run(1, next_step);
            let two = run(2, next_step);
            assert!(crate::base::par::split_jobs() > split, "the steps were split over the pool");
            let three = run(3, next_step);
            assert_eq!(serial.len(), two.len());
            assert!(
                serial == two && serial == three,
                "a thread count changed a step (next_step {next_step})"
            );
        }
    }
}
