//! A run directory: every path in it, and the names of its per-trial evaluation files, built here
//! and nowhere else.
//!
//! A run directory holds:
//! - `config.toml`: the resolved configuration (seed included);
//! - `episodes.csv`: one row per episode ([`crate::log::EpisodeRecord`]);
//! - `eval.csv`: the periodic evaluations ([`crate::log::EvalPoint`]);
//! - `eval-seed<N>.csv`: per-trial evaluations of the run's best checkpoint on the targets of
//!   seed `N` ([`crate::log::TrialRecord`]), written by `stagerl train`, `stagerl eval` and
//!   `stagerl reproduce` (by `train::evaluate_run`);
//! - `tb/`: TensorBoard event files with the same scalars and the losses;
//! - `checkpoints/latest.safetensors`: everything the run needs to continue (networks, targets,
//!   optimiser moments, the replay buffer, every random state, the counters, where the logs
//!   stand), written atomically every `checkpoint_every_episodes` episodes, on a stop request
//!   (SIGINT/SIGTERM in the CLI, mid-episode if need be) and at the end;
//! - `checkpoints/final.safetensors`: the trained agent alone (no replay buffer) at the end;
//! - `checkpoints/best.safetensors`: the agent at its best periodic evaluation (success rate,
//!   then mean reward, on the `eval_seed` targets), for evaluation and deployment. Off-policy
//!   agents, DDPG above all, oscillate after converging; the best checkpoint is the usual remedy
//!   (as Stable-Baselines3's `EvalCallback`). Test it on other targets than it was chosen on.

use std::path::{Path, PathBuf};

use crate::config::Config;
use crate::{Error, Result};

/// Paths inside a run directory.
#[derive(Clone, Debug)]
pub struct RunDir {
    pub root: PathBuf,
}

/// Prefix and suffix of the per-trial evaluation files, `eval-seed<N>.csv`.
const TRIAL_EVAL: (&str, &str) = ("eval-seed", ".csv");

impl RunDir {
    pub fn new(root: &Path) -> RunDir {
        RunDir { root: root.to_path_buf() }
    }
    pub fn config(&self) -> PathBuf {
        self.root.join("config.toml")
    }
    pub fn episodes(&self) -> PathBuf {
        self.root.join("episodes.csv")
    }
    pub fn eval(&self) -> PathBuf {
        self.root.join("eval.csv")
    }
    pub fn tb(&self) -> PathBuf {
        self.root.join("tb")
    }
    pub fn checkpoints(&self) -> PathBuf {
        self.root.join("checkpoints")
    }
    pub fn latest(&self) -> PathBuf {
        self.checkpoints().join("latest.safetensors")
    }
    pub fn final_checkpoint(&self) -> PathBuf {
        self.checkpoints().join("final.safetensors")
    }
    /// The agent of the best periodic evaluation (success rate, then mean reward).
    pub fn best(&self) -> PathBuf {
        self.checkpoints().join("best.safetensors")
    }
    /// The checkpoint a run is evaluated from: best, else final, else latest.
    pub fn best_available_checkpoint(&self) -> Option<PathBuf> {
        [self.best(), self.final_checkpoint(), self.latest()].into_iter().find(|p| p.exists())
    }
    /// The per-trial evaluation on the targets of seed `seed`: `eval-seed<seed>.csv`.
    pub fn trial_eval(&self, seed: u64) -> PathBuf {
        self.root.join(format!("{}{seed}{}", TRIAL_EVAL.0, TRIAL_EVAL.1))
    }
    /// The per-trial evaluation files present, `(seed, path)` sorted by seed.
    pub fn trial_evals(&self) -> Vec<(u64, PathBuf)> {
        let mut found: Vec<(u64, PathBuf)> = std::fs::read_dir(&self.root)
            .into_iter()
            .flatten()
            .filter_map(|e| e.ok())
            .filter_map(|e| Some((trial_eval_seed(&e.file_name().to_string_lossy())?, e.path())))
            .collect();
        found.sort();
        found
    }
    /// Read the run's resolved config.
    pub fn load_config(&self) -> Result<Config> {
        Config::load(&self.config())
    }
    /// The directory holds a run (its `config.toml` exists).
    pub fn holds_run(&self) -> bool {
        self.config().exists()
    }
    /// Create the directory and check that files can be written in it, before any work goes
    /// into a run that could not be saved.
    pub fn ensure_writable(&self) -> Result<()> {
        std::fs::create_dir_all(&self.root).map_err(|e| Error::io(&self.root, e))?;
        let probe = self.root.join(format!(".write-test-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(|e| Error::io(&self.root, e))?;
        std::fs::remove_file(&probe).map_err(|e| Error::io(&probe, e))
    }
    /// A directory is a run when it holds `config.toml` and `episodes.csv`.
    pub fn is_run(&self) -> bool {
        self.config().is_file() && self.episodes().is_file()
    }
}

/// The first directory `parent/<name>`, `parent/<name>-2`, ... that does not exist (a new run
/// beside the old ones instead of over them).
pub fn first_free(parent: &Path, name: &str) -> PathBuf {
    (1..)
        .map(|k| parent.join(if k == 1 { name.to_string() } else { format!("{name}-{k}") }))
        .find(|p| !p.exists())
        .expect("some directory name is free")
}

/// The seed in a per-trial evaluation file's name, `eval-seed<N>.csv`.
fn trial_eval_seed(name: &str) -> Option<u64> {
    name.strip_prefix(TRIAL_EVAL.0)?.strip_suffix(TRIAL_EVAL.1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trial_eval_names_round_trip() {
        let d = RunDir::new(Path::new("/r"));
        assert_eq!(d.trial_eval(1_000_003), Path::new("/r/eval-seed1000003.csv"));
        assert_eq!(trial_eval_seed("eval-seed0.csv"), Some(0));
        assert_eq!(trial_eval_seed("eval-seed1000003.csv"), Some(1_000_003));
        assert_eq!(trial_eval_seed("eval-seedx.csv"), None);
        assert_eq!(trial_eval_seed("eval.csv"), None);
    }
}
