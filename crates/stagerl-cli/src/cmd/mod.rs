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
}

impl RobotArgs {
    /// Load the chain.
    pub fn load(&self) -> Result<stagerl::robot::Chain> {
        stagerl::robot::Chain::load(&self.robot, self.tip.as_deref())
            .with_context(|| format!("loading robot `{}`", self.robot))
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
