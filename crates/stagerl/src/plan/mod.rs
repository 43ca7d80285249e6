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

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::agent::Agent;
use crate::base::rng::Rng;
use crate::config::Config;
use crate::env::{rollout, Flow, Observed, Outcome, ReachEnv, ResolvedTask, Scratch};
use crate::plan::controller::JacobianController;
use crate::robot::Chain;
use crate::run::dir::RunDir;
use crate::{Error, Result};

/// What chooses the actions of a plan.
pub enum PlanPolicy {
    /// A trained agent's deterministic action ([`Agent::predict`]).
    Agent(Box<dyn Agent>),
    /// The scripted damped-least-squares controller.
    Jacobian(JacobianController),
}

/// One plan request (a line of batch input): a target, metres, and optionally a start pose,
/// radians (default: the task's home pose).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlanRequest {
    pub target: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start: Option<Vec<f64>>,
}

/// The outcome of a plan.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
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

/// A plan as one line of batch output: the summary's first four fields and the trajectory.
#[derive(Clone, Debug, Serialize)]
pub struct BatchRecord<'a> {
    pub reached: bool,
    pub steps: u32,
    pub final_distance: f64,
    pub episode_reward: f64,
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
}

impl Planner {
    /// A planner for `policy` on `env` (its task's `max_steps` bounds a plan).
    pub fn new(env: ReachEnv, policy: PlanPolicy) -> Planner {
        let region = match policy {
            PlanPolicy::Agent(_) => Some(TargetRegion::of(env.task(), env.chain())),
            PlanPolicy::Jacobian(_) => None,
        };
        Planner { scratch: Scratch::new(&env), env, policy, region }
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

    /// Plan from `start` (radians; default: the home pose) to `target` (metres).
    pub fn plan(&mut self, target: &[f64], start: Option<&[f64]>) -> Result<Plan> {
        let t = self.check_target(target)?;
        let home;
        let start = match start {
            Some(s) => s,
            None => {
                home = self.env.task().home_pose.clone();
                &home
            }
        };
        self.env.reset_to(start, t)?;
        let warning = self.region.as_ref().and_then(|r| r.outside(&t));
        let mut plan = Plan::start(&self.env, self.env.task().max_steps as usize + 1);
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
        plan.summary.shield = self.env.episode_shield_stats().map(Into::into);
        plan.warning = warning;
        Ok(plan)
    }

    /// Plan one request.
    pub fn plan_request(&mut self, r: &PlanRequest) -> Result<Plan> {
        self.plan(&r.target, r.start.as_deref())
    }
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
