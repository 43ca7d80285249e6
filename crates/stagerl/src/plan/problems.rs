//! The obstacle benchmark's problem sets (`stagerl bench obstacles`): fixed, seeded reaching
//! problems on the task's arm, each a start pose (the task's home pose, radians), a target
//! (metres, base frame) drawn from the task's target distribution, and a scene.
//!
//! 1. `free`: no obstacle.
//! 2. `in-the-way`: one obstacle (a sphere or an axis-aligned box, sizes 0.04-0.1 m, the task's
//!    `[task.random_obstacles]` defaults) placed across the straight line from the start pose's
//!    end effector to the target, as `stagerl eval --obstacles-in-path 1` places it; a draw whose
//!    obstacle misses the line (the placement fell back to anywhere) is drawn again.
//! 3. `random-3`, `random-6`: 3 or 6 such obstacles anywhere in the region, clear of the arm at
//!    its start pose and 5 cm from the target (the task's placement rule).
//! 4. `narrow-gap`: a wall of two boxes (0.04 m thick, 0.5 m wide, 0.7 m high, standing on the
//!    floor) across the line at its middle, perpendicular to it in the horizontal plane, with a
//!    vertical gap of [`GAP_M`] between them centred on the line; targets less than 0.3 m from
//!    the start end effector horizontally, or scenes touching the start pose or within 5 cm of
//!    the target, are drawn again.
//!
//! Every set is drawn from its own stream (`seed` and the set's index), so a set does not change
//! when another is added or resized. `solvable` is asked of each candidate (the benchmark asks
//! the reference planner with a generous budget): problems it refuses are drawn again and
//! counted, so that every kept problem is known to be solvable.

use nalgebra::Vector3;
use serde::Serialize;

use crate::base::rng::Rng;
use crate::config::Config;
use crate::env::ReachEnv;
use crate::sim::collision::ArmCollider;
use crate::sim::scene::{Obstacle, ObstacleShape, RandomObstacles};
use crate::{Error, Result};

/// The width of the narrow gap, metres.
pub const GAP_M: f64 = 0.2;
/// Candidates drawn per kept problem before a set is given up (with an error).
const TRIES_PER_PROBLEM: usize = 200;
/// The index of the problem sets' streams ([`Rng::derived`]), plus the set's index.
const PROBLEM_STREAM: u64 = 0x0B57_AC1E_5E75_0000;

/// A problem set of the benchmark (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProblemSet {
    Free,
    InTheWay,
    #[serde(rename = "random-3")]
    Random3,
    #[serde(rename = "random-6")]
    Random6,
    NarrowGap,
}

impl ProblemSet {
    /// Every set, in the benchmark's order.
    pub const ALL: [ProblemSet; 5] = [
        ProblemSet::Free,
        ProblemSet::InTheWay,
        ProblemSet::Random3,
        ProblemSet::Random6,
        ProblemSet::NarrowGap,
    ];

    /// The set's name (as the CLI and the output write it).
    pub fn name(self) -> &'static str {
        match self {
            ProblemSet::Free => "free",
            ProblemSet::InTheWay => "in-the-way",
            ProblemSet::Random3 => "random-3",
            ProblemSet::Random6 => "random-6",
            ProblemSet::NarrowGap => "narrow-gap",
        }
    }

    /// The set named `name` (as [`ProblemSet::name`] writes it).
    pub fn from_name(name: &str) -> Option<ProblemSet> {
        ProblemSet::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The random obstacles of the set's scenes (`None`: none, or built by hand).
    fn random_obstacles(self) -> Option<RandomObstacles> {
        let count = match self {
            ProblemSet::InTheWay => 1,
            ProblemSet::Random3 => 3,
            ProblemSet::Random6 => 6,
            ProblemSet::Free | ProblemSet::NarrowGap => return None,
        };
        Some(RandomObstacles { count: [count, count], ..RandomObstacles::default() })
    }
}

/// One problem: plan from `start_rad` to `target_m` among `obstacles`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Problem {
    pub set: ProblemSet,
    /// Index within its set.
    pub id: usize,
    pub start_rad: Vec<f64>,
    pub target_m: [f64; 3],
    pub obstacles: Vec<Obstacle>,
}

/// Draw `count` problems of `set` on the task and arm of `cfg` (its own obstacles are not
/// used), each accepted by `solvable`. Returns the problems and how many candidates `solvable`
/// refused. Errors: the config's, or no `count` problems within [`TRIES_PER_PROBLEM`] candidates
/// each.
pub fn draw_problems(
    cfg: &Config,
    set: ProblemSet,
    count: usize,
    seed: u64,
    solvable: &mut dyn FnMut(&Problem) -> bool,
) -> Result<(Vec<Problem>, usize)> {
    let mut cfg = cfg.clone();
    cfg.task.obstacles.clear();
    cfg.task.random_obstacles = set.random_obstacles();
    // The problems do not depend on what a policy observes.
    cfg.task.observe_obstacles = false;
    cfg.task.obstacle_observation = Default::default();
    cfg.task.obstacle_range_m = None;
    // Nor on the reward (whose clearance term needs obstacles, which a free-space set lacks).
    cfg.reward.clearance = None;
    cfg.train.obstacles_in_path = 0.0;
    // Nor on the training schedule (a curriculum needs random obstacles: a free set has none).
    cfg.train.curriculum = None;
    let index = ProblemSet::ALL.iter().position(|&s| s == set).unwrap_or(0) as u64;
    let mut env = ReachEnv::from_config(&cfg, 0)?;
    if set == ProblemSet::InTheWay {
        env.set_obstacles_in_path(1.0)?;
    }
    let mut collider = ArmCollider::new(env.chain(), env.task().collision);
    let mut rng = Rng::derived(seed, PROBLEM_STREAM + index);
    let (mut problems, mut refused) = (Vec::with_capacity(count), 0usize);
    let start = env.task().home_pose.clone();
    for _ in 0..count.saturating_mul(TRIES_PER_PROBLEM) {
        if problems.len() == count {
            break;
        }
        env.reset_with_seed(rng.next_u64());
        let target = env.target();
        let from: Vector3<f64> = env.ee_pose().position;
        let obstacles = match set {
            ProblemSet::Free => Vec::new(),
            ProblemSet::InTheWay => {
                let o = env.obstacles().to_vec();
                if o.len() != 1 || !crosses_segment(&o[0], from, target) {
                    continue;
                }
                o
            }
            ProblemSet::Random3 | ProblemSet::Random6 => {
                let o = env.obstacles().to_vec();
                if o.len() != set.random_obstacles().map_or(0, |r| r.count[0] as usize) {
                    continue;
                }
                o
            }
            ProblemSet::NarrowGap => {
                let Some(o) = narrow_gap(from, target) else { continue };
                collider.set_obstacles(&o);
                let clear_target = o.iter().all(|b| b.distance_to_point_m(target.into()) >= 0.05);
                if !clear_target || collider.check(env.chain(), &start).is_some() {
                    continue;
                }
                o
            }
        };
        let p =
            Problem { set, id: problems.len(), start_rad: start.clone(), target_m: target.into(), obstacles };
        if solvable(&p) {
            problems.push(p);
        } else {
            refused += 1;
        }
    }
    if problems.len() < count {
        return Err(Error::InvalidInput(format!(
            "problem set `{}`: only {} of {count} problems found in {} candidates ({refused} refused as \
             not solvable); the arm's task may not fit the set's scenes",
            set.name(),
            problems.len(),
            count * TRIES_PER_PROBLEM
        )));
    }
    Ok((problems, refused))
}

/// Whether `o` touches the segment from `a` to `b` (checked every 5 mm).
fn crosses_segment(o: &Obstacle, a: Vector3<f64>, b: Vector3<f64>) -> bool {
    let n = ((b - a).norm() / 0.005).ceil().max(1.0) as usize;
    (0..=n).any(|k| {
        let p = a + (b - a) * (k as f64 / n as f64);
        o.distance_to_point_m(p.into()) <= 0.0
    })
}

/// The two boxes of a wall across the line from `from` to `to` at its middle, with a vertical
/// gap of [`GAP_M`] centred on it (`None` when the two are closer than 0.3 m horizontally).
fn narrow_gap(from: Vector3<f64>, to: Vector3<f64>) -> Option<Vec<Obstacle>> {
    let d = Vector3::new(to.x - from.x, to.y - from.y, 0.0);
    if d.norm() < 0.3 {
        return None;
    }
    let u = d / d.norm();
    let v = Vector3::new(-u.y, u.x, 0.0);
    let mid = (from + to) / 2.0;
    let (half_width, half_height, half_thickness) = (0.25, 0.35, 0.02);
    let yaw = u.y.atan2(u.x);
    let rotation = [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()];
    let side = |s: f64| {
        let c = mid + v * (s * (GAP_M / 2.0 + half_width));
        Obstacle {
            shape: ObstacleShape::Cuboid,
            half_extents_m: Some([half_thickness, half_width, half_height]),
            radius_m: None,
            position_m: [c.x, c.y, half_height],
            rotation_xyzw: Some(rotation),
        }
    };
    Some(vec![side(1.0), side(-1.0)])
}

/// One problem of [`obstacle_in_path`]: the target (metres) and the scene, from the task's home
/// pose.
#[derive(Clone, Debug, PartialEq)]
pub struct InPathProblem {
    pub target: [f64; 3],
    pub obstacles: Vec<Obstacle>,
}

/// `count` problems of `stagerl eval --obstacles-in-path 1`'s set (`stagerl bench rrt-connect`):
/// the task of `cfg` with one random obstacle per episode (`[task.random_obstacles]` with
/// `count = [1, 1]`, its other settings `cfg`'s or the defaults) placed in the way from the
/// start pose's end effector to the target (`train.obstacles_in_path = 1`); problem `k` is
/// episode `k` of evaluation seed `seed` (the first after `reset_with_seed(seed)`, then
/// `reset()`). Unlike [`ProblemSet::InTheWay`], an obstacle whose placement in the way failed
/// (it went anywhere) is kept, as the evaluation keeps it.
pub fn obstacle_in_path(cfg: &Config, count: usize, seed: u64) -> Result<Vec<InPathProblem>> {
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
        out.push(InPathProblem { target: [t.x, t.y, t.z], obstacles: env.obstacles().to_vec() });
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
