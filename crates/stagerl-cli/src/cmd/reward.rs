use anyhow::Result;
use serde::Deserialize;
use stagerl::nalgebra::Vector3 as Vec3;
use stagerl::reward::{Reported, RewardFunction, RewardInput, RewardTerms};
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(
    after_help = "Example:\n  echo '{\"ee_pos\":[0.4,0.1,0.5],\"ee_quat\":[0,0,0,1],\"target\":[0.5,0.1,0.4],\"joint_vel\":[0,0,0,0,0,0]}' | stagerl reward --function sar"
)]
pub struct Args {
    /// The reward whose value goes in `reward` (overrides the config's reward.function).
    #[arg(long, value_parser = super::reward_parser())]
    function: RewardFunction,
    /// A TOML config for the constants (beta, dt, boundary, sigmas, bonus); defaults otherwise.
    #[arg(long)]
    config: Option<PathBuf>,
    /// The arm whose joints `joint_vel` lists, one value per joint (rad/s or m/s).
    #[command(flatten)]
    robot: super::RobotArgs,
}

/// The fixed-length fields are read as lists and checked here, so a wrong length is reported
/// with the field's name.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Input {
    ee_pos: Vec<f64>,
    ee_quat: Vec<f64>,
    target: Vec<f64>,
    joint_vel: Vec<f64>,
    /// Only for `reward.direction = "displacement"`: the end-effector position before the step.
    #[serde(default)]
    prev_ee_pos: Option<Vec<f64>>,
}

/// `v` as an array of `N`, or an error naming the key.
fn fixed<const N: usize>(key: &str, v: &[f64]) -> Result<[f64; N]> {
    v.try_into().map_err(|_| anyhow::anyhow!("malformed input: `{key}` has {} values, expected {N}", v.len()))
}

pub fn run(args: Args) -> Result<()> {
    let mut cfg = super::load_config(args.config.as_deref())?;
    cfg.reward.function = args.function;
    cfg.reward.pose_only("stagerl reward")?;
    let dt = cfg.task.dt_s;
    let chain = args.robot.load()?;
    let dof = chain.dof();
    let stdin = std::io::stdin().lock();
    let stdout = crate::out::stdout()?;
    crate::jsonl::process(stdin, stdout, |i: Input| {
        let input = RewardInput {
            ee_pos: Vec3::from(fixed::<3>("ee_pos", &i.ee_pos)?),
            ee_quat: fixed::<4>("ee_quat", &i.ee_quat)?,
            target: Vec3::from(fixed::<3>("target", &i.target)?),
            joint_vel: &i.joint_vel,
            prev_ee_pos: i
                .prev_ee_pos
                .as_deref()
                .map(|p| fixed::<3>("prev_ee_pos", p))
                .transpose()?
                .map(Vec3::from),
        };
        if i.joint_vel.len() != dof {
            anyhow::bail!(
                "malformed input: `joint_vel` has {} values, expected {dof} (one per joint of `{}`; see --robot)",
                i.joint_vel.len(),
                args.robot.robot
            );
        }
        if cfg.reward.direction == stagerl::reward::DirectionSource::Displacement
            && input.prev_ee_pos.is_none()
        {
            anyhow::bail!("reward.direction = \"displacement\" needs the key `prev_ee_pos`");
        }
        Ok(Reported(RewardTerms::try_compute(&cfg.reward, dt, &input)?))
    })
}
