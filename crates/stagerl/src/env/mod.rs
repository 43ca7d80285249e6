//! The random-target reaching task of the paper (section VI), as the design notes
//! (`docs/design.md`) fix it.
//!
//! Every episode starts at the home pose with a new target drawn from the task's distribution.
//! An action is one value per joint, clipped to [-1, 1] and scaled by the joint's speed limit to
//! a joint-velocity command held for `dt`; the joint positions are integrated and clamped to their
//! limits, and the velocity the reward sees is the one actually applied, `(q_new - q_old) / dt`.
//! Reaching the target (`D_PT < beta`) ends the episode (terminated) and adds the success bonus;
//! otherwise it is truncated after `max_steps` steps.
//!
//! [`ReachEnv::step`] allocates nothing.

mod observation;
mod proximity;
pub mod request;
mod rollout;
mod task;
mod vec;

pub use observation::{empty_slot_distance, ObsEntry, ObservationLayout};
pub use rollout::{rollout, track_waypoints, Driver, Flow, Observed, Outcome, Policy, Scratch, Transition};
pub use vec::{VecEnv, MAX_VEC_ENVS, PAR_MIN_ENVS};

use nalgebra::Vector3;
use std::f64::consts::PI;
use std::ops::Range;
use std::sync::Arc;

use crate::base::rng::Rng;
use crate::reward::{RewardConfig, RewardInput, RewardTerms};
use crate::robot::{Chain, Pose};
use crate::sim::arm::Arm;
use crate::sim::collision::{CollisionKind, Contact};
use crate::sim::scene::{place_obstacles, Placement};
use crate::sim::shield::ShieldStats;
use crate::{Error, Result};
pub use task::{
    ObservationKind, ObstacleObservation, OnCollision, ResolvedTask, Sim, TaskConfig,
    DEFAULT_TARGET_JOINT_RANGE_RAD, MAX_OBS_DELTA_SCALE, OBSTACLE_OBS_LEN, PER_LINK_DEFAULT_RANGE_M,
    PER_LINK_OBS_LEN, UR5_HOME_POSE_RAD,
};

/// The outcome of one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Step {
    /// Every reward term; `terms.total` is what the agent receives.
    pub terms: RewardTerms,
    /// A terminal state: the target was reached, or (with `task.on_collision = "terminate"`)
    /// the arm touched something. Success is [`Step::reached`].
    pub terminated: bool,
    /// The step limit was hit without reaching the target: not terminal, bootstrap through it.
    pub truncated: bool,
    /// What the arm touched after the step, if anything ([`ReachEnv::contact`] has the links).
    /// With `task.on_collision = "record"` (the default) it changes nothing else; with
    /// `"terminate"` it ends the episode and `terms.total` has `reward.collision_penalty` taken off.
    pub collision: Option<CollisionKind>,
    /// The arm's clearance from the obstacles after the step (metres, negative inside; the
    /// smallest signed distance between a collision shape and an obstacle), when it was
    /// measured: with `[reward.clearance]` or the per-link observation, among obstacles nearer
    /// than their margin or radius (`f64::INFINITY`: none was). `None`: not measured.
    pub clearance_m: Option<f64>,
    /// How much the safety shield changed this step's command (rad/s, 0: kept it; see
    /// [`crate::sim::shield::Shield::last_change_rad_per_s`]). `None`: the shield is off.
    pub shield_change_rad_per_s: Option<f64>,
}

impl Step {
    /// What the agent receives: the configured reward plus the success bonus (`terms.total`).
    pub fn total(&self) -> f64 {
        self.terms.total
    }
    /// The episode is over (terminated or truncated).
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
    /// The target was reached (`D_PT < beta`): the episode is a success.
    pub fn reached(&self) -> bool {
        self.terms.reached
    }

    /// The outcome of a step of `task` from what the arm did (`input`: the end-effector pose
    /// after the step and before it, the joint velocities applied, the target), whether it ended
    /// in contact (`collided`), the arm's clearance from the obstacles (`clearance_m`, metres,
    /// see [`Step::clearance_m`]), the shield's change to the command (`shield_change`, rad/s,
    /// see [`Step::shield_change_rad_per_s`]) and the steps taken so far, this one included (the result's
    /// `collision` is left for the caller, who knows what was touched). One rule for the
    /// environment and for hindsight relabelling, which asks it again for substituted goals:
    /// 1. the reward terms of the run's reward function (eqs. 1-15 and 18), the success bonus
    ///    included when `D_PT < beta`;
    /// 2. a step in contact with `task.on_collision = "terminate"` ends the episode and loses
    ///    `reward.collision_penalty` (0 when unset); with `"record"` contact changes nothing;
    /// 3. with `[reward.clearance]`, R_clearance of `clearance_m` is taken off (eqs. 19-21 of
    ///    [`crate::reward`]; 0 when not measured); unset, nothing is;
    /// 4. with `reward.shield_penalty`, R_shield = `shield_penalty * shield_change` is taken off
    ///    (eqs. 22-23; 0 without the shield);
    /// 5. terminated: reached or ended by contact; truncated: not terminated at `max_steps`.
    #[inline]
    pub fn outcome(
        task: &ResolvedTask,
        reward: &RewardConfig,
        input: &RewardInput<'_>,
        collided: bool,
        clearance_m: Option<f64>,
        shield_change: Option<f64>,
        steps: u32,
    ) -> Step {
        let mut terms = RewardTerms::compute(reward, task.dt_s, input);
        let ended_by_contact = collided && task.on_collision == OnCollision::Terminate;
        if ended_by_contact {
            terms.total -= reward.collision_penalty.unwrap_or(0.0);
        }
        if let (Some(c), Some(d)) = (&reward.clearance, clearance_m) {
            terms.clearance = c.penalty(d);
            terms.total -= terms.clearance;
        }
        if let (Some(w), Some(c)) = (reward.shield_penalty, shield_change) {
            terms.shield = w * c;
            terms.total -= terms.shield;
        }
        let terminated = terms.reached || ended_by_contact;
        let truncated = !terminated && steps >= task.max_steps;
        Step {
            terms,
            terminated,
            truncated,
            collision: None,
            clearance_m,
            shield_change_rad_per_s: shield_change,
        }
    }
}

/// Check that `task.on_collision` and `reward.collision_penalty` fit together: the penalty is
/// only ever applied when a contact ends the episode.
pub fn check_collision_settings(on_collision: OnCollision, reward: &RewardConfig) -> Result<()> {
    match (on_collision, reward.collision_penalty) {
        (OnCollision::Record, Some(p)) => Err(Error::config(
            "reward.collision_penalty",
            p,
            "unset while task.on_collision = \"record\": the penalty applies only when a contact \
             ends the episode (set task.on_collision = \"terminate\")",
        )),
        _ => Ok(()),
    }
}

/// Check `train.obstacles_in_path`: a probability, and positive only when the task has random
/// obstacles to place.
pub fn check_obstacles_in_path(fraction: f64, random_obstacles: bool) -> Result<()> {
    check_in_path_probability("train.obstacles_in_path", fraction, random_obstacles)
}

/// [`check_obstacles_in_path`] of a setting named `field` (`train.demonstrations.obstacles_in_path`).
pub fn check_in_path_probability(field: &str, fraction: f64, random_obstacles: bool) -> Result<()> {
    if !(0.0..=1.0).contains(&fraction) {
        return Err(Error::config(field, fraction, "a probability in [0, 1]"));
    }
    if fraction > 0.0 && !random_obstacles {
        return Err(Error::config(
            field,
            fraction,
            "0 for a task without [task.random_obstacles] (there is no random obstacle to place)",
        ));
    }
    Ok(())
}

/// Check joint positions for `chain`: one finite value per joint, each within its joint's limits.
pub fn check_joint_positions(chain: &Chain, q: &[f64]) -> Result<()> {
    let n = chain.dof();
    if q.len() != n {
        return Err(Error::InvalidInput(format!(
            "start pose has {} values, expected {n} (one per joint of the arm, radians)",
            q.len()
        )));
    }
    for (i, (j, &v)) in chain.joints().iter().zip(q).enumerate() {
        if !(v.is_finite() && v >= j.lower && v <= j.upper) {
            return Err(Error::InvalidInput(format!(
                "start pose: joint {i} `{}` = {v} is outside its limits [{}, {}]",
                j.name, j.lower, j.upper
            )));
        }
    }
    Ok(())
}

/// Everything that changes as a [`ReachEnv`] runs, for exact checkpoints: the random stream and,
/// mid-episode, the joint positions, the target and the step count. The end-effector pose and the
/// observation follow from these.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnvState {
    pub rng: Rng,
    pub q: Vec<f64>,
    pub joint_vel: Vec<f64>,
    pub target: [f64; 3],
    pub steps: u32,
    pub done: bool,
    /// Steps of this episode that ended in contact.
    #[serde(default)]
    pub collision_steps: u32,
    /// The episode's random obstacles (`[task.random_obstacles]`), after the fixed ones.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub random_obstacles: Vec<crate::sim::scene::Obstacle>,
    /// With `task.sim = "dynamic"`: the joints' instantaneous velocities (rad/s), which with
    /// `q` are the simulation's state.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sim_velocities: Vec<f64>,
    /// The request's scene the next episodes have ([`ReachEnv::set_request_obstacles`]), when
    /// one is set; `random_obstacles` then holds this episode's obstacles after the fixed ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request_obstacles: Option<Vec<crate::sim::scene::Obstacle>>,
    /// What the safety shield did in this episode so far (`None`: the shield is off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shield_episode: Option<ShieldStats>,
}

/// The reaching environment.
#[derive(Clone, Debug)]
pub struct ReachEnv {
    chain: Arc<Chain>,
    task: ResolvedTask,
    reward: RewardConfig,
    rng: Rng,
    q: Vec<f64>,
    joint_vel: Vec<f64>,
    scratch: Vec<f64>,
    ee: Pose,
    target: Vector3<f64>,
    steps: u32,
    done: bool,
    /// Steps of this episode that ended in contact.
    collision_steps: u32,
    obs: Vec<f32>,
    /// Where each entry of `obs` is.
    layout: ObservationLayout,
    /// The simulated arm in its scene (kinematic or dynamic, with its collision checks).
    arm: Arm,
    /// The episode's obstacles: the fixed ones, then the random ones.
    obstacles: Vec<crate::sim::scene::Obstacle>,
    /// `task.obstacle_observation = "nearest"`: (distance from the end effector, index) per
    /// obstacle, sorted for the observation's slots (scratch of capacity `max_obstacles`).
    nearest: Vec<(f64, usize)>,
    /// The largest value of a "nearest" slot's distance entry (an empty slot's).
    far_obs: f32,
    /// The probability that an episode's first random obstacle is placed in the way
    /// ([`ReachEnv::set_obstacles_in_path`]; 0 unless set).
    obstacles_in_path: f64,
    /// The task's random obstacles with a smaller largest count
    /// ([`ReachEnv::set_max_random_obstacles`]; `None`: the task's own).
    capped_random: Option<crate::sim::scene::RandomObstacles>,
    /// A request's obstacles ([`ReachEnv::set_request_obstacles`]): episodes have the task's
    /// fixed obstacles and these, and no random ones. `None`: the task's scene.
    request_obstacles: Option<Vec<crate::sim::scene::Obstacle>>,
    /// Each collision shape's nearest obstacle within `proximity_cutoff` (scratch, one per
    /// shape; see [`proximity`]).
    proximity: Vec<Option<(usize, crate::sim::collision::distance::Closest)>>,
    /// The distance below which `proximity` is measured (m); `None`: it is not (neither the
    /// per-link observation nor `[reward.clearance]` is on).
    proximity_cutoff: Option<f64>,
}

/// The checks of an environment's parts: the reward's values and collision settings, and the
/// task against the arm ([`check_task_for_arm`]).
pub fn check_parts(chain: &Chain, task: &ResolvedTask, reward: &RewardConfig) -> Result<()> {
    reward.validate()?;
    check_collision_settings(task.on_collision, reward)?;
    check_clearance_settings(chain, task, reward)?;
    check_shield_penalty(task, reward)?;
    check_task_for_arm(chain, task)
}

/// Check that `reward.shield_penalty` has a shield to charge: `[task.shield]` enabled (turning
/// it off later, as `stagerl eval --no-shield` does, leaves nothing to charge: the term is 0).
pub fn check_shield_penalty(task: &ResolvedTask, reward: &RewardConfig) -> Result<()> {
    match reward.shield_penalty {
        Some(w) if !task.shield.is_some_and(|s| s.enabled) => Err(Error::config(
            "reward.shield_penalty",
            w,
            "unset unless [task.shield] has enabled = true: it charges the changes the safety \
             shield makes to the commands",
        )),
        _ => Ok(()),
    }
}

/// Check that `[reward.clearance]` can measure something: obstacles to keep clear of, and an
/// arm with collision shapes to measure from.
pub fn check_clearance_settings(chain: &Chain, task: &ResolvedTask, reward: &RewardConfig) -> Result<()> {
    let Some(c) = &reward.clearance else { return Ok(()) };
    let value = format!("{{ weight = {}, margin_m = {} }}", c.weight, c.margin_m);
    if task.max_obstacles() == 0 {
        return Err(Error::config(
            "reward.clearance",
            value,
            "unset for a task without obstacles ([[task.obstacles]] or [task.random_obstacles]): \
             it penalises the arm's clearance from them",
        ));
    }
    if chain.collision_shapes().is_empty() {
        return Err(Error::config(
            "reward.clearance",
            value,
            format!(
                "unset for this arm: no link of `{}` to `{}` has a collision shape (box, sphere, \
                 cylinder or loaded mesh) to measure the clearance from",
                chain.base_link(),
                chain.tip_link()
            ),
        ));
    }
    Ok(())
}

/// The checks of a resolved task against the arm: one value per joint, and contacts that can
/// end an episode only on an arm with collision shapes.
pub fn check_task_for_arm(chain: &Chain, task: &ResolvedTask) -> Result<()> {
    let n = chain.dof();
    let meshes = chain.mesh_collision_links();
    let mesh_note = match meshes.len() {
        0 => String::new(),
        _ => format!(
            " (the collision meshes of links {} were not loaded)",
            meshes.iter().map(|l| format!("`{l}`")).collect::<Vec<_>>().join(", ")
        ),
    };
    if task.on_collision == OnCollision::Terminate && chain.collision_shapes().is_empty() {
        return Err(Error::config(
            "task.on_collision",
            "\"terminate\"",
            format!(
                "\"record\" for this arm: no link of `{}` to `{}` has a collision shape (box, \
                 sphere, cylinder or loaded mesh){mesh_note}, so no contact can end an episode",
                chain.base_link(),
                chain.tip_link()
            ),
        ));
    }
    if task.home_pose.len() != n || task.target_joint_range.len() != n {
        return Err(Error::InvalidInput(format!(
            "the task was resolved for {} joints, the arm has {n}",
            task.home_pose.len()
        )));
    }
    check_collision_mechanism(chain, task, &mesh_note)?;
    if let Some(r) = &task.random_obstacles {
        check_random_obstacles_placeable(chain, task, r)?;
    }
    Ok(())
}

/// Refusals of settings under which a collision check can never fire or fires at once: an arm
/// whose only collision geometry is meshes that were not loaded (a URDF given as text, or
/// `robot.missing_collision = "ignore"`) and checks or obstacles that would then
/// never report a contact; `on_collision = "terminate"` with every check off and no obstacle;
/// `"terminate"` with the home pose already in contact (every episode would end at its first
/// step).
fn check_collision_mechanism(chain: &Chain, task: &ResolvedTask, mesh_note: &str) -> Result<()> {
    let checks = task.collision;
    let obstacles = !task.obstacles.is_empty() || task.random_obstacles.is_some();
    if chain.collision_shapes().is_empty() && !chain.mesh_collision_links().is_empty() {
        let what = if obstacles { "the obstacles" } else { "the floor and the arm itself" };
        if obstacles || checks.floor || checks.self_collision {
            return Err(Error::config(
                "robot.urdf",
                format!("\"{}\"", chain.base_link()),
                format!(
                    "an arm with collision shapes (box, sphere, cylinder or loaded mesh) for contacts \
                     with {what}: no link of `{}` to `{}` has one{mesh_note}, so every contact would go \
                     unseen and the collision rate would read 0 %; load the URDF from its file with \
                     its meshes (robot.missing_collision = \"error\" says why one is not read), or turn \
                     the checks off ([task.collision] floor = false, self_collision = false) and \
                     remove the obstacles",
                    chain.base_link(),
                    chain.tip_link()
                ),
            ));
        }
    }
    if task.on_collision != OnCollision::Terminate {
        return Ok(());
    }
    if !checks.floor && !checks.self_collision && !obstacles {
        return Err(Error::config(
            "task.on_collision",
            "\"terminate\"",
            "\"record\" here: [task.collision] has floor = false and self_collision = false and \
             the task has no obstacle, so no contact can ever end an episode",
        ));
    }
    let mut collider = crate::sim::collision::ArmCollider::new(chain, checks);
    collider.set_obstacles(&task.obstacles);
    if let Some(c) = collider.check(chain, &task.home_pose) {
        return Err(Error::config(
            "task.on_collision",
            "\"terminate\"",
            format!(
                "a home pose (task.home_pose_rad = {:?}) clear of contacts: there the arm touches \
                 ({}), so every episode would end at its first step; move the pose or the obstacle, \
                 or set on_collision = \"record\"",
                task.home_pose,
                c.describe(chain)
            ),
        ));
    }
    Ok(())
}

/// Sample episodes of the random obstacles' placement (home pose, random targets, a stream of
/// its own): an error, naming the settings, when none of the obstacles asked for can be placed
/// (all of them would be left out, every episode, without a word).
fn check_random_obstacles_placeable(
    chain: &Chain,
    task: &ResolvedTask,
    r: &crate::sim::scene::RandomObstacles,
) -> Result<()> {
    if r.count[1] == 0 {
        return Ok(());
    }
    let mut rng = Rng::new(0x0B57_C1EA);
    let mut collider = (!chain.collision_shapes().is_empty())
        .then(|| crate::sim::collision::ArmCollider::new(chain, task.collision));
    let mut q = vec![0.0; chain.dof()];
    let (mut asked, mut placed, mut out) = (0usize, 0usize, Vec::new());
    for _ in 0..SAMPLE_EPISODES {
        let target = task.draw_target_candidate(chain, &mut rng, &mut q);
        let p = Placement { chain, q: &task.home_pose, target, in_path: 0.0 };
        // The count drawn is at least count[0]; ask for count[1] to be safe: what matters is
        // whether any can be placed.
        place_obstacles(&[], Some(r), &p, collider.as_mut(), &mut rng, &mut out);
        asked += r.count[1] as usize;
        placed += out.len();
        if placed > 0 {
            return Ok(());
        }
    }
    Err(Error::config(
        "task.random_obstacles",
        format!(
            "{{ target_clearance_m = {}, size_m = {:?}, region_min_m = {:?}, region_max_m = {:?} }}",
            r.target_clearance_m, r.size_m, r.region_min_m, r.region_max_m
        ),
        format!(
            "obstacles that can be placed: in {SAMPLE_EPISODES} sample episodes none of up to {asked} \
             could be (each must be at least target_clearance_m from the target and clear of the arm \
             at its home pose), so every episode would run without them; lower target_clearance_m, \
             or move or widen the region"
        ),
    ))
}

/// Episodes sampled by [`check_random_obstacles_placeable`].
const SAMPLE_EPISODES: usize = 50;

impl ReachEnv {
    /// An environment for `chain`, seeded; call [`ReachEnv::reset`] before stepping. Its parts
    /// are checked ([`check_parts`]); a config's are checked once by
    /// [`crate::config::Config::resolve`].
    pub fn new(chain: Arc<Chain>, task: ResolvedTask, reward: RewardConfig, seed: u64) -> Result<ReachEnv> {
        check_parts(&chain, &task, &reward)?;
        ReachEnv::assemble(chain, task, reward, seed)
    }

    /// [`ReachEnv::new`] of parts checked already.
    pub(crate) fn assemble(
        chain: Arc<Chain>,
        task: ResolvedTask,
        reward: RewardConfig,
        seed: u64,
    ) -> Result<ReachEnv> {
        let n = chain.dof();
        let layout = ObservationLayout::of(&task);
        let mut obstacles = Vec::with_capacity(task.max_obstacles());
        obstacles.extend(task.obstacles.iter().cloned());
        let q = task.home_pose.clone();
        let ee = chain.fk(&q);
        let mut arm = Arm::new(&chain, task.sim == Sim::Dynamic, task.dt_s, &obstacles, task.collision)?;
        arm.set_shield(&chain, task.shield)?;
        let far_obs = empty_slot_distance(&task, &chain);
        let mut env = ReachEnv {
            proximity: vec![None; chain.collision_shapes().len()],
            proximity_cutoff: proximity::proximity_cutoff(&task, &reward),
            arm,
            nearest: Vec::with_capacity(task.max_obstacles()),
            far_obs,
            obstacles,
            obstacles_in_path: 0.0,
            capped_random: None,
            request_obstacles: None,
            chain,
            rng: Rng::new(seed),
            joint_vel: vec![0.0; n],
            scratch: vec![0.0; n],
            ee,
            target: ee.position,
            steps: 0,
            done: true,
            collision_steps: 0,
            obs: vec![0.0; layout.dim()],
            layout,
            q,
            task,
            reward,
        };
        env.measure_proximity();
        env.write_observation();
        Ok(env)
    }

    /// Start a new episode: home pose, new target from the environment's random stream.
    pub fn reset(&mut self) -> &[f32] {
        self.q.copy_from_slice(&self.task.home_pose);
        self.target = self.task.sample_target(&self.chain, &mut self.rng, &mut self.scratch);
        self.begin_episode()
    }

    /// Reseed the random stream (the next targets and random obstacles).
    pub fn reseed(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
    }

    /// Reseed the random stream, then [`ReachEnv::reset`].
    pub fn reset_with_seed(&mut self, seed: u64) -> &[f32] {
        self.rng = Rng::new(seed);
        self.reset()
    }

    /// Start a new episode at the home pose with a given target (metres, base frame).
    pub fn reset_to_target(&mut self, target: Vector3<f64>) -> Result<&[f32]> {
        if !target.iter().all(|x| x.is_finite()) {
            return Err(Error::InvalidInput(format!("target {target:?} is not finite")));
        }
        self.q.copy_from_slice(&self.task.home_pose);
        self.target = target;
        Ok(self.begin_episode())
    }

    /// Check a target asked for by a user (metres; `stagerl plan`, the Python `reset(options=)`):
    /// three finite values, `z >= 0`, within the arm's reach ([`Chain::reach_m`]) of its first
    /// joint. The one check of every entry point that takes a target.
    pub fn check_target(&self, target: &[f64]) -> Result<Vector3<f64>> {
        let chain = &self.chain;
        let (origin, reach) = (chain.first_joint_origin(), chain.reach_m());
        let &[x, y, z] = target else {
            return Err(Error::InvalidInput(format!(
                "target has {} values, expected 3 (x, y, z in metres)",
                target.len()
            )));
        };
        if !target.iter().all(|v| v.is_finite()) {
            return Err(Error::InvalidInput(format!("target {target:?} is not finite")));
        }
        let t = Vector3::new(x, y, z);
        let d = (t - origin).norm();
        let reach_text = format!(
            "the arm reaches at most {reach:.4} m from its first joint at [{}, {}, {}], above the floor z = 0",
            origin.x, origin.y, origin.z
        );
        if z < 0.0 {
            return Err(Error::InvalidInput(format!(
                "target [{x}, {y}, {z}] is below the floor (z = {z} m < 0); {reach_text}"
            )));
        }
        if d > reach {
            return Err(Error::InvalidInput(format!(
                "target [{x}, {y}, {z}] is {d:.4} m from the first joint, out of reach: {reach_text}"
            )));
        }
        Ok(t)
    }

    /// Start a new episode at joint positions `start` (radians, metres for prismatic joints)
    /// with a given target (metres, base frame); the random stream is untouched (but for the
    /// episode's random obstacles, `[task.random_obstacles]`, which are drawn from it).
    ///
    /// Errors: `start` without one value per joint (the expected count given), a value that is
    /// not finite or outside its joint's limits (the joint, the value and the limits named), a
    /// target that is not finite.
    pub fn reset_to(&mut self, start: &[f64], target: Vector3<f64>) -> Result<&[f32]> {
        check_joint_positions(&self.chain, start)?;
        if !target.iter().all(|x| x.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "target {:?} is not finite",
                [target.x, target.y, target.z]
            )));
        }
        self.q.copy_from_slice(start);
        self.target = target;
        Ok(self.begin_episode())
    }

    /// From the next reset on, the scene of a request: the task's fixed obstacles and
    /// `obstacles` (checked by the caller: [`request::check_obstacle_values`]), without the
    /// task's random obstacles; `None` goes back to the task's scene. An observation with fewer
    /// obstacle slots than obstacles holds the nearest ones to the end effector.
    pub fn set_request_obstacles(&mut self, obstacles: Option<&[crate::sim::scene::Obstacle]>) {
        self.request_obstacles = obstacles.map(<[_]>::to_vec);
    }

    fn begin_episode(&mut self) -> &[f32] {
        if let Some(extra) = &self.request_obstacles {
            self.obstacles.clear();
            self.obstacles.extend(self.task.obstacles.iter().chain(extra).cloned());
            self.arm.set_obstacles(&self.obstacles);
        } else if self.task.random_obstacles.is_none() && self.obstacles.len() != self.task.obstacles.len() {
            // Back from a request's scene to the task's.
            self.obstacles.clone_from(&self.task.obstacles);
            self.arm.set_obstacles(&self.obstacles);
        } else if let Some(random) = &self.task.random_obstacles {
            let random = self.capped_random.as_ref().unwrap_or(random);
            let p = Placement {
                chain: &self.chain,
                q: &self.q,
                target: self.target,
                in_path: self.obstacles_in_path,
            };
            place_obstacles(
                &self.task.obstacles,
                Some(random),
                &p,
                self.arm.collider_mut(),
                &mut self.rng,
                &mut self.obstacles,
            );
            self.arm.set_obstacles(&self.obstacles);
        }
        self.joint_vel.fill(0.0);
        if let Some(shield) = self.arm.shield_mut() {
            shield.begin_episode();
        }
        // The start pose was checked against the limits; at rest.
        self.arm
            .set_state(&self.chain, &self.q, &self.joint_vel)
            .expect("a checked start pose is a valid state");
        self.ee = self.chain.fk(&self.q);
        self.steps = 0;
        self.collision_steps = 0;
        self.done = false;
        self.measure_proximity();
        self.write_observation();
        &self.obs
    }

    /// Apply one action (one value per joint, nominally in [-1, 1]; clipped).
    ///
    /// Errors: a wrong length, a NaN or infinite value, or a step after the episode ended.
    pub fn step(&mut self, action: &[f32]) -> Result<Step> {
        let n = self.q.len();
        if action.len() != n {
            return Err(Error::InvalidInput(format!(
                "action has {} values, the arm has {n} joints",
                action.len()
            )));
        }
        if let Some(i) = action.iter().position(|a| !a.is_finite()) {
            return Err(Error::InvalidInput(format!("action[{i}] = {} is not finite", action[i])));
        }
        if self.done {
            return Err(Error::InvalidInput("the episode is over: call reset() before step()".into()));
        }
        let prev_ee = self.ee.position;
        let stepped = self.arm.step(
            &self.chain,
            action,
            self.task.dt_s,
            self.steps + 1,
            &mut self.q,
            &mut self.joint_vel,
        );
        if let Err(e) = stepped {
            self.done = true;
            return Err(e);
        }
        // The check placed the arm at q: its frames give the tip (the same pose to the bit).
        let frames = self.arm.collider().and_then(|c| c.frames_placed_at(&self.q));
        self.ee =
            frames.and_then(|f| self.chain.tip_pose_from_frames(f)).unwrap_or_else(|| self.chain.fk(&self.q));
        self.steps += 1;
        self.collision_steps += u32::from(self.arm.contact().is_some());
        let clearance = self.measure_proximity();
        let input = RewardInput {
            ee_pos: self.ee.position,
            ee_quat: self.ee.quaternion_xyzw(),
            target: self.target,
            joint_vel: &self.joint_vel,
            prev_ee_pos: Some(prev_ee),
        };
        let contact = self.arm.contact();
        let shield_change = self.arm.shield().map(|s| s.last_change_rad_per_s());
        let mut step = Step::outcome(
            &self.task,
            &self.reward,
            &input,
            contact.is_some(),
            clearance,
            shield_change,
            self.steps,
        );
        step.collision = contact.map(|c| c.kind());
        self.done = step.done();
        self.write_observation();
        Ok(step)
    }

    fn write_observation(&mut self) {
        let layout = self.layout;
        for (o, q) in self.obs[layout.q_over_pi()].iter_mut().zip(&self.q) {
            *o = (q / PI) as f32;
        }
        let p = self.ee.position;
        for (k, o) in self.obs[layout.ee_pos()].iter_mut().enumerate() {
            *o = p[k] as f32;
        }
        let slots = layout.obstacles();
        match self.task.obstacle_observation {
            ObstacleObservation::Absolute => self.write_obstacles_absolute(slots),
            ObstacleObservation::Nearest => self.write_obstacles_nearest(slots),
            ObstacleObservation::PerLink => self.write_obstacles_per_link(slots),
        }
        let k = self.task.obs_delta_scale;
        self.layout.write_target_entries(&mut self.obs, k, self.ee.position, self.target);
    }

    /// [`ObstacleObservation::Absolute`]'s slots, into `self.obs[slots]`.
    fn write_obstacles_absolute(&mut self, slots: Range<usize>) {
        if self.obstacles.len() > slots.len() / task::OBSTACLE_OBS_LEN {
            return self.write_obstacles_absolute_nearest(slots);
        }
        let slots = &mut self.obs[slots];
        slots.fill(0.0);
        for (o, slot) in self.obstacles.iter().zip(slots.chunks_exact_mut(task::OBSTACLE_OBS_LEN)) {
            let (p, h) = (o.position_m, o.half_size_m());
            for k in 0..3 {
                slot[k] = p[k] as f32;
                slot[3 + k] = h[k] as f32;
            }
            slot[6] = f32::from(u8::from(o.shape == crate::sim::scene::ObstacleShape::Sphere));
        }
    }

    /// [`ObstacleObservation::Absolute`]'s slots when a request has more obstacles than the
    /// slots: the nearest to the end effector, nearest first.
    fn write_obstacles_absolute_nearest(&mut self, slots: Range<usize>) {
        let ee = self.ee.position;
        self.nearest.clear();
        self.nearest
            .extend(self.obstacles.iter().enumerate().map(|(i, o)| (o.distance_to_point_m(ee.into()), i)));
        self.nearest.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let slots = &mut self.obs[slots];
        slots.fill(0.0);
        for (&(_, i), slot) in self.nearest.iter().zip(slots.chunks_exact_mut(task::OBSTACLE_OBS_LEN)) {
            let o = &self.obstacles[i];
            let (p, h) = (o.position_m, o.half_size_m());
            for k in 0..3 {
                slot[k] = p[k] as f32;
                slot[3 + k] = h[k] as f32;
            }
            slot[6] = f32::from(u8::from(o.shape == crate::sim::scene::ObstacleShape::Sphere));
        }
    }

    /// [`ObstacleObservation::Nearest`]'s slots, into `self.obs[slots]`.
    fn write_obstacles_nearest(&mut self, slots: Range<usize>) {
        let ee = self.ee.position;
        let scale = self.task.obs_delta_scale;
        self.nearest.clear();
        self.nearest
            .extend(self.obstacles.iter().enumerate().map(|(i, o)| (o.distance_to_point_m(ee.into()), i)));
        self.nearest.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let slots = &mut self.obs[slots];
        for slot in slots.chunks_exact_mut(task::OBSTACLE_OBS_LEN) {
            slot.fill(0.0);
            slot[6] = self.far_obs;
        }
        let range = self.task.obstacle_range_m.unwrap_or(f64::INFINITY);
        for (&(distance, i), slot) in self.nearest.iter().zip(slots.chunks_exact_mut(task::OBSTACLE_OBS_LEN))
        {
            if distance > range {
                // Nearest first: the rest are farther still, and stay empty.
                break;
            }
            let o = &self.obstacles[i];
            let (p, h) = (o.position_m, o.half_size_m());
            for k in 0..3 {
                slot[k] = (scale * (p[k] - ee[k])) as f32;
                slot[3 + k] = (scale * h[k]) as f32;
            }
            slot[6] = (scale * distance) as f32;
        }
    }

    /// What the safety shield did since the environment was made or its counts were reset
    /// (`None`: the shield is off).
    pub fn shield_stats(&self) -> Option<ShieldStats> {
        self.arm.shield().map(|s| *s.stats())
    }

    /// What the safety shield did in this episode (`None`: the shield is off).
    pub fn episode_shield_stats(&self) -> Option<ShieldStats> {
        self.arm.shield().map(|s| *s.episode_stats())
    }

    /// Turn the safety shield on or off (`--shield`), with the task's `[task.shield]` values
    /// (the defaults when it has none); its counts start at zero.
    ///
    /// Errors: on for a dynamic simulation or an arm without collision shapes.
    pub fn set_shield(&mut self, enabled: bool) -> Result<()> {
        let config = crate::sim::shield::ShieldConfig { enabled, ..self.task.shield.unwrap_or_default() };
        self.arm.set_shield(&self.chain, Some(config))?;
        self.task.shield = Some(config);
        Ok(())
    }

    /// Forget the safety shield's counts.
    pub fn reset_shield_stats(&mut self) {
        if let Some(s) = self.arm.shield_mut() {
            s.reset_stats();
        }
    }

    /// The obstacles of this episode: the fixed ones, then the random ones.
    pub fn obstacles(&self) -> &[crate::sim::scene::Obstacle] {
        &self.obstacles
    }

    /// What the arm touches at its current joint positions (checked at every reset and step),
    /// if anything; [`Contact::describe`] names the links.
    pub fn contact(&self) -> Option<Contact> {
        self.arm.contact()
    }

    /// The current observation.
    pub fn observation(&self) -> &[f32] {
        &self.obs
    }
    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.obs.len()
    }
    /// Action length (the number of joints).
    pub fn act_dim(&self) -> usize {
        self.q.len()
    }
    /// Joint positions, radians (metres for prismatic joints).
    pub fn joint_positions(&self) -> &[f64] {
        &self.q
    }
    /// Joint velocities applied in the last step, rad/s.
    pub fn joint_velocities(&self) -> &[f64] {
        &self.joint_vel
    }
    /// End-effector pose after the last step or reset.
    pub fn ee_pose(&self) -> &Pose {
        &self.ee
    }
    /// The episode's target, metres.
    pub fn target(&self) -> Vector3<f64> {
        self.target
    }
    /// D_PT now, metres.
    pub fn distance(&self) -> f64 {
        (self.target - self.ee.position).norm()
    }
    /// Steps taken in this episode.
    pub fn steps(&self) -> u32 {
        self.steps
    }
    /// Steps of this episode that ended in contact ([`ReachEnv::contact`]).
    pub fn collision_steps(&self) -> u32 {
        self.collision_steps
    }
    /// The episode has ended.
    pub fn is_done(&self) -> bool {
        self.done
    }
    /// Whether contacts are looked for at all: the arm has collision shapes. When not,
    /// [`ReachEnv::collision_steps`] is 0 without meaning, and episodes and evaluations record
    /// no collision count ("not checked").
    pub fn collisions_checked(&self) -> bool {
        !self.chain.collision_shapes().is_empty()
    }
    /// The arm.
    pub fn chain(&self) -> &Arc<Chain> {
        &self.chain
    }
    /// From the next reset on, place an episode's first random obstacle in the way from the
    /// start pose's end effector to the target with probability `fraction` (the trainer's
    /// `train.obstacles_in_path`; see [`crate::sim::scene::place_obstacles`]). 0, the default, draws
    /// every obstacle from the region.
    ///
    /// Errors: a fraction outside [0, 1] (or NaN), or a positive one for a task without
    /// `[task.random_obstacles]`.
    pub fn set_obstacles_in_path(&mut self, fraction: f64) -> Result<()> {
        check_obstacles_in_path(fraction, self.task.random_obstacles.is_some())?;
        self.obstacles_in_path = fraction;
        Ok(())
    }

    /// From the next reset on, draw an episode's random obstacle count uniformly from
    /// `task.random_obstacles.count[0]` to `max` instead of to `count[1]` (the curriculum's
    /// stages, `[train.curriculum]`). `max = count[1]` draws as the task says.
    ///
    /// Errors: a task without `[task.random_obstacles]`, or `max` outside its `count`.
    pub fn set_max_random_obstacles(&mut self, max: u32) -> Result<()> {
        let Some(random) = &self.task.random_obstacles else {
            return Err(Error::InvalidInput(
                "a largest random obstacle count for a task without [task.random_obstacles]".into(),
            ));
        };
        let [lo, hi] = random.count;
        if !(lo..=hi).contains(&max) {
            return Err(Error::config(
                "train.curriculum.max_obstacles",
                max,
                format!("a count within task.random_obstacles.count = [{lo}, {hi}]"),
            ));
        }
        self.capped_random = (max < hi).then(|| {
            let mut capped = random.clone();
            capped.count[1] = max;
            capped
        });
        Ok(())
    }

    /// The resolved task.
    pub fn task(&self) -> &ResolvedTask {
        &self.task
    }
    /// The reward settings.
    pub fn reward_config(&self) -> &RewardConfig {
        &self.reward
    }
    /// The environment's whole state (for checkpoints).
    pub fn state(&self) -> EnvState {
        EnvState {
            rng: self.rng.clone(),
            q: self.q.clone(),
            joint_vel: self.joint_vel.clone(),
            target: [self.target.x, self.target.y, self.target.z],
            steps: self.steps,
            done: self.done,
            collision_steps: self.collision_steps,
            random_obstacles: self.obstacles[self.task.obstacles.len()..].to_vec(),
            sim_velocities: self.arm.sim_velocities(),
            request_obstacles: self.request_obstacles.clone(),
            shield_episode: self.episode_shield_stats(),
        }
    }

    /// Restore a state from [`ReachEnv::state`]; errors if it does not fit this arm.
    pub fn restore(&mut self, s: &EnvState) -> Result<()> {
        let n = self.q.len();
        if s.q.len() != n || s.joint_vel.len() != n {
            return Err(Error::InvalidInput(format!(
                "environment state for {} joints, the arm has {n}",
                s.q.len()
            )));
        }
        if !(s.sim_velocities.is_empty() || s.sim_velocities.len() == n) {
            return Err(Error::InvalidInput(format!(
                "environment state with {} simulated joint velocities, the arm has {n} joints",
                s.sim_velocities.len()
            )));
        }
        let finite =
            s.q.iter().chain(&s.joint_vel).chain(&s.target).chain(&s.sim_velocities).all(|x| x.is_finite());
        if !finite {
            return Err(Error::InvalidInput("environment state holds a non-finite value".into()));
        }
        if let Some(r) = &s.request_obstacles {
            request::check_obstacle_values(r, "EnvState.request_obstacles")?;
        }
        // This episode's obstacles after the fixed ones: the task's random ones, or a request's.
        let random = self.task.max_obstacles() - self.task.obstacles.len();
        let max = random.max(s.request_obstacles.as_ref().map_or(0, Vec::len));
        if s.random_obstacles.len() > max {
            return Err(Error::InvalidInput(format!(
                "environment state with {} random obstacles, the task allows {random} and its request's scene {}",
                s.random_obstacles.len(),
                s.request_obstacles.as_ref().map_or(0, Vec::len)
            )));
        }
        for (i, o) in s.random_obstacles.iter().enumerate() {
            o.validate(&format!("environment state: random obstacle {i}"))?;
        }
        self.rng = s.rng.clone();
        self.q.copy_from_slice(&s.q);
        self.joint_vel.copy_from_slice(&s.joint_vel);
        self.target = Vector3::from(s.target);
        self.steps = s.steps;
        self.done = s.done;
        self.collision_steps = s.collision_steps;
        self.request_obstacles.clone_from(&s.request_obstacles);
        if let (Some(shield), Some(stats)) = (self.arm.shield_mut(), s.shield_episode) {
            shield.resume_episode(stats);
        }
        self.obstacles.truncate(self.task.obstacles.len());
        self.obstacles.extend(s.random_obstacles.iter().cloned());
        self.arm.set_obstacles(&self.obstacles);
        let v = if s.sim_velocities.is_empty() { &s.joint_vel } else { &s.sim_velocities };
        self.arm.set_state(&self.chain, &self.q, v)?;
        self.ee = self.chain.fk(&self.q);
        self.measure_proximity();
        self.write_observation();
        Ok(())
    }

    /// The random generator's state (for checkpoints).
    pub fn rng(&self) -> &Rng {
        &self.rng
    }
    /// Replace the random generator's state (when resuming).
    pub fn set_rng(&mut self, rng: Rng) {
        self.rng = rng;
    }
}

#[cfg(test)]
pub(crate) mod tests;
