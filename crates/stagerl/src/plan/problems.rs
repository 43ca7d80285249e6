//! Seeded planning problems for benchmarks (`stagerl bench rrt-connect`): "one obstacle across
//! the straight line", the set `stagerl eval --obstacles-in-path 1` evaluates on. The task is
//! `cfg`'s with one random obstacle per episode (`[task.random_obstacles]` with `count = [1,
//! 1]`, the other settings the defaults unless `cfg` sets them) placed in the way from the start
//! pose's end effector to the target (`train.obstacles_in_path = 1`); problem `k` is episode
//! `k` of evaluation seed `seed` (the first after `reset_with_seed(seed)`, then `reset()`).

use crate::config::Config;
use crate::env::ReachEnv;
use crate::sim::scene::{Obstacle, RandomObstacles};
use crate::Result;

/// One problem: the target (metres) and the scene, from the task's home pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    pub target: [f64; 3],
    pub obstacles: Vec<Obstacle>,
}

/// `count` problems with one obstacle in the way, of evaluation seed `seed`, on the arm and task
/// of `cfg` (see the module's doc).
pub fn obstacle_in_path(cfg: &Config, count: usize, seed: u64) -> Result<Vec<Problem>> {
    let mut cfg = cfg.clone();
    let random = cfg.task.random_obstacles.take().unwrap_or_default();
    cfg.task.random_obstacles = Some(RandomObstacles { count: [1, 1], ..random });
    let mut env = ReachEnv::from_config(&cfg, 0)?;
    env.set_obstacles_in_path(1.0)?;
    let mut out = Vec::with_capacity(count);
    for k in 0..count {
        if k == 0 {
            env.reset_with_seed(seed);
        } else {
            env.reset();
        }
        let t = env.target();
        out.push(Problem { target: [t.x, t.y, t.z], obstacles: env.obstacles().to_vec() });
    }
    Ok(out)
}
