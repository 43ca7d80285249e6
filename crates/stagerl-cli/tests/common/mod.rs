//! Helpers shared by the CLI integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The `stagerl` binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_stagerl"))
}

/// A fresh, empty scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stagerl-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A run's episodes.csv without the wall-time column (the only one allowed to differ).
pub fn episodes_without_wall(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("episodes.csv"))
        .unwrap()
        .lines()
        .map(|l| l.rsplit_once(',').unwrap().0.to_string())
        .collect()
}
