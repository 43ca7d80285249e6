//! Evaluation trajectories: the end-effector paths of a trained policy, recomputed by loading the
//! run's checkpoint and rolling out its deterministic policy (the per-trial CSV holds no paths).

use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

use super::runs::RunData;
use super::table::{algo_title, reward_title};
use crate::env::{Driver, Flow, ReachEnv, Transition};
use crate::io::csv::{self, CsvRow};
use crate::run::dir::RunDir;
use crate::train::eval;
use crate::Result;

/// One evaluation episode's path.
#[derive(Clone, Debug, Serialize)]
pub struct TrajectoryPath {
    /// 1-based, as in the per-trial CSV.
    pub trial: u32,
    /// End-effector positions from the reset to the last step, metres.
    pub points: Vec<[f64; 3]>,
    pub target: [f64; 3],
    pub success: bool,
    pub reward: f64,
}

/// Paths of one run.
#[derive(Clone, Debug, Serialize)]
pub struct Rollouts {
    pub title: String,
    pub run: String,
    /// The checkpoint rolled out, relative to the report's input directory.
    pub checkpoint: String,
    pub eval_seed: u64,
    /// Success threshold, metres (drawn around the targets).
    pub beta_m: f64,
    pub paths: Vec<TrajectoryPath>,
}

/// A policy whose end-effector path is recorded, from each reset to the episode's end.
struct Tracer<P> {
    policy: P,
    paths: Vec<Vec<[f64; 3]>>,
}

impl<P: FnMut(&ReachEnv, &mut [f32]) -> Result<()>> Driver for Tracer<P> {
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()> {
        if env.steps() == 0 {
            self.paths.push(vec![env.ee_pose().position.into()]);
        }
        (self.policy)(env, action)
    }
    fn on_step(&mut self, t: &Transition<'_>) -> Result<Flow> {
        if let Some(path) = self.paths.last_mut() {
            path.push(t.env.ee_pose().position.into());
        }
        Ok(Flow::Continue)
    }
}

/// Roll out the first `trials` evaluation episodes of `run`'s deterministic policy from its best
/// available checkpoint, with the targets of evaluation seed `eval_seed` (the same trials as the
/// per-trial CSV written with that seed).
pub fn rollout(run: &RunData, trials: u32, eval_seed: u64) -> Result<Rollouts> {
    let cfg = &run.config;
    let (ckpt, mut env, mut agent) = eval::load_run_agent(&RunDir::new(&run.dir), cfg, None)?;
    let mut driver = Tracer { policy: eval::deterministic(agent.as_mut()), paths: Vec::new() };
    let (_, records) = eval::evaluate(&mut env, &mut driver, &eval::EvalOptions::new(trials, eval_seed))?;
    let points = driver.paths;
    let paths: Vec<TrajectoryPath> = records
        .iter()
        .zip(points)
        .map(|(r, points)| TrajectoryPath {
            trial: r.trial,
            points,
            target: r.target,
            success: r.success,
            reward: r.reward,
        })
        .collect();
    let reached = paths.iter().filter(|p| p.success).count();
    Ok(Rollouts {
        title: format!(
            "{} + {} ({}, seed {}): {reached} of {trials} trials reached",
            algo_title(crate::report::method::Method::of(cfg)),
            reward_title(cfg.reward.function),
            run.name,
            run.seed()
        ),
        run: run.name.clone(),
        checkpoint: Path::new(&run.name)
            .join(ckpt.strip_prefix(&run.dir).unwrap_or(&ckpt))
            .display()
            .to_string(),
        eval_seed,
        beta_m: cfg.reward.beta_m,
        paths,
    })
}

/// A row of `trajectories.csv`: one point of one evaluation path.
pub struct TrajectoryRow<'a> {
    pub run: &'a str,
    pub path: &'a TrajectoryPath,
    /// 0 at the reset.
    pub step: usize,
}

impl CsvRow for TrajectoryRow<'_> {
    const HEADER: &'static str = "run,trial,step,x_m,y_m,z_m,target_x_m,target_y_m,target_z_m,success";

    fn write_row(&self, out: &mut String) {
        let TrajectoryRow { run, path, step } = *self;
        let ([x, y, z], [tx, ty, tz]) = (path.points[step], path.target);
        let (trial, success) = (path.trial, u8::from(path.success));
        let _ = write!(out, "{run},{trial},{step},{x},{y},{z},{tx},{ty},{tz},{success}");
    }
}

/// The paths as CSV, one row per point ([`TrajectoryRow`]).
pub fn to_csv(sets: &[Rollouts]) -> String {
    let rows: Vec<TrajectoryRow<'_>> = sets
        .iter()
        .flat_map(|set| {
            set.paths.iter().flat_map(move |path| {
                (0..path.points.len()).map(move |step| TrajectoryRow { run: &set.run, path, step })
            })
        })
        .collect();
    csv::to_csv(&rows)
}
