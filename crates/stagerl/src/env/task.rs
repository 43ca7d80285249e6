//! The reaching task's section of the config (`[task]`): control period, episode length, home
//! pose, the target distribution and the observation layout; resolved against an arm, and the
//! target sampling that resolution makes safe.

use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;

use crate::base::rng::Rng;
use crate::robot::{Chain, JointKind};
use crate::sim::collision::Checks;
use crate::sim::scene::{Obstacle, RandomObstacles, MAX_OBSTACLES};
use crate::sim::shield::ShieldConfig;
use crate::{Error, Result};

/// What the policy observes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ObservationKind {
    /// N + 10 values (16 for six joints), f32: q / pi (N), end-effector position (3, m),
    /// target (3, m), k (target - end-effector) (3, m), k D_PT (1, m), with
    /// k = `task.obs_delta_scale`.
    Standard,
}

/// The reaching task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// Control period: each joint-velocity command is held this long, seconds (paper: 0.05).
    pub dt_s: f64,
    /// Steps before an episode is truncated (paper: 50).
    pub max_steps: u32,
    /// Pose every episode starts from, radians (metres for prismatic joints). Unset: the UR5 home
    /// pose [0, -pi/2, pi/2, -pi/2, -pi/2, 0], which needs a six-joint arm.
    pub home_pose_rad: Option<Vec<f64>>,
    /// Target = FK(home + u * range), u uniform in [-1, 1]^N, radians per joint. Unset:
    /// [1.2, 0.8, 0.8, 0, 0, 0], which needs a six-joint arm.
    pub target_joint_range_rad: Option<Vec<f64>>,
    /// Targets are drawn again until their height is above this, metres (default 0.05).
    pub target_min_z_m: f64,
    /// Observation layout.
    pub observation: ObservationKind,
    /// Factor on the observation's `target - end-effector` and `D_PT` entries. Near the goal
    /// these are about 0.01 m, a tiny input for a network that must turn them into precise
    /// joint velocities; a factor of 10 puts the last centimetre on the scale of the other inputs.
    /// At most [`MAX_OBS_DELTA_SCALE`]: the scaled entries are stored as f32.
    pub obs_delta_scale: f64,
    /// `[[task.obstacles]]`: boxes (`shape = "cuboid"`, `half_extents_m`) and spheres
    /// (`shape = "sphere"`, `radius_m`) at `position_m` (base frame, metres), optionally turned by
    /// `rotation_xyzw`. The arm's contacts with them are recorded ([`crate::sim::collision`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<Obstacle>,
    /// `[task.collision]`: which contacts are looked for (`floor`, `self_collision`); unset:
    /// both. Contacts are recorded; they change nothing in the episode (the paper's task).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub collision: Option<Checks>,
    /// What a contact does (`"record"` or `"terminate"`). Default `"record"`: contacts are
    /// counted and change nothing, the paper's task. `"terminate"` ends the episode at the first
    /// step that ends in contact, with `reward.collision_penalty` subtracted (our extension: the
    /// paper has no collision term). Success stays "the target was reached".
    #[serde(default, skip_serializing_if = "OnCollision::is_record")]
    pub on_collision: OnCollision,
    /// `[task.random_obstacles]`: obstacles drawn anew for every episode, after its target
    /// (from the environment's random stream), beside the fixed `[[task.obstacles]]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub random_obstacles: Option<RandomObstacles>,
    /// Add the obstacles to the observation: 7 values per obstacle slot (one per fixed obstacle,
    /// then `random_obstacles.count[1]` slots): centre (3, m), half size along the obstacle's
    /// axes (3, m; a sphere's radius three times) and 1 for a sphere, 0 for a box; an empty slot
    /// is all zeros. A box's orientation is not observed (random boxes are axis-aligned).
    #[serde(default, skip_serializing_if = "is_false")]
    pub observe_obstacles: bool,
    /// How `observe_obstacles` encodes the obstacles: `"absolute"` (the default, above),
    /// `"nearest"` (see [`ObstacleObservation::Nearest`]) or `"per_link"` (one slot per
    /// collision shape of the arm, see [`ObstacleObservation::PerLink`]).
    #[serde(default, skip_serializing_if = "ObstacleObservation::is_absolute")]
    pub obstacle_observation: ObstacleObservation,
    /// How far the obstacle observation sees, metres (> 0): with `obstacle_observation =
    /// "nearest"`, obstacles whose surface is farther than this from the end effector are left
    /// out (unset: none is), with `"per_link"` the influence radius R (unset: 0.1 m).
    /// `"nearest"`: a left-out obstacle's slot reads as empty, far away, so that the obstacle
    /// entries change only near an obstacle (see docs/physics.md's random-obstacles results for
    /// what it changes). `"per_link"`: R is the distance at and beyond which a shape's slot
    /// reads "no obstacle near" ([`PER_LINK_DEFAULT_RANGE_M`] when unset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacle_range_m: Option<f64>,
    /// How a joint-velocity command moves the arm: `"kinematic"` (the default: integrated and
    /// clamped to the limits, no inertia) or `"dynamic"` (a rigid-body simulation, rapier3d:
    /// velocity motors capped at each joint's URDF effort, gravity, contacts with the floor, the
    /// obstacles and the arm itself; see [`crate::sim::physics`]). Either way the reward sees the
    /// velocity actually achieved, `(q_new - q_old) / dt_s`.
    #[serde(default, skip_serializing_if = "Sim::is_kinematic")]
    pub sim: Sim,
    /// `[task.shield]`: the safety shield that filters every command so that no checked pair
    /// comes closer than a margin within a step (see [`crate::sim::shield`]; `--shield` on
    /// `plan`, `eval`, `train`). Unset: off. Kinematic simulation only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shield: Option<ShieldConfig>,
}

/// `task.sim`: the simulator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Sim {
    /// Joint positions integrated from the commands, clamped to the limits (the paper's V-REP
    /// scene approximated without inertia): the default.
    #[default]
    Kinematic,
    /// A rigid-body simulation of the arm ([`crate::sim::physics::DynamicArm`]).
    Dynamic,
}

impl Sim {
    /// The default (left out of a written config, so that older configs keep their hash).
    pub fn is_kinematic(&self) -> bool {
        *self == Sim::Kinematic
    }

    /// The name in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Sim::Kinematic => "kinematic",
            Sim::Dynamic => "dynamic",
        }
    }
}

impl std::str::FromStr for Sim {
    type Err = Error;
    fn from_str(s: &str) -> Result<Sim> {
        match s {
            "kinematic" => Ok(Sim::Kinematic),
            "dynamic" => Ok(Sim::Dynamic),
            _ => Err(Error::config("task.sim", s, "\"kinematic\" or \"dynamic\"")),
        }
    }
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// Values per obstacle slot of the observation (`task.observe_obstacles`) in the `"absolute"`
/// and `"nearest"` encodings.
pub const OBSTACLE_OBS_LEN: usize = 7;

/// Values per slot (one per collision shape of the arm) of the `"per_link"` encoding.
pub const PER_LINK_OBS_LEN: usize = 4;

/// The influence radius of the `"per_link"` encoding when `task.obstacle_range_m` is unset,
/// metres: about one control step of the end effector at full speed. With 0.3 m, most slots
/// vary in most steps and SAC + SAR learnt far less in 2000 episodes (3.6 % against 42.6 %
/// success, one seed: docs/results/per-link-diagnostic/).
pub const PER_LINK_DEFAULT_RANGE_M: f64 = 0.1;

/// `task.obstacle_observation`: the 7 values of an observed obstacle's slot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ObstacleObservation {
    /// Centre in the base frame (3, m), half size along the obstacle's axes (3, m) and 1 for a
    /// sphere, 0 for a box; slots in the order of the obstacles (fixed, then random), an empty
    /// slot all zeros.
    #[default]
    Absolute,
    /// Relative to the end effector and scaled as the target's entries are (k =
    /// `task.obs_delta_scale`): k (centre - end effector) (3, m), k x half size (3, m) and k x
    /// the end effector's distance to the obstacle's surface (1, m; negative inside); slots
    /// ordered nearest first by that distance (ties by obstacle order). An empty slot is zeros
    /// but its distance, the largest a slot can hold ([`ResolvedTask::obstacle_obs_bounds`]), so
    /// that it reads as far away.
    Nearest,
    /// One slot of [`PER_LINK_OBS_LEN`] values per collision shape of the arm (in the order of
    /// the URDF's `<collision>` elements, [`crate::robot::Chain::collision_shapes`]), whatever
    /// the number of obstacles. With `d` the signed distance from the shape to its nearest
    /// obstacle (m, negative: the depth of an overlap; [`crate::sim::collision::distance`]),
    /// `n` the unit direction from the shape's closest point to the obstacle's (for an overlap:
    /// the direction that deepens it) and R the influence radius (`task.obstacle_range_m`,
    /// unset: [`PER_LINK_DEFAULT_RANGE_M`]): when `d < R`, `n (1 - max(d, 0) / R)` (3, a
    /// direction weighted by proximity: 0 at R, unit at contact) and `max(d, -R) / R` (1);
    /// otherwise (no obstacle within R) `0, 0, 0, 1`. Every value is in [-1, 1].
    PerLink,
}

impl ObstacleObservation {
    /// The default (left out of a written config, so that older configs keep their hash).
    pub fn is_absolute(&self) -> bool {
        *self == ObstacleObservation::Absolute
    }

    /// The name in configs.
    pub fn name(self) -> &'static str {
        match self {
            ObstacleObservation::Absolute => "absolute",
            ObstacleObservation::Nearest => "nearest",
            ObstacleObservation::PerLink => "per_link",
        }
    }

    /// Values per slot.
    pub fn slot_len(self) -> usize {
        match self {
            ObstacleObservation::Absolute | ObstacleObservation::Nearest => OBSTACLE_OBS_LEN,
            ObstacleObservation::PerLink => PER_LINK_OBS_LEN,
        }
    }
}

/// `task.on_collision`: what a step that ends in contact does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum OnCollision {
    /// Count it (episodes.csv's `collision_steps`, the evaluations' collision rate); nothing else.
    #[default]
    Record,
    /// End the episode (terminated, not a success) with `reward.collision_penalty`.
    Terminate,
}

impl OnCollision {
    /// The default (left out of a written config, so that older configs keep their hash).
    pub fn is_record(&self) -> bool {
        *self == OnCollision::Record
    }
}

impl Default for TaskConfig {
    fn default() -> Self {
        TaskConfig {
            dt_s: 0.05,
            max_steps: 50,
            home_pose_rad: None,
            target_joint_range_rad: None,
            target_min_z_m: 0.05,
            observation: ObservationKind::Standard,
            obs_delta_scale: 10.0,
            obstacles: Vec::new(),
            collision: None,
            on_collision: OnCollision::Record,
            random_obstacles: None,
            observe_obstacles: false,
            obstacle_observation: ObstacleObservation::Absolute,
            obstacle_range_m: None,
            sim: Sim::Kinematic,
            shield: None,
        }
    }
}

/// The UR5 home pose of the design notes (`docs/design.md`), radians.
pub const UR5_HOME_POSE_RAD: [f64; 6] = [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0];
/// The default target joint range of the design notes (`docs/design.md`), radians.
pub const DEFAULT_TARGET_JOINT_RANGE_RAD: [f64; 6] = [1.2, 0.8, 0.8, 0.0, 0.0, 0.0];

/// Largest `task.obs_delta_scale`: the scaled `target - end-effector` entries are f32, and a
/// larger factor turns distances of metres into infinite observations.
pub const MAX_OBS_DELTA_SCALE: f64 = 1e6;

/// A task whose per-joint vectors are resolved against an arm and checked.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedTask {
    pub dt_s: f64,
    pub max_steps: u32,
    pub home_pose: Vec<f64>,
    pub target_joint_range: Vec<f64>,
    pub target_min_z_m: f64,
    pub observation: ObservationKind,
    pub obs_delta_scale: f64,
    /// Fraction of target draws accepted by the height test, estimated from 2000 seeded draws.
    pub target_acceptance: f64,
    pub obstacles: Vec<Obstacle>,
    pub collision: Checks,
    pub on_collision: OnCollision,
    pub random_obstacles: Option<RandomObstacles>,
    pub observe_obstacles: bool,
    pub obstacle_observation: ObstacleObservation,
    /// `task.obstacle_range_m`, m (nearest encoding; the per-link encoding's influence radius).
    pub obstacle_range_m: Option<f64>,
    /// The arm's collision shapes ([`crate::robot::Chain::collision_shapes`]): the slots of the
    /// per-link encoding.
    pub arm_shapes: usize,
    pub sim: Sim,
    /// `[task.shield]` as configured (the shield is on when it is `enabled`).
    pub shield: Option<ShieldConfig>,
}

fn check_finite(field: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::config(field, v, "a finite number"))
    }
}

impl TaskConfig {
    /// Chain-independent checks.
    pub fn validate(&self) -> Result<()> {
        if !(self.dt_s.is_finite() && self.dt_s > 0.0) {
            return Err(Error::config("task.dt_s", self.dt_s, "a finite number of seconds > 0"));
        }
        if self.max_steps == 0 {
            return Err(Error::config("task.max_steps", self.max_steps, "an integer >= 1"));
        }
        check_finite("task.target_min_z_m", self.target_min_z_m)?;
        if !(self.obs_delta_scale > 0.0 && self.obs_delta_scale <= MAX_OBS_DELTA_SCALE) {
            return Err(Error::config(
                "task.obs_delta_scale",
                self.obs_delta_scale,
                format!("a number in (0, {MAX_OBS_DELTA_SCALE:e}]"),
            ));
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(Error::config(
                "task.obstacles",
                format!("{} obstacles", self.obstacles.len()),
                format!("at most {MAX_OBSTACLES}"),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            o.validate(&format!("task.obstacles[{i}]"))?;
        }
        if let Some(r) = &self.random_obstacles {
            r.validate()?;
        }
        if self.observe_obstacles && self.obstacle_slots() == 0 {
            return Err(Error::config(
                "task.observe_obstacles",
                true,
                "false when the task has no obstacles ([[task.obstacles]] or [task.random_obstacles])",
            ));
        }
        if !self.observe_obstacles && !self.obstacle_observation.is_absolute() {
            return Err(Error::config(
                "task.obstacle_observation",
                format!("\"{}\"", self.obstacle_observation.name()),
                "\"absolute\" (the default) unless task.observe_obstacles = true: it says how observed obstacles are encoded",
            ));
        }
        if let Some(r) = self.obstacle_range_m {
            if !(r.is_finite() && r > 0.0) {
                return Err(Error::config(
                    "task.obstacle_range_m",
                    r,
                    "a distance in metres, finite and > 0",
                ));
            }
            if !self.observe_obstacles || self.obstacle_observation.is_absolute() {
                return Err(Error::config(
                    "task.obstacle_range_m",
                    r,
                    "unset unless task.observe_obstacles = true and task.obstacle_observation = \"nearest\" (it leaves far obstacles out of that encoding) or \"per_link\" (its influence radius)",
                ));
            }
        }
        self.validate_shield()
    }

    /// `[task.shield]`: its values, and the kinematic simulation when it is on.
    fn validate_shield(&self) -> Result<()> {
        let Some(shield) = &self.shield else { return Ok(()) };
        shield.validate()?;
        if shield.enabled && self.sim == Sim::Dynamic {
            return Err(Error::config(
                "task.shield.enabled",
                true,
                "false with task.sim = \"dynamic\" (the shield verifies the motion a command makes, \
                 which only the kinematic simulation carries out exactly)",
            ));
        }
        Ok(())
    }

    /// Obstacle slots of the observation: 0 unless `observe_obstacles`; the obstacles an
    /// episode can have (the per-link encoding has one slot per collision shape of the arm
    /// instead: [`ResolvedTask::obstacle_slots`]).
    pub fn obstacle_slots(&self) -> usize {
        obstacle_slots(self.observe_obstacles, &self.obstacles, &self.random_obstacles)
    }

    /// Resolve the per-joint vectors for `chain` and check them against its limits; also check
    /// that the target distribution can be sampled.
    pub fn resolve(&self, chain: &Chain) -> Result<ResolvedTask> {
        self.validate()?;
        self.resolve_checked(chain)
    }

    /// [`TaskConfig::resolve`] of a task whose values are checked already (by
    /// [`crate::config::Config::resolve`]). Both per-joint vectors unset on an arm that is not
    /// six-jointed: one message naming both.
    pub(crate) fn resolve_checked(&self, chain: &Chain) -> Result<ResolvedTask> {
        let n = chain.dof();
        let (home, range) = self.joint_vectors(chain)?;
        if self.observe_obstacles
            && self.obstacle_observation == ObstacleObservation::PerLink
            && chain.collision_shapes().is_empty()
        {
            return Err(Error::config(
                "task.obstacle_observation",
                "\"per_link\"",
                format!(
                    "\"absolute\" or \"nearest\" for this arm: \"per_link\" has one slot per collision \
                     shape and no link of `{}` to `{}` has one (box, sphere, cylinder or loaded mesh)",
                    chain.base_link(),
                    chain.tip_link()
                ),
            ));
        }
        let mut resolved = ResolvedTask {
            dt_s: self.dt_s,
            max_steps: self.max_steps,
            home_pose: home,
            target_joint_range: range,
            target_min_z_m: self.target_min_z_m,
            observation: self.observation,
            obs_delta_scale: self.obs_delta_scale,
            target_acceptance: 0.0,
            obstacles: self.obstacles.clone(),
            collision: self.collision.unwrap_or_default(),
            on_collision: self.on_collision,
            random_obstacles: self.random_obstacles.clone(),
            observe_obstacles: self.observe_obstacles,
            obstacle_observation: self.obstacle_observation,
            obstacle_range_m: self.obstacle_range_m,
            arm_shapes: chain.collision_shapes().len(),
            sim: self.sim,
            shield: self.shield,
        };
        // Estimate how often a draw passes the height test; refuse a distribution the arm
        // cannot (or almost never) reach.
        let draws = 2000;
        let mut rng = Rng::new(0x7A26E7);
        let mut q = vec![0.0; n];
        let (mut accepted, mut best_z) = (0usize, f64::NEG_INFINITY);
        for _ in 0..draws {
            let p = resolved.draw_target_candidate(chain, &mut rng, &mut q);
            best_z = best_z.max(p.z);
            accepted += usize::from(p.z > self.target_min_z_m);
        }
        resolved.target_acceptance = accepted as f64 / draws as f64;
        if resolved.target_acceptance < 0.001 {
            return Err(Error::config(
                "task.target_min_z_m",
                self.target_min_z_m,
                format!(
                    "a height the arm reaches from task.home_pose_rad within task.target_joint_range_rad: \
                     {accepted} of {draws} draws passed, the highest was z = {best_z:.4} m"
                ),
            ));
        }
        Ok(resolved)
    }

    /// The home pose and the target joint range for `chain` (the defaults on a six-joint arm),
    /// checked against its limits.
    fn joint_vectors(&self, chain: &Chain) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = chain.dof();
        // Both unset on an arm that is not six-jointed: one message naming both.
        if n != 6 && self.home_pose_rad.is_none() && self.target_joint_range_rad.is_none() {
            return Err(Error::config(
                "task.home_pose_rad and task.target_joint_range_rad",
                "(unset)",
                format!(
                    "set both, one value per joint: their defaults are for a six-joint arm, this one has {n} \
                     joints (`stagerl robot URDF` suggests values; with `--config-out FILE` it \
                     writes a config that trains on the arm)"
                ),
            ));
        }
        let per_joint = |field: &str, given: &Option<Vec<f64>>, default: &[f64; 6]| -> Result<Vec<f64>> {
            match given {
                Some(v) if v.len() != n => Err(Error::config(
                    field,
                    format!("{v:?}"),
                    format!("one value per joint: the arm has {n} joints"),
                )),
                Some(v) => Ok(v.clone()),
                None if n == 6 => Ok(default.to_vec()),
                None => Err(Error::config(
                    field,
                    "(unset)",
                    format!(
                        "set it: the default {default:?} is for a six-joint arm, this one has {n} joints \
                         (`stagerl robot URDF` suggests a value)"
                    ),
                )),
            }
        };
        let home = per_joint("task.home_pose_rad", &self.home_pose_rad, &UR5_HOME_POSE_RAD)?;
        let range = per_joint(
            "task.target_joint_range_rad",
            &self.target_joint_range_rad,
            &DEFAULT_TARGET_JOINT_RANGE_RAD,
        )?;
        for (i, joint) in chain.joints().iter().enumerate() {
            let (lo, hi) = (chain.lower_limits()[i], chain.upper_limits()[i]);
            if !home[i].is_finite() || home[i] < lo || home[i] > hi {
                return Err(Error::config(
                    format!("task.home_pose_rad[{i}]"),
                    home[i],
                    format!("within the limits of joint `{}`: [{lo}, {hi}]", joint.name),
                ));
            }
            if !(range[i].is_finite() && range[i] >= 0.0) {
                return Err(Error::config(
                    format!("task.target_joint_range_rad[{i}]"),
                    range[i],
                    "a finite number >= 0",
                ));
            }
            if joint.kind == JointKind::Prismatic && range[i] > hi - lo {
                return Err(Error::config(
                    format!("task.target_joint_range_rad[{i}]"),
                    range[i],
                    format!("at most the travel of prismatic joint `{}`: {}", joint.name, hi - lo),
                ));
            }
        }
        Ok((home, range))
    }
}

fn obstacle_slots(observe: bool, fixed: &[Obstacle], random: &Option<RandomObstacles>) -> usize {
    if observe {
        fixed.len() + random.as_ref().map_or(0, |r| r.count[1] as usize)
    } else {
        0
    }
}

impl ResolvedTask {
    /// Obstacle slots of the observation (see [`TaskConfig::observe_obstacles`]): one per
    /// obstacle an episode can have, or with the per-link encoding one per collision shape of
    /// the arm.
    pub fn obstacle_slots(&self) -> usize {
        match self.obstacle_observation {
            ObstacleObservation::PerLink if self.observe_obstacles => self.arm_shapes,
            _ => obstacle_slots(self.observe_obstacles, &self.obstacles, &self.random_obstacles),
        }
    }

    /// The per-link encoding's influence radius R, metres (`task.obstacle_range_m`, unset:
    /// [`PER_LINK_DEFAULT_RANGE_M`]).
    pub fn per_link_range_m(&self) -> f64 {
        self.obstacle_range_m.unwrap_or(PER_LINK_DEFAULT_RANGE_M)
    }

    /// Most obstacles an episode has (fixed and random).
    pub fn max_obstacles(&self) -> usize {
        self.obstacles.len() + self.random_obstacles.as_ref().map_or(0, |r| r.count[1] as usize)
    }

    /// Bounds of the obstacle entries of the observation, per value of one slot (low, high), for
    /// an end effector at most `reach_m` metres from the base. Absolute: the region and the fixed
    /// obstacles' centres, sizes up to the largest, the sphere flag in [0, 1]. Nearest: the same
    /// centres less any end-effector position, sizes and distances, scaled by `obs_delta_scale`.
    pub fn obstacle_obs_bounds(&self, reach_m: f64) -> [(f64, f64); OBSTACLE_OBS_LEN] {
        let mut b = [(0.0_f64, 0.0_f64); OBSTACLE_OBS_LEN];
        b[6] = (0.0, 1.0);
        let mut grow = |p: [f64; 3], h: [f64; 3]| {
            for k in 0..3 {
                b[k] = (b[k].0.min(p[k]), b[k].1.max(p[k]));
                b[3 + k].1 = b[3 + k].1.max(h[k]);
            }
        };
        for o in &self.obstacles {
            grow(o.position_m, o.half_size_m());
        }
        if let Some(r) = &self.random_obstacles {
            grow(r.region_min_m, [r.size_m[1]; 3]);
            grow(r.region_max_m, [r.size_m[1]; 3]);
        }
        if self.obstacle_observation == ObstacleObservation::Nearest {
            let k = self.obs_delta_scale;
            // The farthest a centre can be from an end effector within reach.
            let far = (0..3).map(|i| b[i].0.abs().max(b[i].1.abs()).powi(2)).sum::<f64>().sqrt() + reach_m;
            let largest = (3..6).map(|i| b[i].1).fold(0.0, f64::max);
            for i in 0..3 {
                b[i] = (k * (b[i].0 - reach_m), k * (b[i].1 + reach_m));
                b[3 + i].1 *= k;
            }
            b[6] = (-k * largest, k * far);
        }
        b
    }

    /// One candidate target: FK(home + u * range) with u uniform in [-1, 1]^N, clamped to the
    /// joint limits. `q` is scratch of length N.
    #[inline]
    pub fn draw_target_candidate(
        &self,
        chain: &Chain,
        rng: &mut Rng,
        q: &mut [f64],
    ) -> nalgebra::Vector3<f64> {
        let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
        for i in 0..q.len() {
            let u = rng.uniform_range(-1.0, 1.0);
            q[i] = (self.home_pose[i] + u * self.target_joint_range[i]).clamp(lo[i], hi[i]);
        }
        chain.fk(q).position
    }

    /// A target from the task's distribution (draws again until above `target_min_z_m`).
    pub fn sample_target(&self, chain: &Chain, rng: &mut Rng, q: &mut [f64]) -> nalgebra::Vector3<f64> {
        // Validation guarantees an acceptance rate of at least 1e-3, so 1e6 draws fail with
        // probability below e^-1000; the highest candidate is the fallback all the same.
        let mut best = self.draw_target_candidate(chain, rng, q);
        for _ in 0..1_000_000 {
            if best.z > self.target_min_z_m {
                break;
            }
            let p = self.draw_target_candidate(chain, rng, q);
            if p.z > best.z {
                best = p;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolve_against_the_ur5() {
        let chain = Chain::ur5();
        let t = TaskConfig::default().resolve(&chain).unwrap();
        assert_eq!(t.home_pose, UR5_HOME_POSE_RAD.to_vec());
        assert!(t.target_acceptance > 0.5, "{}", t.target_acceptance);

        let wrong_len = TaskConfig { home_pose_rad: Some(vec![0.0; 5]), ..TaskConfig::default() };
        let e = wrong_len.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.home_pose_rad") && e.contains("6 joints"), "{e}");

        let outside =
            TaskConfig { home_pose_rad: Some(vec![0.0, 0.0, 4.0, 0.0, 0.0, 0.0]), ..TaskConfig::default() };
        let e = outside.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.home_pose_rad[2]") && e.contains("elbow_joint"), "{e}");

        let negative = TaskConfig {
            target_joint_range_rad: Some(vec![1.0, -0.1, 0.0, 0.0, 0.0, 0.0]),
            ..TaskConfig::default()
        };
        let e = negative.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.target_joint_range_rad[1]"), "{e}");

        // The UR5 reaches less than 1 m up from its base: a 5 m floor is unreachable.
        let unreachable = TaskConfig { target_min_z_m: 5.0, ..TaskConfig::default() };
        let e = unreachable.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.target_min_z_m") && e.contains("0 of 2000"), "{e}");
    }
}
