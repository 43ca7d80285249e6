//! Planning: the joint trajectory from a start pose to a target, by rolling out (eq. 16,
//! [`crate::env::rollout()`]) a trained agent's deterministic policy or the scripted
//! [`JacobianController`], every state recorded.
//!
//! Row `k` of a [`Plan`] is the state after `k` control steps (row 0 the start, its joint
//! velocities zero, its reward 0): joint positions (rad), the joint velocities applied in step
//! `k` (rad/s), the end-effector pose (metres; quaternion `(x, y, z, w)`), the distance to the
//! target (metres) and step `k`'s reward (bonus included). The [`PlanSummary`] adds the path
//! length of the end effector (the sum of its displacements, metres) and the joint travel (the
//! sum of `|dq|` over steps and joints, radians).
//!
//! Checked before planning: a target of three finite values, not below the floor (`z >= 0`) and
//! within [`Chain::reach_m`] of the first joint; a start pose of one value per joint within the
//! limits. A target outside the training target distribution is planned with a
//! [`Plan::warning`].

pub mod controller;
pub mod problems;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::agent::Agent;
use crate::base::rng::Rng;
use crate::config::Config;
use crate::env::request::{check_obstacle_values, check_scene_for_request};
use crate::env::{
    check_joint_positions, rollout, track_waypoints, Flow, Observed, Outcome, ReachEnv, ResolvedTask, Scratch,
};
use crate::plan::controller::JacobianController;
use crate::robot::Chain;
use crate::run::dir::RunDir;
use crate::sim::collision::ArmCollider;
use crate::sim::rrt_connect::{RrtConnect, RrtStats};
use crate::sim::scene::Obstacle;
use crate::{Error, Result};

/// What chooses the actions of a plan.
pub enum PlanPolicy {
    /// A trained agent's deterministic action ([`Agent::predict`]).
    Agent(Box<dyn Agent>),
    /// The scripted damped-least-squares controller.
    Jacobian(JacobianController),
    /// The sampling-based reference planner ([`crate::sim::rrt_connect`]).
    RrtConnect(RrtConnect),
}

/// One plan request (a line of batch input): a target, metres, optionally a start pose,
/// radians (default: the task's home pose), and optionally obstacles (the schema of
/// `[[task.obstacles]]`), which add to the planner's fixed scene ([`Planner::set_scene`]).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlanRequest {
    pub target: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<Vec<Obstacle>>,
}

/// The outcome of a plan.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlanSummary {
    /// The last step ended within beta of the target (the episode terminated).
    pub reached: bool,
    /// Control steps taken.
    pub steps: u32,
    /// Distance to the target after the last step, metres.
    pub final_distance: f64,
    /// Eq. 16's `R_episode`: the sum of the steps' rewards.
    pub episode_reward: f64,
    /// Sum of the end effector's displacements between rows, metres.
    pub path_length_m: f64,
    /// Sum over steps and joints of `|q[k+1] - q[k]|`, radians.
    pub joint_travel_rad: f64,
    /// Steps that ended with the arm in contact (floor, itself, an obstacle): 0 for a
    /// collision-free plan.
    pub collision_steps: u32,
    /// Any contact (floor, itself, an obstacle, as the task checks them) anywhere along the
    /// path: the start pose, and the linear joint motion of every step checked continuously
    /// ([`ArmCollider::check_motion`]).
    pub collision: bool,
    /// The smallest distance between the arm's collision shapes and the scene's obstacles along
    /// the path (metres, negative: a penetration's depth; within
    /// [`crate::sim::collision::motion::CLEARANCE_TOLERANCE_M`]); the floor and the arm's own
    /// pairs do not count. `None` (`null`) without obstacles or collision shapes.
    pub min_clearance_m: Option<f64>,
    /// Wall time from the checked request to the trajectory (planning and rollout; not the
    /// collision report above), seconds.
    pub plan_time_s: f64,
    /// Why the plan does not reach the target, when a planner knows (RRT-Connect: no
    /// collision-free goal, the budget spent, a path longer than the step limit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// RRT-Connect's statistics (that planner only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rrt_connect: Option<RrtStats>,
    /// What the safety shield did in this plan (`--shield`; left out when it is off).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub shield: Option<crate::sim::shield::ShieldSummary>,
}

/// A planned trajectory: `rows()` states, stored by column.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Joints of the arm.
    pub dof: usize,
    /// Control period, seconds.
    pub dt_s: f64,
    /// Joint positions, rows x dof, radians.
    pub q: Vec<f64>,
    /// Joint velocities applied in the step that led to each row, rows x dof, rad/s.
    pub joint_vel: Vec<f64>,
    /// End-effector positions, metres.
    pub ee_pos: Vec<[f64; 3]>,
    /// End-effector orientations `(x, y, z, w)`.
    pub ee_quat: Vec<[f64; 4]>,
    /// Distance to the target per row, metres.
    pub distance: Vec<f64>,
    /// Reward of the step that led to each row (0 for row 0).
    pub reward: Vec<f64>,
    pub summary: PlanSummary,
    /// Set when the target lies outside the training target distribution (the plan still ran).
    pub warning: Option<String>,
}

/// One row of a [`Plan`], as the JSON-lines output writes it.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PlanRow<'a> {
    pub step: usize,
    pub t_s: f64,
    pub q: &'a [f64],
    pub joint_vel: &'a [f64],
    pub ee_pos: [f64; 3],
    pub ee_quat: [f64; 4],
    pub distance: f64,
    pub reward: f64,
}

/// A plan as one line of batch output: the summary's first four fields, the collision report,
/// the plan time and the trajectory.
#[derive(Clone, Debug, Serialize)]
pub struct BatchRecord<'a> {
    pub reached: bool,
    pub steps: u32,
    pub final_distance: f64,
    pub episode_reward: f64,
    pub collision: bool,
    pub min_clearance_m: Option<f64>,
    pub plan_time_s: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rrt_connect: Option<RrtStats>,
    pub q: Vec<&'a [f64]>,
    pub ee_pos: &'a [[f64; 3]],
    /// What the safety shield did (`--shield`; left out when it is off).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub shield: Option<crate::sim::shield::ShieldSummary>,
}

/// A plan that serialises as its [`BatchRecord`] (one line of batch output).
#[derive(Clone, Debug)]
pub struct BatchLine(pub Plan);

impl Serialize for BatchLine {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        self.0.batch_record().serialize(s)
    }
}

impl Plan {
    fn start(env: &ReachEnv, capacity: usize) -> Plan {
        let n = env.act_dim();
        let mut plan = Plan {
            dof: n,
            dt_s: env.task().dt_s,
            q: Vec::with_capacity(capacity * n),
            joint_vel: Vec::with_capacity(capacity * n),
            ee_pos: Vec::with_capacity(capacity),
            ee_quat: Vec::with_capacity(capacity),
            distance: Vec::with_capacity(capacity),
            reward: Vec::with_capacity(capacity),
            summary: PlanSummary {
                reached: false,
                steps: 0,
                final_distance: env.distance(),
                episode_reward: 0.0,
                path_length_m: 0.0,
                joint_travel_rad: 0.0,
                collision_steps: 0,
                collision: false,
                min_clearance_m: None,
                plan_time_s: 0.0,
                reason: None,
                rrt_connect: None,
                shield: None,
            },
            warning: None,
        };
        plan.record(env, 0.0);
        plan.joint_vel.iter_mut().for_each(|v| *v = 0.0);
        plan
    }

    /// Append the environment's current state as a row reached with `reward`.
    fn record(&mut self, env: &ReachEnv, reward: f64) {
        let ee = env.ee_pose();
        let p = [ee.position.x, ee.position.y, ee.position.z];
        if let Some(last) = self.ee_pos.last() {
            let d = (ee.position - Vector3::from(*last)).norm();
            self.summary.path_length_m += d;
            let prev = &self.q[self.q.len() - self.dof..];
            let travel: f64 = prev.iter().zip(env.joint_positions()).map(|(a, b)| (b - a).abs()).sum();
            self.summary.joint_travel_rad += travel;
        }
        self.q.extend_from_slice(env.joint_positions());
        self.joint_vel.extend_from_slice(env.joint_velocities());
        self.ee_pos.push(p);
        self.ee_quat.push(ee.quaternion_xyzw());
        self.distance.push(env.distance());
        self.reward.push(reward);
    }

    /// Number of rows (steps + 1).
    pub fn rows(&self) -> usize {
        self.distance.len()
    }

    /// Row `k`.
    pub fn row(&self, k: usize) -> PlanRow<'_> {
        let n = self.dof;
        PlanRow {
            step: k,
            t_s: k as f64 * self.dt_s,
            q: &self.q[k * n..(k + 1) * n],
            joint_vel: &self.joint_vel[k * n..(k + 1) * n],
            ee_pos: self.ee_pos[k],
            ee_quat: self.ee_quat[k],
            distance: self.distance[k],
            reward: self.reward[k],
        }
    }

    /// The plan as one line of batch output.
    pub fn batch_record(&self) -> BatchRecord<'_> {
        BatchRecord {
            reached: self.summary.reached,
            steps: self.summary.steps,
            final_distance: self.summary.final_distance,
            episode_reward: self.summary.episode_reward,
            collision: self.summary.collision,
            min_clearance_m: self.summary.min_clearance_m,
            plan_time_s: self.summary.plan_time_s,
            reason: self.summary.reason.as_deref(),
            rrt_connect: self.summary.rrt_connect,
            q: self.q.chunks_exact(self.dof).collect(),
            ee_pos: &self.ee_pos,
            shield: self.summary.shield,
        }
    }

    /// The CSV header for an arm of `dof` joints: `step,t_s,q0..,joint_vel0..,ee_x,ee_y,ee_z,
    /// ee_qx,ee_qy,ee_qz,ee_qw,distance,reward`.
    pub fn csv_header(dof: usize) -> String {
        let mut h = String::from("step,t_s");
        for prefix in ["q", "joint_vel"] {
            for i in 0..dof {
                let _ = write!(h, ",{prefix}{i}");
            }
        }
        h.push_str(",ee_x,ee_y,ee_z,ee_qx,ee_qy,ee_qz,ee_qw,distance,reward");
        h
    }

    /// The plan as CSV (header and one line per row; floats in Rust's shortest round-trip form,
    /// as every CSV of stagerl).
    pub fn to_csv(&self) -> String {
        let mut out = Plan::csv_header(self.dof);
        out.push('\n');
        for k in 0..self.rows() {
            let r = self.row(k);
            let _ = write!(out, "{},{}", r.step, r.t_s);
            for v in r.q.iter().chain(r.joint_vel).chain(&r.ee_pos).chain(&r.ee_quat) {
                let _ = write!(out, ",{v}");
            }
            let _ = writeln!(out, ",{},{}", r.distance, r.reward);
        }
        out
    }
}

/// Where the training targets lie: the cells of a grid of [`REGION_CELL_M`] cubes that hold one
/// of 20 000 seeded draws of the task's target distribution, or touch one that does.
#[derive(Clone, Debug, PartialEq)]
struct TargetRegion {
    cells: HashSet<[i64; 3]>,
}

/// Edge of the grid cells of the training-target region, metres: a target more than one cell
/// from every sampled training target is reported as outside the distribution.
pub const REGION_CELL_M: f64 = 0.05;

fn cell(p: &Vector3<f64>) -> [i64; 3] {
    [0, 1, 2].map(|i| (p[i] / REGION_CELL_M).floor() as i64)
}

impl TargetRegion {
    fn of(task: &ResolvedTask, chain: &Chain) -> TargetRegion {
        let mut rng = Rng::new(0x9_1A4);
        let mut scratch = vec![0.0; chain.dof()];
        let mut cells = HashSet::new();
        for _ in 0..20_000 {
            let c = cell(&task.sample_target(chain, &mut rng, &mut scratch));
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        cells.insert([c[0] + dx, c[1] + dy, c[2] + dz]);
                    }
                }
            }
        }
        TargetRegion { cells }
    }

    /// Why `target` lies outside the region, if it does.
    fn outside(&self, target: &Vector3<f64>) -> Option<String> {
        (!self.cells.contains(&cell(target))).then(|| {
            format!(
                "target [{}, {}, {}] lies outside the training target distribution (more than {} m \
                 from every sampled training target); the policy was not trained there",
                target.x, target.y, target.z, REGION_CELL_M
            )
        })
    }
}

/// Plans trajectories on one environment with one policy.
pub struct Planner {
    env: ReachEnv,
    policy: PlanPolicy,
    scratch: Scratch,
    /// Where the policy was trained (for agents; the controller needs no training).
    region: Option<TargetRegion>,
    /// The fixed scene of every request ([`Planner::set_scene`]) and its name in messages.
    scene: Vec<Obstacle>,
    scene_name: String,
    /// The checker of RRT-Connect and of the paths' collision report.
    collider: ArmCollider,
}

impl Planner {
    /// A planner for `policy` on `env` (its task's `max_steps` bounds a plan).
    pub fn new(env: ReachEnv, policy: PlanPolicy) -> Planner {
        let region = match policy {
            PlanPolicy::Agent(_) => Some(TargetRegion::of(env.task(), env.chain())),
            PlanPolicy::Jacobian(_) | PlanPolicy::RrtConnect(_) => None,
        };
        let collider = ArmCollider::new(env.chain(), env.task().collision);
        Planner {
            scratch: Scratch::new(&env),
            env,
            policy,
            region,
            scene: Vec::new(),
            scene_name: "scene".into(),
            collider,
        }
    }

    /// The deterministic policy of a run directory's checkpoint (`checkpoint`, else the best
    /// available), with `max_steps` (default: the run's `task.max_steps`); the checkpoint's path
    /// first.
    pub fn from_run(
        run: &RunDir,
        checkpoint: Option<&Path>,
        max_steps: Option<u32>,
    ) -> Result<(PathBuf, Planner)> {
        let mut cfg = run.load_config()?;
        set_max_steps(&mut cfg, max_steps)?;
        let (path, env, agent) = crate::train::eval::load_run_agent(run, &cfg, checkpoint)?;
        Ok((path, Planner::new(env, PlanPolicy::Agent(agent))))
    }

    /// The Jacobian controller on the task and arm of `cfg`, with `max_steps` (default: the
    /// config's `task.max_steps`).
    pub fn jacobian(cfg: &Config, max_steps: Option<u32>) -> Result<Planner> {
        let mut cfg = cfg.clone();
        set_max_steps(&mut cfg, max_steps)?;
        let env = ReachEnv::from_config(&cfg, 0)?;
        let ctl = JacobianController::new(env.chain());
        Ok(Planner::new(env, PlanPolicy::Jacobian(ctl)))
    }

    /// RRT-Connect with settings `rrt` on the task and arm of `cfg`, with `max_steps`
    /// (default: the config's `task.max_steps`) bounding the timed path.
    pub fn rrt_connect(cfg: &Config, max_steps: Option<u32>, rrt: RrtConnect) -> Result<Planner> {
        check_rrt_settings(&rrt)?;
        let mut cfg = cfg.clone();
        set_max_steps(&mut cfg, max_steps)?;
        let env = ReachEnv::from_config(&cfg, 0)?;
        Ok(Planner::new(env, PlanPolicy::RrtConnect(rrt)))
    }

    /// The fixed scene of every later request (`stagerl plan --scene`): a request's own
    /// obstacles add to it (the scene first). `name` names the list in messages (`--scene
    /// s.toml obstacles`: `--scene s.toml obstacles[2].radius_m`). Errors: a bad obstacle.
    pub fn set_scene(&mut self, obstacles: Vec<Obstacle>, name: &str) -> Result<()> {
        check_obstacle_values(&obstacles, name)?;
        self.scene = obstacles;
        self.scene_name = name.into();
        Ok(())
    }

    /// The fixed scene ([`Planner::set_scene`]).
    pub fn scene(&self) -> &[Obstacle] {
        &self.scene
    }

    /// Turn the safety shield on or off for the plans to come (see [`ReachEnv::set_shield`]).
    pub fn set_shield(&mut self, enabled: bool) -> Result<()> {
        self.env.set_shield(enabled)
    }

    /// Place each plan's first random obstacle in the way with probability `fraction` (see
    /// [`ReachEnv::set_obstacles_in_path`]).
    pub fn set_obstacles_in_path(&mut self, fraction: f64) -> Result<()> {
        self.env.set_obstacles_in_path(fraction)
    }

    /// Reseed the environment's random stream (the random obstacles of the plans to come).
    pub fn reseed(&mut self, seed: u64) {
        self.env.reseed(seed);
    }

    /// The environment plans run on.
    pub fn env(&self) -> &ReachEnv {
        &self.env
    }

    /// Check a target (metres): three finite values, `z >= 0`, within the arm's reach of its
    /// first joint.
    pub fn check_target(&self, target: &[f64]) -> Result<Vector3<f64>> {
        self.env.check_target(target)
    }

    /// Plan from `start` (radians; default: the home pose) to `target` (metres) in the fixed
    /// scene.
    pub fn plan(&mut self, target: &[f64], start: Option<&[f64]>) -> Result<Plan> {
        self.plan_among(target, start, None)
    }

    /// Plan one request.
    pub fn plan_request(&mut self, r: &PlanRequest) -> Result<Plan> {
        self.plan_among(&r.target, r.start.as_deref(), r.obstacles.as_deref())
    }

    /// Plan from `start` (radians; default: the home pose) to `target` (metres) among the
    /// task's fixed obstacles, the fixed scene and `obstacles` (named `obstacles[i]` in
    /// messages). With neither a scene nor `obstacles`, the task's scene as it is (its random
    /// obstacles drawn). The request is checked first ([`crate::env::request`]).
    pub fn plan_among(
        &mut self,
        target: &[f64],
        start: Option<&[f64]>,
        obstacles: Option<&[Obstacle]>,
    ) -> Result<Plan> {
        let t = self.check_target(target)?;
        let start: Vec<f64> = start.map_or_else(|| self.env.task().home_pose.clone(), <[f64]>::to_vec);
        check_joint_positions(self.env.chain(), &start)?;
        if let Some(o) = obstacles {
            check_obstacle_values(o, "obstacles")?;
        }
        let given = obstacles.is_some() || !self.scene.is_empty();
        let extra: Vec<Obstacle> = self.scene.iter().chain(obstacles.unwrap_or_default()).cloned().collect();
        self.check_scene(&extra, &start, t)?;
        self.env.set_request_obstacles(given.then_some(&extra[..]));
        let timer = std::time::Instant::now();
        self.env.reset_to(&start, t)?;
        let mut plan = self.roll_out()?;
        plan.summary.plan_time_s = timer.elapsed().as_secs_f64();
        self.report_collisions(&mut plan);
        let warnings: Vec<String> =
            [self.region.as_ref().and_then(|r| r.outside(&t)), self.observation_warning(given)]
                .into_iter()
                .flatten()
                .collect();
        plan.warning = (!warnings.is_empty()).then(|| warnings.join("; "));
        Ok(plan)
    }

    /// [`check_scene_for_request`] of the task's fixed obstacles and `extra` (the scene's,
    /// then the request's).
    fn check_scene(&mut self, extra: &[Obstacle], start: &[f64], t: Vector3<f64>) -> Result<()> {
        let c = &mut self.collider;
        let fixed = &self.env.task().obstacles;
        let all: Vec<Obstacle> = fixed.iter().chain(extra).cloned().collect();
        let (nf, ns) = (fixed.len(), self.scene.len());
        let named = |i: usize| match i {
            i if i < nf => format!("task.obstacles[{i}]"),
            i if i < nf + ns => format!("{}[{}]", self.scene_name, i - nf),
            i => format!("obstacles[{}]", i - nf - ns),
        };
        check_scene_for_request(self.env.chain(), c, &all, named, start, Some(t))
    }

    /// Roll the policy out from the environment's reset state, every state recorded.
    fn roll_out(&mut self) -> Result<Plan> {
        let mut plan = Plan::start(&self.env, self.env.task().max_steps as usize + 1);
        let mut waypoints = Vec::new();
        if let PlanPolicy::RrtConnect(rrt) = &self.policy {
            let (env, c) = (&self.env, &mut self.collider);
            let start = env.joint_positions().to_vec();
            let (stats, path) =
                rrt.plan_timed(env.chain(), c, env.obstacles(), &start, &env.target(), env.task().dt_s);
            plan.summary.rrt_connect = Some(stats);
            match path {
                Ok(path) => waypoints = path,
                Err(why) => {
                    plan.summary.reason = Some(format!("RRT-Connect found no path: {why}"));
                    return Ok(plan);
                }
            }
        }
        let outcome = {
            let record = |tr: &crate::env::Transition<'_>| {
                plan.record(tr.env, tr.step.total());
                Ok(Flow::Continue)
            };
            match &mut self.policy {
                PlanPolicy::Agent(agent) => {
                    let act = crate::train::eval::deterministic(agent.as_mut());
                    rollout(&mut self.env, &mut self.scratch, &mut Observed(act, record))?
                }
                PlanPolicy::Jacobian(ctl) => {
                    rollout(&mut self.env, &mut self.scratch, &mut Observed(ctl.policy(), record))?
                }
                PlanPolicy::RrtConnect(_) => rollout(
                    &mut self.env,
                    &mut self.scratch,
                    &mut Observed(track_waypoints(&waypoints), record),
                )?,
            }
        };
        let Outcome::Finished { reward, last } = outcome else {
            return Err(Error::InvalidInput("the plan's rollout stopped before the episode ended".into()));
        };
        plan.summary.reached = last.reached();
        plan.summary.steps = self.env.steps();
        plan.summary.final_distance = self.env.distance();
        plan.summary.episode_reward = reward;
        plan.summary.collision_steps = self.env.collision_steps();
        let needed = waypoints.len().saturating_sub(1);
        if !plan.summary.reached && needed > plan.summary.steps as usize {
            plan.summary.reason = Some(format!(
                "the path needs {needed} control steps at the joints' speed limits, more than the step \
                 limit of {} (raise --max-steps)",
                plan.summary.steps
            ));
        }
        plan.summary.shield = self.env.episode_shield_stats().map(Into::into);
        Ok(plan)
    }

    /// The continuous collision report of `plan` among the episode's obstacles: `collision`
    /// and `min_clearance_m`.
    fn report_collisions(&mut self, plan: &mut Plan) {
        let c = &mut self.collider;
        if c.is_empty() {
            return;
        }
        let chain = self.env.chain();
        c.set_obstacles(self.env.obstacles());
        let n = plan.dof;
        let row = |k: usize| &plan.q[k * n..(k + 1) * n];
        let mut collision = plan.summary.collision_steps > 0 || c.check(chain, row(0)).is_some();
        let mut clearance = c.motion_clearance_m(chain, row(0), row(0));
        for k in 1..plan.rows() {
            collision = collision || c.check_motion(chain, row(k - 1), row(k)).is_some();
            if let Some(d) = c.motion_clearance_m(chain, row(k - 1), row(k)) {
                clearance = Some(clearance.map_or(d, |m| m.min(d)));
            }
        }
        // A graze between two checked poses that the clearance's finer sampling saw.
        plan.summary.collision = collision || clearance.is_some_and(|m| m < 0.0);
        plan.summary.min_clearance_m = clearance;
    }

    /// What a policy that observes obstacles misses of the scene, if anything.
    fn observation_warning(&self, given: bool) -> Option<String> {
        if !matches!(self.policy, PlanPolicy::Agent(_)) {
            return None;
        }
        let task = self.env.task();
        let n = self.env.obstacles().len();
        if task.observe_obstacles && task.obstacle_observation == crate::env::ObstacleObservation::PerLink {
            // One slot per collision shape, each with its nearest obstacle among all of them.
            None
        } else if task.observe_obstacles {
            let slots = task.obstacle_slots();
            (n > slots).then(|| {
                format!(
                    "the policy observes {slots} obstacle(s) and the scene has {n}: it sees the {slots} \
                     nearest to the end effector at each step"
                )
            })
        } else {
            (given && n > 0).then(|| {
                "the policy was trained without observing obstacles (task.observe_obstacles = false): \
                 it does not see the scene's obstacles (collision and min_clearance_m report what it did)"
                    .to_string()
            })
        }
    }
}

/// Check RRT-Connect's settings (`--planner-budget-s`, `--planner-iterations`).
fn check_rrt_settings(r: &RrtConnect) -> Result<()> {
    if !(r.budget_s.is_finite() && r.budget_s > 0.0 && r.budget_s <= 3600.0) {
        return Err(Error::config("planner budget (--planner-budget-s)", r.budget_s, "seconds in (0, 3600]"));
    }
    if r.max_iterations == 0 {
        return Err(Error::config("planner iterations (--planner-iterations)", 0, "1 or more"));
    }
    if !(r.step_rad.is_finite() && r.step_rad > 0.0) {
        return Err(Error::config("RRT-Connect step_rad", r.step_rad, "a positive number of radians"));
    }
    Ok(())
}

fn set_max_steps(cfg: &mut Config, max_steps: Option<u32>) -> Result<()> {
    if let Some(n) = max_steps {
        if n == 0 {
            return Err(Error::InvalidInput("max steps 0: a plan needs at least 1 step".into()));
        }
        cfg.task.max_steps = n;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
