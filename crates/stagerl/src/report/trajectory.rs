//! Evaluation trajectories: the end-effector paths of a trained policy, recomputed by loading the
//! run's checkpoint and rolling out its deterministic policy (the per-trial CSV holds no paths).

use serde::Serialize;
use std::fmt::Write as _;

use super::runs::RunData;
use super::table::{algo_title, reward_title};
use crate::env::ReachEnv;
use crate::train::{self, RunDir};
use crate::{Error, Result};

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
    pub checkpoint: String,
    pub eval_seed: u64,
    /// Success threshold, metres (drawn around the targets).
    pub beta_m: f64,
    pub paths: Vec<TrajectoryPath>,
}

/// Roll out the first `trials` evaluation episodes of `run`'s deterministic policy from its best
/// available checkpoint, with the targets of evaluation seed `eval_seed` (the same trials as the
/// per-trial CSV written with that seed).
pub fn rollout(run: &RunData, trials: u32, eval_seed: u64) -> Result<Rollouts> {
    let rd = RunDir::new(&run.dir);
    let ckpt = rd
        .best_available_checkpoint()
        .ok_or_else(|| Error::InvalidInput(format!("{}: no checkpoint", rd.checkpoints().display())))?;
    let cfg = &run.config;
    let mut env = ReachEnv::from_config(cfg, 0)?;
    let mut agent = train::load_agent(cfg, &env, &ckpt)?;
    let mut action = vec![0.0f32; env.act_dim()];
    env.reset_with_seed(eval_seed);
    let mut paths = Vec::new();
    for trial in 0..trials {
        if trial > 0 {
            env.reset();
        }
        let t = env.target();
        let mut points = vec![env.ee_pose().position.into()];
        let mut reward = 0.0;
        let success = loop {
            agent.predict(env.observation(), &mut action);
            let s = env.step(&action)?;
            reward += s.total();
            points.push(env.ee_pose().position.into());
            if s.done() {
                break s.terminated;
            }
        };
        paths.push(TrajectoryPath { trial: trial + 1, points, target: [t.x, t.y, t.z], success, reward });
    }
    let reached = paths.iter().filter(|p| p.success).count();
    Ok(Rollouts {
        title: format!(
            "{} + {} ({}, seed {}): {reached} of {trials} trials reached",
            algo_title(cfg.agent.algo),
            reward_title(cfg.reward.function),
            run.name,
            run.seed()
        ),
        run: run.name.clone(),
        checkpoint: ckpt.display().to_string(),
        eval_seed,
        beta_m: cfg.reward.beta_m,
        paths,
    })
}

/// The paths as CSV: `run,trial,step,x_m,y_m,z_m,target_x_m,target_y_m,target_z_m,success`.
pub fn to_csv(sets: &[Rollouts]) -> String {
    let mut s = String::from("run,trial,step,x_m,y_m,z_m,target_x_m,target_y_m,target_z_m,success\n");
    for set in sets {
        for p in &set.paths {
            for (k, q) in p.points.iter().enumerate() {
                let _ = writeln!(
                    s,
                    "{},{},{k},{},{},{},{},{},{},{}",
                    set.run,
                    p.trial,
                    q[0],
                    q[1],
                    q[2],
                    p.target[0],
                    p.target[1],
                    p.target[2],
                    u8::from(p.success)
                );
            }
        }
    }
    s
}
