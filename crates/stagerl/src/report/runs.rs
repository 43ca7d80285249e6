//! Finding run directories and reading what a run wrote: `config.toml`, `episodes.csv`,
//! `eval.csv` and the per-trial evaluation CSV (`eval-final-seed<N>.csv`, else `eval-seed<N>.csv`,
//! else one of `stagerl eval`; the readers are beside their writers in [`crate::io::csv`], the
//! file names in [`crate::run::dir`]).

use std::path::{Path, PathBuf};

use crate::config::Config;
use crate::io::csv::{read_episodes, read_eval_points, read_trials_csv};
use crate::io::csv::{EpisodeRecord, TrialRecord};
use crate::run::dir::RunDir;
use crate::{Error, Result};

use crate::io::csv::EvalPoint;

/// The per-trial evaluation a run holds.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalEval {
    pub path: PathBuf,
    /// The evaluation seed, from the file name.
    pub seed: u64,
    pub trials: Vec<TrialRecord>,
}

/// Everything the report reads from one run directory.
#[derive(Clone, Debug)]
pub struct RunData {
    pub dir: PathBuf,
    /// Path relative to the report's input directory.
    pub name: String,
    pub config: Config,
    /// The regime its sweep's preset names ([`super::reference::Regime::of_run`]).
    pub regime: super::reference::Regime,
    /// Empty when `episodes.csv` could not be read (see `notes`).
    pub episodes: Vec<EpisodeRecord>,
    /// Empty when there is no `eval.csv`.
    pub eval_points: Vec<EvalPoint>,
    pub final_eval: Option<FinalEval>,
    /// The final checkpoint's closing evaluation on the same targets, when the run has one.
    pub final_checkpoint_eval: Option<FinalEval>,
    /// All configured episodes are in `episodes.csv`.
    pub complete: bool,
    /// Problems met while reading, for the report.
    pub notes: Vec<String>,
}

impl RunData {
    pub fn seed(&self) -> u64 {
        self.config.train.seed
    }
}

/// A directory that looked like a run but could not be read.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SkippedRun {
    pub name: String,
    pub reason: String,
}

/// A directory is a run when it holds `config.toml` and `episodes.csv`.
pub fn is_run_dir(dir: &Path) -> bool {
    RunDir::new(dir).is_run()
}

fn sorted_subdirs(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    out.sort();
    Ok(out)
}

/// Run directories in `root`: `root` itself if it is one, else its children and grandchildren
/// that are (a run's own subdirectories are not searched), sorted by path.
pub fn discover(root: &Path) -> Result<Vec<PathBuf>> {
    if !root.is_dir() {
        return Err(Error::InvalidInput(format!("{}: not a directory", root.display())));
    }
    if is_run_dir(root) {
        return Ok(vec![root.to_path_buf()]);
    }
    let mut runs = Vec::new();
    for child in sorted_subdirs(root)? {
        if is_run_dir(&child) {
            runs.push(child);
        } else if let Ok(grandchildren) = sorted_subdirs(&child) {
            runs.extend(grandchildren.into_iter().filter(|g| is_run_dir(g)));
        }
    }
    Ok(runs)
}

/// Read one run. A missing or malformed `episodes.csv`, `eval.csv` or trial CSV becomes a note;
/// an unreadable `config.toml` is an error (the run cannot be grouped).
pub fn load_run(dir: &Path, root: &Path) -> Result<RunData> {
    let rd = RunDir::new(dir);
    let name = dir.strip_prefix(root).ok().filter(|p| !p.as_os_str().is_empty()).unwrap_or(dir);
    let name = name.display().to_string();
    let config = rd.load_config()?;
    let mut notes = Vec::new();
    let episodes = read_episodes(&rd.episodes()).unwrap_or_else(|e| {
        notes.push(format!("episodes.csv not read: {e}"));
        Vec::new()
    });
    let eval_points = if rd.eval().exists() {
        read_eval_points(&rd.eval()).unwrap_or_else(|e| {
            notes.push(format!("eval.csv not read: {e}"));
            Vec::new()
        })
    } else {
        Vec::new()
    };
    let mut final_eval = None;
    for (seed, path) in rd.trial_evals() {
        match read_trials_csv(&path) {
            Ok(trials) if !trials.is_empty() => {
                final_eval = Some(FinalEval { path, seed, trials });
                break;
            }
            Ok(_) => notes.push(format!("{} holds no trials", path.display())),
            Err(e) => notes.push(format!("not read: {e}")),
        }
    }
    let final_checkpoint_eval = final_eval.as_ref().and_then(|f| {
        let path = rd.final_checkpoint_eval(f.seed);
        let trials = read_trials_csv(&path).ok().filter(|t| !t.is_empty())?;
        Some(FinalEval { path, seed: f.seed, trials })
    });
    // The budget's last episode is in `episodes.csv` (and, under an episode budget, every one).
    let complete = episodes.last().is_some_and(|r| config.train.is_last(r.episode, r.env_steps))
        && (config.train.env_steps.is_some() || episodes.len() as u64 >= config.train.episodes);
    Ok(RunData {
        regime: super::reference::Regime::of_run(dir, root),
        dir: dir.to_path_buf(),
        name,
        config,
        episodes,
        eval_points,
        final_eval,
        final_checkpoint_eval,
        complete,
        notes,
    })
}
