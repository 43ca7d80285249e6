//! Finding run directories and reading what a run wrote: `config.toml`, `episodes.csv`,
//! `eval.csv` and the per-trial evaluation CSV (`eval-final-seed<N>.csv`, else `eval-seed<N>.csv`,
//! else one of `stagerl eval`).

use std::path::{Path, PathBuf};

use crate::config::Config;
use crate::log::csv::read_episodes;
use crate::log::EpisodeRecord;
use crate::train::{RunDir, TrialRecord};
use crate::{Error, Result};

pub use crate::train::eval::{read_trials_csv, TRIALS_HEADER};
pub use crate::train::EVAL_HEADER;

/// One periodic evaluation (a row of `eval.csv`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct EvalPoint {
    pub episode: u64,
    pub env_steps: u64,
    /// In [0, 1].
    pub success_rate: f64,
    pub mean_reward: f64,
    /// Mean steps of the successful trials; `None` when none succeeded.
    pub mean_steps: Option<f64>,
    pub median_final_distance_m: f64,
}

/// The per-trial evaluation a run holds.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalEval {
    pub path: PathBuf,
    /// The evaluation seed, from the file name.
    pub seed: Option<u64>,
    pub trials: Vec<TrialRecord>,
}

/// Everything the report reads from one run directory.
#[derive(Clone, Debug)]
pub struct RunData {
    pub dir: PathBuf,
    /// Path relative to the report's input directory.
    pub name: String,
    pub config: Config,
    /// Empty when `episodes.csv` could not be read (see `notes`).
    pub episodes: Vec<EpisodeRecord>,
    /// Empty when there is no `eval.csv`.
    pub eval_points: Vec<EvalPoint>,
    pub final_eval: Option<FinalEval>,
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
    dir.join("config.toml").is_file() && dir.join("episodes.csv").is_file()
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

fn parse_opt_f64(s: &str) -> std::result::Result<Option<f64>, std::num::ParseFloatError> {
    if s.is_empty() {
        Ok(None)
    } else {
        s.parse().map(Some)
    }
}

/// Read a run's `eval.csv`.
pub fn read_eval_points(path: &Path) -> Result<Vec<EvalPoint>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut lines = text.lines();
    if lines.next().map(str::trim_end) != Some(EVAL_HEADER) {
        return Err(Error::InvalidInput(format!("{}: expected the header {EVAL_HEADER:?}", path.display())));
    }
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let bad = || Error::InvalidInput(format!("{}: malformed row {line:?}", path.display()));
            let f: Vec<&str> = line.trim_end().split(',').collect();
            if f.len() != 6 {
                return Err(bad());
            }
            Ok(EvalPoint {
                episode: f[0].parse().map_err(|_| bad())?,
                env_steps: f[1].parse().map_err(|_| bad())?,
                success_rate: f[2].parse().map_err(|_| bad())?,
                mean_reward: f[3].parse().map_err(|_| bad())?,
                mean_steps: parse_opt_f64(f[4]).map_err(|_| bad())?,
                median_final_distance_m: f[5].parse().map_err(|_| bad())?,
            })
        })
        .collect()
}

/// The seed in a name `<prefix><N>.csv`.
fn seed_of(name: &str, prefix: &str) -> Option<u64> {
    name.strip_prefix(prefix)?.strip_suffix(".csv")?.parse().ok()
}

/// The seed of a file of `stagerl eval`, `eval-<checkpoint>-trials<T>-seed<N>.csv`.
fn eval_command_seed(name: &str) -> Option<u64> {
    let (head, seed) = name.strip_prefix("eval-")?.strip_suffix(".csv")?.rsplit_once("-seed")?;
    let (_, trials) = head.rsplit_once("-trials")?;
    trials.parse::<u32>().ok()?;
    seed.parse().ok()
}

/// The per-trial evaluation files of a run: the closing evaluation `eval-final-seed<N>.csv`
/// first, then `eval-seed<N>.csv` (older versions), then the files of `stagerl eval`
/// (`eval-<checkpoint>-trials<T>-seed<N>.csv`), each sorted by seed.
pub fn trial_files(dir: &Path) -> Vec<(PathBuf, Option<u64>)> {
    let mut found: Vec<(u8, u64, PathBuf)> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(s) = seed_of(&name, "eval-final-seed") {
                Some((0, s, e.path()))
            } else if let Some(s) = seed_of(&name, "eval-seed") {
                Some((1, s, e.path()))
            } else {
                eval_command_seed(&name).map(|s| (2, s, e.path()))
            }
        })
        .collect();
    found.sort();
    found.into_iter().map(|(_, s, p)| (p, Some(s))).collect()
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
    for (path, seed) in trial_files(dir) {
        match read_trials_csv(&path) {
            Ok(trials) if !trials.is_empty() => {
                final_eval = Some(FinalEval { path, seed, trials });
                break;
            }
            Ok(_) => notes.push(format!("{} holds no trials", path.display())),
            Err(e) => notes.push(format!("not read: {e}")),
        }
    }
    let complete = episodes.len() as u64 >= config.train.episodes
        && episodes.last().is_some_and(|r| r.episode >= config.train.episodes);
    Ok(RunData { dir: dir.to_path_buf(), name, config, episodes, eval_points, final_eval, complete, notes })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_from_file_names() {
        assert_eq!(seed_of("eval-final-seed1000003.csv", "eval-final-seed"), Some(1_000_003));
        assert_eq!(seed_of("eval-seed0.csv", "eval-seed"), Some(0));
        assert_eq!(seed_of("eval-seedx.csv", "eval-seed"), None);
        assert_eq!(seed_of("eval.csv", "eval-seed"), None);
        assert_eq!(eval_command_seed("eval-best-trials500-seed7.csv"), Some(7));
        assert_eq!(eval_command_seed("eval-my-ck-trials5-seed0.csv"), Some(0));
        assert_eq!(eval_command_seed("eval-best-seed7.csv"), None);
        assert_eq!(eval_command_seed("eval-final-seed7.csv"), None);
    }
}
