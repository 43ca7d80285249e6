//! Demonstrations from the reference planner (`[train.demonstrations]`, issue 34 item 4), stored
//! in an off-policy agent's replay buffer before its first training episode:
//!
//! 1. An environment of their own: the training environment's task and arm, its random stream
//!    drawn from the run's seed (`Rng::derived(seed, 6)`), every episode's first random obstacle
//!    across the straight line to the target with probability `obstacles_in_path`, up to the
//!    task's largest obstacle count (whatever a curriculum's stage).
//! 2. Demonstration `i`: reset, then RRT-Connect ([`RrtConnect::plan_timed`], seed
//!    `Rng::derived(seed, 7)`'s `i`-th draw, `max_iterations` and no wall-time budget) from the
//!    start pose to the target among the episode's obstacles grown by `clearance_m`, timed at
//!    `speed_fraction` of the joints' speed limits. An unsolved plan stores nothing.
//! 3. The plan played in the environment ([`track_waypoints`]: one waypoint per control step):
//!    each transition, with the reward training gives it, goes into the replay buffer; its
//!    observation joins `agent.norm_obs`'s statistics as an explored one would. A plan longer
//!    than `task.max_steps` ends at the step limit.
//!
//! They are not training environment steps (the run's budget, `learning_starts` and the logs
//! count those only), and with `agent.her` they are not relabelled. Deterministic: the same seed
//! and config store the same transitions on any machine and thread count.

use serde::{Deserialize, Serialize};

use crate::agent::replay::ReplayBuffer;
use crate::agent::OffPolicy;
use crate::base::rng::Rng;
use crate::config::DemonstrationsConfig;
use crate::env::{rollout, track_waypoints, Driver, Flow, Outcome, ReachEnv, Scratch, Transition};
use crate::sim::collision::ArmCollider;
use crate::sim::rrt_connect::RrtConnect;
use crate::{Error, Result};

/// What the demonstrations gave (saved in the run's checkpoints).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DemoStats {
    /// Episodes planned.
    pub episodes: u32,
    /// Plans RRT-Connect found (stored).
    pub solved: u32,
    /// Stored episodes that reached the target.
    pub reached: u32,
    /// Stored episodes with a contact (the environment's check at the control steps); `None`:
    /// no contact was looked for (an arm without collision shapes).
    pub collided: Option<u32>,
    /// Transitions stored in the replay buffer.
    pub transitions: u64,
}

/// Plan and store the demonstrations of `cfg` in `buffer`: `env` is the training environment as
/// the task makes it, `seed` the run's.
pub(super) fn demonstrate(
    cfg: &DemonstrationsConfig,
    seed: u64,
    mut env: ReachEnv,
    agent: &mut dyn OffPolicy,
    buffer: &mut ReplayBuffer,
) -> Result<DemoStats> {
    // 1. The environment.
    env.reseed(Rng::derived(seed, 6).next_u64());
    env.set_obstacles_in_path(cfg.obstacles_in_path)?;
    let mut collider = ArmCollider::new(env.chain(), env.task().collision);
    let mut scratch = Scratch::new(&env);
    let mut seeds = Rng::derived(seed, 7);
    let checked = env.collisions_checked();
    let mut stats =
        DemoStats { episodes: cfg.episodes, collided: checked.then_some(0), ..DemoStats::default() };
    let mut start = Vec::with_capacity(env.chain().dof());
    for _ in 0..cfg.episodes {
        // 2. The plan.
        env.reset();
        let rrt = RrtConnect {
            seed: seeds.next_u64(),
            budget_s: f64::INFINITY,
            max_iterations: cfg.max_iterations,
            margin_m: cfg.clearance_m,
            ..RrtConnect::default()
        };
        start.clear();
        start.extend_from_slice(env.joint_positions());
        let (_, path) = rrt.plan_timed(
            env.chain(),
            &mut collider,
            env.obstacles(),
            &start,
            &env.target(),
            // Waypoints `speed_fraction` of the limits apart: a step of `dt_s` at that speed.
            env.task().dt_s * cfg.speed_fraction,
        );
        let Ok(waypoints) = path else { continue };
        // 3. The plan played and stored.
        let mut d = Demonstrator {
            track: track_waypoints(&waypoints),
            agent: &mut *agent,
            buffer: &mut *buffer,
            n: 0,
        };
        let Outcome::Finished { last, .. } = rollout(&mut env, &mut scratch, &mut d)? else {
            return Err(Error::InvalidInput("a demonstration's rollout stopped before its end".into()));
        };
        stats.transitions += d.n;
        stats.solved += 1;
        stats.reached += u32::from(last.reached());
        if let Some(c) = &mut stats.collided {
            *c += u32::from(env.collision_steps() > 0);
        }
    }
    Ok(stats)
}

/// Step 3's driver: the plan's actions, every transition stored.
struct Demonstrator<'a, F> {
    track: F,
    agent: &'a mut dyn OffPolicy,
    buffer: &'a mut ReplayBuffer,
    /// Transitions stored.
    n: u64,
}

impl<F: FnMut(&ReachEnv, &mut [f32]) -> Result<()>> Driver for Demonstrator<'_, F> {
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()> {
        self.agent.observe(env.observation());
        (self.track)(env, action)
    }

    fn on_step(&mut self, t: &Transition<'_>) -> Result<Flow> {
        self.buffer.push(t.obs, t.action, t.step.total(), t.env.observation(), t.step.terminated);
        self.n += 1;
        Ok(Flow::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::Learner;
    use crate::config::Config;

    /// The demonstrations of `cfg` (run seed `seed`), the buffer they filled and the arrays.
    fn demos(cfg: &Config, seed: u64) -> (DemoStats, ReplayBuffer) {
        let run = cfg.resolve().unwrap();
        let env = run.env(1).unwrap();
        let Learner::OffPolicy(mut agent) = run.learner(2) else { panic!("an off-policy agent") };
        let mut buffer = ReplayBuffer::new(100_000, env.obs_dim(), env.act_dim()).unwrap();
        let d = cfg.train.demonstrations.clone().unwrap();
        let stats = demonstrate(&d, seed, env, agent.as_mut(), &mut buffer).unwrap();
        (stats, buffer)
    }

    fn config(extra: &str) -> Config {
        let text = format!("[agent]\nhidden = [16, 16]\n{extra}");
        Config::from_toml_str(&text, std::path::Path::new("t.toml")).unwrap()
    }

    #[test]
    fn free_space_demonstrations_reach_every_target_and_fill_the_buffer() {
        let cfg = config("[train.demonstrations]\nepisodes = 20\n");
        let (stats, buffer) = demos(&cfg, 3);
        assert_eq!(
            (stats.episodes, stats.solved, stats.reached, stats.collided),
            (20, 20, 20, Some(0)),
            "{stats:?}"
        );
        assert_eq!(buffer.len() as u64, stats.transitions);
        assert!(stats.transitions >= 20, "{stats:?}");
        let [(_, obs), (_, act), (_, rew), (_, next), (_, done)] = buffer.arrays();
        let n = buffer.len();
        // Actions within the speed limits, finite values everywhere, and one terminal
        // transition (the target reached) per episode.
        assert!(act[..n * 6].iter().all(|a| a.abs() <= 1.0));
        assert!([obs, rew, next].iter().all(|x| x[..n].iter().all(|v| v.is_finite())));
        assert_eq!(done[..n].iter().filter(|&&d| d == 1.0).count(), 20);
        // The same seed stores the same transitions; another seed others.
        let (again, b2) = demos(&cfg, 3);
        assert_eq!((stats, buffer.arrays()), (again, b2.arrays()));
        let (_, b3) = demos(&cfg, 4);
        assert_ne!(buffer.arrays()[0].1[..n], b3.arrays()[0].1[..n]);
        // At half the speed limits: actions within [-0.5, 0.5], about twice the steps.
        let slow = config("[train.demonstrations]\nepisodes = 20\nspeed_fraction = 0.5\n");
        let (s2, b2) = demos(&slow, 3);
        let m = b2.len();
        assert!(b2.arrays()[1].1[..m * 6].iter().all(|a| a.abs() <= 0.5 + 1e-6));
        assert!(b2.arrays()[1].1[..m * 6].iter().any(|a| a.abs() > 0.45), "the fastest joint near 0.5");
        assert!(s2.transitions as f64 > 1.6 * stats.transitions as f64, "{s2:?} vs {stats:?}");
    }

    #[test]
    fn demonstrations_go_round_obstacles_in_the_way_without_contact() {
        let cfg = config(
            "[task]\non_collision = \"terminate\"\nobserve_obstacles = true\nobstacle_observation = \"per_link\"\n\
             [task.random_obstacles]\ncount = [1, 3]\n[reward]\ncollision_penalty = 10.0\n\
             [train.demonstrations]\nepisodes = 30\nobstacles_in_path = 1.0\n",
        );
        let (stats, buffer) = demos(&cfg, 5);
        assert!(stats.solved >= 27 && stats.reached == stats.solved, "{stats:?}");
        assert_eq!(stats.collided, Some(0), "{stats:?}");
        // No contact penalty among the stored rewards (a contact ends an episode at -10 or below).
        let n = buffer.len();
        assert!(buffer.arrays()[2].1[..n].iter().all(|&r| r > -10.0));
    }
}
