//! Sweeps: the paper's protocol of algorithms x reward functions x seeds, each run trained and
//! then evaluated on random targets, resumable and shardable across machines.
//!
//! A preset is a TOML file with a `[sweep]` section and, beside it, any sections of an ordinary
//! [`Config`] that every run shares:
//!
//! ```toml
//! [sweep]
//! algorithms = ["ddpg", "sac"]
//! rewards = ["basic", "posture", "stride", "har", "sar"]
//! seeds = [1, 2, 3]
//! eval_trials = 500
//!
//! [train]
//! episodes = 10000
//! ```
//!
//! Run `i` of the sweep (algorithm-major, then reward, then seed) lives in
//! `OUT/<algo>-<reward>-seed<seed>/`, a normal run directory; its evaluation is
//! `eval-final-seed<eval_seed>.csv` there, recorded with its settings (see
//! [`train::final_eval`]). A run is finished when its checkpoint says so and its evaluation is
//! recorded with the sweep's settings (else only the evaluation runs again); a run with a
//! checkpoint is resumed; any other starts from scratch. Several processes can share one sweep
//! directory: each run is locked by the process working on it, and skipped by the others.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use crate::agent::Algo;
use crate::config::Config;
use crate::reward::RewardFunction;
use crate::train::{self, final_eval, EvalSummary, Progress, RunDir, TrainOptions};
use crate::{Error, Result};

/// The `[sweep]` section of a preset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    pub algorithms: Vec<Algo>,
    pub rewards: Vec<RewardFunction>,
    pub seeds: Vec<u64>,
    /// Evaluation trials of each trained run (paper: 500).
    #[serde(default = "default_trials")]
    pub eval_trials: u32,
    /// Seed of the evaluation targets (not `train.eval_seed`, which picks the best checkpoint).
    #[serde(default)]
    pub eval_seed: u64,
}

fn default_trials() -> u32 {
    500
}

/// A parsed preset: the sweep and the config every run starts from.
#[derive(Clone, Debug, PartialEq)]
pub struct Preset {
    pub sweep: SweepSpec,
    pub base: Config,
}

/// One run of a sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// Position in the sweep (for sharding).
    pub index: usize,
    pub name: String,
    pub config: Config,
}

/// Where a run stands on disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunStatus {
    /// Trained and evaluated.
    Done,
    /// Trained, not yet evaluated (or killed during its evaluation).
    Trained,
    /// Trained and evaluated with other settings (trials, seed, checkpoint, config) than the
    /// sweep's: only the evaluation runs again.
    StaleEval,
    /// Has a checkpoint to continue from.
    Partial { episode: u64 },
    /// Nothing usable yet.
    New,
}

impl Preset {
    /// Parse a preset; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Preset> {
        let bad = |m: String| Error::ConfigParse { path: origin.to_path_buf(), message: m };
        let mut table: toml::Table = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
        let sweep = table.remove("sweep").ok_or_else(|| bad("no [sweep] section".into()))?;
        let sweep: SweepSpec = sweep.try_into().map_err(|e: toml::de::Error| bad(format!("[sweep]: {e}")))?;
        let rest = toml::to_string(&table).map_err(|e| bad(e.to_string()))?;
        let base = Config::from_toml_str(&rest, origin)?;
        let preset = Preset { sweep, base };
        preset.validate()?;
        Ok(preset)
    }

    /// Read a preset file.
    pub fn load(path: &Path) -> Result<Preset> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Preset::from_toml_str(&text, path)
    }

    fn validate(&self) -> Result<()> {
        let s = &self.sweep;
        for (field, n) in [
            ("sweep.algorithms", s.algorithms.len()),
            ("sweep.rewards", s.rewards.len()),
            ("sweep.seeds", s.seeds.len()),
        ] {
            if n == 0 {
                return Err(Error::config(field, "[]", "at least one entry"));
            }
        }
        let mut seeds = s.seeds.clone();
        seeds.sort_unstable();
        if seeds.windows(2).any(|w| w[0] == w[1]) {
            return Err(Error::config("sweep.seeds", format!("{:?}", s.seeds), "distinct seeds"));
        }
        if s.eval_trials == 0 {
            return Err(Error::config("sweep.eval_trials", 0, "an integer >= 1"));
        }
        Ok(())
    }

    /// Every run of the sweep, in order.
    pub fn runs(&self) -> Vec<RunSpec> {
        let mut out = Vec::new();
        for &algo in &self.sweep.algorithms {
            for &reward in &self.sweep.rewards {
                for &seed in &self.sweep.seeds {
                    let mut config = self.base.clone();
                    config.agent.algo = algo;
                    config.reward.function = reward;
                    config.train.seed = seed;
                    out.push(RunSpec {
                        index: out.len(),
                        name: format!("{algo}-{reward}-seed{seed}"),
                        config,
                    });
                }
            }
        }
        out
    }
}

/// The runs of shard `index` of `count`: those whose sweep position is congruent to `index`.
pub fn shard(runs: Vec<RunSpec>, index: usize, count: usize) -> Result<Vec<RunSpec>> {
    if count == 0 || index >= count {
        return Err(Error::InvalidInput(format!(
            "task index {index} of {count} tasks: need count >= 1 and 0 <= index < count"
        )));
    }
    Ok(runs.into_iter().filter(|r| r.index % count == index).collect())
}

/// The evaluation file of a run (its closing evaluation, see [`train::final_eval`]).
pub fn eval_csv(dir: &Path, eval_seed: u64) -> PathBuf {
    final_eval::csv_path(dir, eval_seed)
}

/// Where the run `dir` of `spec` stands in `sweep`: done only when its closing evaluation is
/// recorded with the sweep's evaluation settings.
pub fn status(dir: &Path, spec: &RunSpec, sweep: &SweepSpec) -> Result<RunStatus> {
    let (trials, seed) = (sweep.eval_trials, sweep.eval_seed);
    Ok(match train::checkpointed_episode(dir)? {
        Some((_, true)) if final_eval::is_current(dir, &spec.config, trials, seed) => RunStatus::Done,
        Some((_, true)) if final_eval::recorded(dir, seed).is_some() => RunStatus::StaleEval,
        Some((_, true)) => RunStatus::Trained,
        Some((episode, false)) => RunStatus::Partial { episode },
        None => RunStatus::New,
    })
}

/// Train (or resume) and evaluate one run into `out/<name>`, holding the run directory's lock
/// ([`Error::Locked`] when another process holds it). A finished run is not repeated; a run
/// whose config.toml differs from the preset's is refused rather than mixed. Returns where the
/// run stood before and its evaluation.
pub fn run_one(
    spec: &RunSpec,
    out: &Path,
    sweep: &SweepSpec,
    opts: &TrainOptions<'_>,
    on_episode: &mut dyn FnMut(&Progress<'_>),
) -> Result<(RunStatus, EvalSummary)> {
    let dir = out.join(&spec.name);
    check_existing(spec, out)?;
    // [runsafe] One process per run: another process's run is skipped (`Error::Locked`). The
    // status is read under the lock, so a run another process finished is not trained again.
    let _lock = crate::lock::DirLock::run(&dir)?;
    check_existing(spec, out)?;
    let before = status(&dir, spec, sweep)?;
    match before {
        RunStatus::Done => return Ok((before, read_eval(&dir, sweep.eval_seed)?)),
        RunStatus::Trained | RunStatus::StaleEval => {}
        RunStatus::Partial { .. } => {
            train::resume(&dir, opts, on_episode)?;
        }
        RunStatus::New => {
            train::train_with(&spec.config, &dir, opts, on_episode)?;
        }
    }
    let (summary, _) = final_eval::run(&dir, &spec.config, sweep.eval_trials, sweep.eval_seed, opts.stop)?;
    Ok((before, summary))
}

/// Refuse a run directory that holds a run of another configuration than `spec`'s.
pub fn check_existing(spec: &RunSpec, out: &Path) -> Result<()> {
    let dir = out.join(&spec.name);
    let run = RunDir::new(&dir);
    if run.config().exists() && run.load_config()? != spec.config {
        return Err(Error::InvalidInput(format!(
            "{} holds a run of another configuration than this sweep's; move it away or use another output directory",
            dir.display()
        )));
    }
    Ok(())
}

/// [`check_existing`] for every run, before anything is written: all refusals in one error.
pub fn check_all_existing(runs: &[RunSpec], out: &Path) -> Result<()> {
    let refused: Vec<String> =
        runs.iter().filter_map(|r| check_existing(r, out).err()).map(|e| e.to_string()).collect();
    if refused.is_empty() {
        Ok(())
    } else {
        Err(Error::InvalidInput(format!("nothing was written:\n  {}", refused.join("\n  "))))
    }
}

/// Write the sweep's `preset.toml` (atomically, under the sweep directory's lock) unless it
/// already holds `text`: several processes sharing the sweep write it once.
pub fn write_preset(out: &Path, text: &str) -> Result<()> {
    let _lock = crate::lock::DirLock::sweep(out)?;
    let path = out.join("preset.toml");
    if std::fs::read(&path).is_ok_and(|old| old == text.as_bytes()) {
        return Ok(());
    }
    crate::io::write_atomic(&path, text.as_bytes())
}

/// Summarise an existing evaluation file.
pub fn read_eval(dir: &Path, eval_seed: u64) -> Result<EvalSummary> {
    final_eval::read(dir, eval_seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PRESET: &str =
        "[sweep]\nalgorithms = [\"ddpg\", \"sac\"]\nrewards = [\"posture\", \"sar\"]\nseeds = [1, 2, 3]\n\
                          eval_trials = 20\n[train]\nepisodes = 7\n";

    #[test]
    fn preset_expands_in_order_and_shards_cover_every_run_once() {
        let p = Preset::from_toml_str(PRESET, Path::new("p.toml")).unwrap();
        assert_eq!(p.base.train.episodes, 7);
        let runs = p.runs();
        assert_eq!(runs.len(), 12);
        assert_eq!(runs[0].name, "ddpg-posture-seed1");
        assert_eq!(runs[11].name, "sac-sar-seed3");
        assert_eq!(runs[4].config.reward.function, RewardFunction::Sar);
        assert_eq!(runs[4].config.train.seed, 2);
        let mut seen: Vec<usize> = Vec::new();
        for i in 0..5 {
            seen.extend(shard(runs.clone(), i, 5).unwrap().iter().map(|r| r.index));
        }
        seen.sort_unstable();
        assert_eq!(seen, (0..12).collect::<Vec<_>>());
        assert!(shard(runs.clone(), 5, 5).is_err());
        assert!(shard(runs, 0, 0).is_err());
    }

    #[test]
    fn preset_errors_name_the_field() {
        let cases = [
            ("[train]\nepisodes = 3\n", "no [sweep]"),
            ("[sweep]\nalgorithms = []\nrewards = [\"sar\"]\nseeds = [1]\n", "sweep.algorithms"),
            ("[sweep]\nalgorithms = [\"ppo\"]\nrewards = [\"sar\"]\nseeds = [1]\n", "ppo"),
            ("[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1, 1]\n", "sweep.seeds"),
            ("[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1]\nextra = 2\n", "extra"),
            (
                "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1]\n[train]\nepisodes = 0\n",
                "train.episodes",
            ),
        ];
        for (text, needle) in cases {
            let e = Preset::from_toml_str(text, Path::new("p.toml")).unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn bundled_presets_parse() {
        for name in ["smoke", "quick", "paper"] {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../configs/{name}.toml"));
            let p = Preset::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(p.sweep.algorithms, vec![Algo::Ddpg, Algo::Sac], "{name}");
            assert_eq!(p.sweep.rewards.len(), 5, "{name}");
        }
        let paper =
            Preset::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/paper.toml")).unwrap();
        assert_eq!(
            (paper.sweep.seeds.len(), paper.base.train.episodes, paper.sweep.eval_trials),
            (20, 10000, 500)
        );
        assert_eq!(paper.base.task.max_steps, 50);
    }
}
