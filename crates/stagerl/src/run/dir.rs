//! A run directory: every path in it, and the names of its per-trial evaluation files, built here
//! and nowhere else.
//!
//! A run directory holds:
//! - `config.toml`: the resolved configuration (seed included);
//! - `episodes.csv`: one row per episode ([`crate::io::csv::EpisodeRecord`]);
//! - `eval.csv`: the periodic evaluations ([`crate::io::csv::EvalPoint`]);
//! - `eval-final-seed<N>.csv` and its record `eval-final-seed<N>.json`: the closing evaluation
//!   of the run's best checkpoint on the targets of seed `N` ([`crate::io::csv::TrialRecord`]),
//!   written by `stagerl train` and `stagerl reproduce` (see `train::final_eval`);
//! - `eval-<checkpoint>-trials<T>-seed<N>.csv`: evaluations by `stagerl eval` (all through
//!   `train::eval::evaluate`); `eval-seed<N>.csv`: the per-trial evaluations of older versions,
//!   still read;
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
//! - `.stagerl.lock`: the advisory lock of the process writing the run (see `crate::run::lock`).

use crate::env::Sim;
use std::path::{Path, PathBuf};

use crate::config::Config;
use crate::{Error, Result};

/// How a `stagerl eval` differs from the run's own task; its file is named for it
/// ([`RunDir::eval_command_in`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EvalVariant {
    /// Another simulator than the run's (`--sim`).
    pub sim: Option<Sim>,
    /// The first random obstacle in the way with this probability (`--obstacles-in-path`,
    /// `train.obstacles_in_path`'s placement), where the run's evaluations draw them unbiased.
    pub obstacles_in_path: Option<f64>,
    /// The safety shield on (`--shield`) or off (`--no-shield`) where the run's config
    /// (`[task.shield]`) has it the other way.
    pub shield: Option<bool>,
}

/// Paths inside a run directory.
#[derive(Clone, Debug)]
pub struct RunDir {
    pub root: PathBuf,
}

/// The lock file's name inside a locked run or sweep directory.
pub const LOCK_FILE: &str = ".stagerl.lock";

/// Prefix and suffix of the closing evaluation's per-trial file, `eval-final-seed<N>.csv`.
const FINAL_EVAL: (&str, &str) = ("eval-final-seed", ".csv");

/// Prefix and suffix of the per-trial evaluation files of older versions, `eval-seed<N>.csv`.
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
    /// The directories a run writes files into (where a killed writer may leave temporary files).
    pub fn written_dirs(&self) -> [PathBuf; 3] {
        [self.root.clone(), self.checkpoints(), self.tb()]
    }
    /// The lock file of the process writing the run.
    pub fn lock_file(&self) -> PathBuf {
        self.root.join(LOCK_FILE)
    }
    /// The closing evaluation's per-trial CSV on the targets of `seed`: `eval-final-seed<N>.csv`.
    pub fn final_eval(&self, seed: u64) -> PathBuf {
        self.root.join(format!("{}{seed}{}", FINAL_EVAL.0, FINAL_EVAL.1))
    }
    /// The closing evaluation of the final checkpoint (the paper's protocol: the trained model),
    /// beside the selected checkpoint's: `eval-final-seed<N>-final-checkpoint.csv`.
    pub fn final_checkpoint_eval(&self, seed: u64) -> PathBuf {
        self.root.join(format!("{}{seed}-final-checkpoint{}", FINAL_EVAL.0, FINAL_EVAL.1))
    }
    /// The record of the closing evaluation on the targets of `seed` (its settings, written
    /// last): `eval-final-seed<N>.json`.
    pub fn final_eval_record(&self, seed: u64) -> PathBuf {
        self.root.join(format!("{}{seed}.json", FINAL_EVAL.0))
    }
    /// The file `stagerl eval` writes: named by the checkpoint (its file stem), the trial count
    /// and the seed, `eval-<checkpoint>-trials<T>-seed<N>.csv`, so that evaluations of other
    /// settings sit side by side and none replaces the closing evaluation a report reads.
    pub fn eval_command(&self, checkpoint: &Path, trials: u32, seed: u64) -> PathBuf {
        self.eval_command_in(checkpoint, trials, seed, EvalVariant::default())
    }
    /// [`RunDir::eval_command`] on another task than the run's ([`EvalVariant`]):
    /// `eval-<checkpoint>-trials<T>-seed<S>[-sim-<sim>][-in-path-<p>][-shield|-no-shield].csv`,
    /// which no report takes
    /// for the run's own evaluation.
    pub fn eval_command_in(
        &self,
        checkpoint: &Path,
        trials: u32,
        seed: u64,
        variant: EvalVariant,
    ) -> PathBuf {
        let stem = checkpoint.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let sim = variant.sim.map(|s| format!("-sim-{}", s.name())).unwrap_or_default();
        let in_path = variant.obstacles_in_path.map(|p| format!("-in-path-{p}")).unwrap_or_default();
        let shield = match variant.shield {
            Some(true) => "-shield",
            Some(false) => "-no-shield",
            None => "",
        };
        self.root.join(format!("eval-{stem}-trials{trials}-seed{seed}{sim}{in_path}{shield}.csv"))
    }
    /// The per-trial evaluation on the targets of seed `seed` of older versions: `eval-seed<seed>.csv`.
    pub fn trial_eval(&self, seed: u64) -> PathBuf {
        self.root.join(format!("{}{seed}{}", TRIAL_EVAL.0, TRIAL_EVAL.1))
    }
    /// The per-trial evaluation files present, `(seed, path)`: the closing evaluations
    /// (`eval-final-seed<N>.csv`) first, then `eval-seed<N>.csv` (older versions), then the files
    /// of `stagerl eval`, each sorted by seed.
    pub fn trial_evals(&self) -> Vec<(u64, PathBuf)> {
        let mut found: Vec<(u8, u64, PathBuf)> = std::fs::read_dir(&self.root)
            .into_iter()
            .flatten()
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let (kind, seed) = trial_eval_kind(&e.file_name().to_string_lossy())?;
                Some((kind, seed, e.path()))
            })
            .collect();
        found.sort();
        found.into_iter().map(|(_, seed, p)| (seed, p)).collect()
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

/// `path` resolved as the file system will resolve it: canonical (symbolic links followed, `..`
/// and `.` removed) when it exists; else its parent's canonical path joined with its name (a
/// dangling symbolic link: its target, resolved the same way, up to 40 links).
pub fn resolve_path(path: &Path) -> PathBuf {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        if let Ok(c) = std::fs::canonicalize(&p) {
            return c;
        }
        match std::fs::read_link(&p) {
            Ok(target) => {
                p = match p.parent() {
                    Some(dir) => dir.join(target),
                    None => target,
                };
            }
            Err(_) => break,
        }
    }
    let (Some(name), parent) = (p.file_name(), p.parent()) else { return p };
    let parent = match parent.filter(|d| !d.as_os_str().is_empty()) {
        Some(d) => std::fs::canonicalize(d).unwrap_or_else(|_| d.to_path_buf()),
        None => std::fs::canonicalize(".").unwrap_or_default(),
    };
    parent.join(name)
}

/// Whether `name`, a file in a run's directory, is one the run's own writer (training, its
/// evaluations) writes: `config.toml`, the metrics (`episodes.csv`, `eval.csv`), the evaluations
/// (`eval-*.csv`, `eval-*.json`), the provenance record or the lock.
fn is_run_file_name(name: &str) -> bool {
    matches!(name, "config.toml" | "episodes.csv" | "eval.csv" | LOCK_FILE | crate::run::provenance::FILE)
        || (name.starts_with("eval-") && (name.ends_with(".csv") || name.ends_with(".json")))
}

/// An error if writing the output `out` would replace a file of a run that only the run's own
/// writer may write, whatever `--force` says: its config, its metrics, its evaluations, anything
/// in its `checkpoints/` or `tb/`; or one of `inputs` (the checkpoint a command reads). Paths are
/// compared resolved ([`resolve_path`]): a symbolic link or `..` does not get round it. And an
/// error if `out` is not a regular file ([`crate::io::check_output_kind`]). `flag` names the
/// output in the message (`--out`).
pub fn check_output_path(out: &Path, flag: &str, inputs: &[&Path]) -> Result<()> {
    crate::io::check_output_kind(out).map_err(|e| match e {
        Error::InvalidInput(m) => Error::InvalidInput(format!("{flag} {m}")),
        other => other,
    })?;
    let resolved = resolve_path(out);
    for input in inputs {
        if resolve_path(input) == resolved {
            return Err(Error::InvalidInput(format!(
                "{flag} {}: is the file this command reads ({}); write the output elsewhere",
                out.display(),
                input.display()
            )));
        }
    }
    let refuse = |what: &str, run: &Path| {
        Err(Error::InvalidInput(format!(
            "{flag} {}: is {what} of the run in {} (only the run's training writes it; --force does \
             not change that); write the output elsewhere",
            out.display(),
            run.display()
        )))
    };
    let Some(dir) = resolved.parent() else { return Ok(()) };
    let name = resolved.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    if RunDir::new(dir).holds_run() && is_run_file_name(&name) {
        return refuse(&format!("`{name}`, a file"), dir);
    }
    if let (Some(sub), Some(root)) = (dir.file_name(), dir.parent()) {
        if (sub == "checkpoints" || sub == "tb") && RunDir::new(root).holds_run() {
            return refuse(&format!("in `{}/`, a directory", sub.to_string_lossy()), root);
        }
    }
    Ok(())
}

/// The first directory `parent/<name>`, `parent/<name>-2`, ... that does not exist (a new run
/// beside the old ones instead of over them).
pub fn first_free(parent: &Path, name: &str) -> PathBuf {
    (1..)
        .map(|k| parent.join(if k == 1 { name.to_string() } else { format!("{name}-{k}") }))
        .find(|p| !p.exists())
        .expect("some directory name is free")
}

/// The seed in a file name `<prefix><N><suffix>`.
fn seed_of(name: &str, (prefix, suffix): (&str, &str)) -> Option<u64> {
    name.strip_prefix(prefix)?.strip_suffix(suffix)?.parse().ok()
}

/// The seed of a file of `stagerl eval`, `eval-<checkpoint>-trials<T>-seed<N>.csv`.
fn eval_command_seed(name: &str) -> Option<u64> {
    let (head, seed) = name.strip_prefix("eval-")?.strip_suffix(".csv")?.rsplit_once("-seed")?;
    let (_, trials) = head.rsplit_once("-trials")?;
    trials.parse::<u32>().ok()?;
    seed.parse().ok()
}

/// The kind (0: closing evaluation, 1: older `eval-seed<N>.csv`, 2: `stagerl eval`) and seed of a
/// per-trial evaluation file's name.
fn trial_eval_kind(name: &str) -> Option<(u8, u64)> {
    if let Some(s) = seed_of(name, FINAL_EVAL) {
        Some((0, s))
    } else if let Some(s) = seed_of(name, TRIAL_EVAL) {
        Some((1, s))
    } else {
        eval_command_seed(name).map(|s| (2, s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trial_eval_names_round_trip() {
        let d = RunDir::new(Path::new("/r"));
        let dynamic = EvalVariant { sim: Some(Sim::Dynamic), obstacles_in_path: None, shield: None };
        let other = d.eval_command_in(Path::new("c/best.safetensors"), 50, 3, dynamic);
        assert_eq!(other, Path::new("/r/eval-best-trials50-seed3-sim-dynamic.csv"));
        assert_eq!(trial_eval_kind("eval-best-trials50-seed3-sim-dynamic.csv"), None, "not the run's own");
        let both = EvalVariant { obstacles_in_path: Some(0.5), ..dynamic };
        let in_path = d.eval_command_in(Path::new("c/best.safetensors"), 50, 3, both);
        assert_eq!(in_path, Path::new("/r/eval-best-trials50-seed3-sim-dynamic-in-path-0.5.csv"));
        assert_eq!(trial_eval_kind("eval-best-trials50-seed3-in-path-1.csv"), None, "not the run's own");
        let unshielded = EvalVariant { obstacles_in_path: Some(1.0), shield: Some(false), sim: None };
        let off = d.eval_command_in(Path::new("c/best.safetensors"), 50, 3, unshielded);
        assert_eq!(off, Path::new("/r/eval-best-trials50-seed3-in-path-1-no-shield.csv"));
        assert_eq!(trial_eval_kind("eval-best-trials50-seed3-no-shield.csv"), None, "not the run's own");
        assert_eq!(trial_eval_kind("eval-best-trials50-seed3.csv"), Some((2, 3)));
        assert_eq!(d.trial_eval(1_000_003), Path::new("/r/eval-seed1000003.csv"));
        assert_eq!(d.final_eval(7), Path::new("/r/eval-final-seed7.csv"));
        assert_eq!(d.final_eval_record(7), Path::new("/r/eval-final-seed7.json"));
        assert_eq!(d.final_checkpoint_eval(7), Path::new("/r/eval-final-seed7-final-checkpoint.csv"));
        assert_eq!(
            trial_eval_kind("eval-final-seed7-final-checkpoint.csv"),
            None,
            "not a main evaluation file"
        );
        let best = d.best();
        assert_eq!(d.eval_command(&best, 5, 3), Path::new("/r/eval-best-trials5-seed3.csv"));
        assert_eq!(trial_eval_kind("eval-final-seed1000003.csv"), Some((0, 1_000_003)));
        assert_eq!(trial_eval_kind("eval-seed0.csv"), Some((1, 0)));
        assert_eq!(trial_eval_kind("eval-seed1000003.csv"), Some((1, 1_000_003)));
        assert_eq!(trial_eval_kind("eval-seedx.csv"), None);
        assert_eq!(trial_eval_kind("eval.csv"), None);
        assert_eq!(trial_eval_kind("eval-best-trials500-seed7.csv"), Some((2, 7)));
        assert_eq!(trial_eval_kind("eval-my-ck-trials5-seed0.csv"), Some((2, 0)));
        assert_eq!(trial_eval_kind("eval-best-seed7.csv"), None);
        assert_eq!(trial_eval_kind("eval-final-seed7.json"), None);
    }
}
