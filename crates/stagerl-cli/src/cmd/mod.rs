pub mod bench;
pub mod config;
pub mod demo;
pub mod eval;
pub mod export;
pub mod fk;
pub mod plan;
pub mod report;
pub mod reproduce;
pub mod reward;
pub mod robot;
pub mod train;
pub mod view;

use anyhow::{Context, Result};
use stagerl::config::Config;
use std::path::Path;

/// The arm of `fk` and `reward`: `--robot` and `--tip`.
#[derive(clap::Args)]
pub struct RobotArgs {
    /// `ur5` or `panda` for a bundled arm (6 and 7 joints), or a path to a URDF file.
    #[arg(long, default_value = "ur5")]
    pub robot: String,
    /// Tip link of the URDF (default: its only leaf link).
    #[arg(long)]
    pub tip: Option<String>,
    /// A folder holding ROS package folders, where `package://` mesh paths are looked for
    /// before `ROS_PACKAGE_PATH` and the URDF's folder (repeatable); mesh files are read only
    /// below these folders and the URDF's.
    #[arg(long = "package-path", value_name = "DIR")]
    pub package_paths: Vec<std::path::PathBuf>,
}

impl RobotArgs {
    /// Load the chain (collision meshes too: one that cannot be read is an error).
    pub fn load(&self) -> Result<stagerl::robot::Chain> {
        let meshes =
            stagerl::robot::MeshOptions { package_paths: self.package_paths.clone(), ..Default::default() }
                .with_ros_package_path();
        stagerl::robot::Chain::load_with(&self.robot, self.tip.as_deref(), &meshes)
            .with_context(|| format!("loading robot `{}`", self.robot))
    }
}

/// What a run on `chain` should be told about its collision geometry before it starts: no
/// collision shape at all (contacts are then not checked: no rate of collisions means
/// anything), or meshes left out by `robot.missing_collision = "ignore"`; `None` otherwise.
pub fn collision_notice(chain: &stagerl::robot::Chain) -> Option<String> {
    let unloaded = chain.unloaded_collision();
    let left_out = unloaded
        .iter()
        .map(|u| format!("link `{}`: `{}` ({})", u.link, u.file, u.reason))
        .collect::<Vec<_>>()
        .join("; ");
    if chain.collision_shapes().is_empty() {
        let why =
            if unloaded.is_empty() { String::new() } else { format!(" (meshes not loaded: {left_out})") };
        Some(format!(
            "warning: no link of `{}` to `{}` has a collision shape{why}: contacts with the floor,              the arm itself and obstacles are NOT checked, and collision rates are not measured",
            chain.base_link(),
            chain.tip_link()
        ))
    } else if !unloaded.is_empty() {
        Some(format!("warning: collision meshes left out (robot.missing_collision = \"ignore\"): {left_out}"))
    } else {
        None
    }
}

/// The trained run a command reads: `--run` and `--checkpoint`.
#[derive(clap::Args)]
pub struct RunArgs {
    /// The run directory (holds config.toml and checkpoints/).
    #[arg(long)]
    pub run: std::path::PathBuf,
    /// Checkpoint to use (default: the run's best, else final, else latest).
    #[arg(long)]
    pub checkpoint: Option<std::path::PathBuf>,
}

/// The `--algo` parser: `--help` lists the algorithms.
pub fn algo_parser() -> impl clap::builder::TypedValueParser<Value = stagerl::agent::Algo> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(stagerl::agent::Algo::ALL.map(|a| a.name()))
        .try_map(|s| s.parse::<stagerl::agent::Algo>())
}

/// The reward-function parser: `--help` lists the five functions.
pub fn reward_parser() -> impl clap::builder::TypedValueParser<Value = stagerl::reward::RewardFunction> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(stagerl::reward::RewardFunction::ALL.map(|r| r.name()))
        .try_map(|s| s.parse::<stagerl::reward::RewardFunction>())
}

/// The config in `path`, or the defaults.
pub fn load_config(path: Option<&Path>) -> Result<Config> {
    match path {
        Some(p) => Config::load(p).with_context(|| format!("loading config {}", p.display())),
        None => Ok(Config::default()),
    }
}
