pub mod bench;
pub mod demo;
pub mod eval;
pub mod fk;
pub mod plan;
pub mod report;
pub mod reproduce;
pub mod reward;
pub mod train;

use anyhow::{Context, Result};
use stagerl::config::Config;
use std::path::Path;

/// The config in `path`, or the defaults.
pub fn load_config(path: Option<&Path>) -> Result<Config> {
    match path {
        Some(p) => Config::load(p).with_context(|| format!("loading config {}", p.display())),
        None => Ok(Config::default()),
    }
}
