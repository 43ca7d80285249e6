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

/// Every scalar of a run's TensorBoard event files (`tb/`), as `(tag, step, value)`, files in
/// name order.
pub fn tb_scalars(dir: &Path) -> Vec<(String, i64, f32)> {
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(dir.join("tb")).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    files.iter().flat_map(|f| stagerl::log::tensorboard::read_scalars(f).unwrap()).collect()
}

/// Panics unless every tag of `scalars` has the steps `1..=n` exactly once each (`eval/` tags:
/// the multiples of `eval_every` and `n`).
pub fn assert_steps_once(scalars: &[(String, i64, f32)], n: i64, eval_every: i64, what: &str) {
    let mut by_tag: std::collections::BTreeMap<&str, Vec<i64>> = Default::default();
    for (tag, step, _) in scalars {
        by_tag.entry(tag.as_str()).or_default().push(*step);
    }
    assert!(by_tag.contains_key("train/episode_reward"), "{what}: no train/episode_reward");
    for (tag, mut steps) in by_tag {
        steps.sort_unstable();
        let expect: Vec<i64> = if tag.starts_with("eval/") {
            (1..=n).filter(|s| s % eval_every == 0 || *s == n).collect()
        } else if tag.starts_with("train/") {
            (1..=n).collect()
        } else {
            // Losses start with learning: a contiguous range ending at n.
            let first = *steps.first().unwrap();
            (first..=n).collect()
        };
        assert_eq!(steps, expect, "{what}: steps of {tag}");
    }
}
