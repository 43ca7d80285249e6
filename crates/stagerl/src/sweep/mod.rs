//! Sweeps: the paper's protocol of algorithms x reward functions x seeds, each run trained and
//! then evaluated on random targets, resumable and shardable across machines.
//!
//! A preset is a TOML file with a `[sweep]` section and, beside it, any sections of an ordinary
//! [`Config`] that every run shares; `[agent.ddpg]`, `[agent.td3]` and `[agent.sac]` for each
//! algorithm of the sweep, each run keeping only its own:
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
//!
//! [agent.ddpg]
//! noise = "ou"
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
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use crate::agent::Algo;
use crate::agent::HerConfig;
use crate::config::Config;
use crate::reward::RewardFunction;
use crate::run::dir::RunDir;
use crate::train::eval::EvalSummary;
use crate::train::{self, final_eval, Progress, TrainOptions};
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
    /// Hindsight relabelling variants ([`crate::train::her`]): each run of the sweep once per entry,
    /// `"off"` or a goal strategy (`"future"`, `"final"`, `"episode"`, with `k` from
    /// `[agent.her]`, else 4). Empty (absent): as the preset's `[agent]` says.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub her: Vec<String>,
}

impl SweepSpec {
    /// The `agent.her` of each entry of `sweep.her` (`[base]` when empty), `base` giving `k`.
    fn her_variants(&self, base: Option<HerConfig>) -> Result<Vec<Option<HerConfig>>> {
        if self.her.is_empty() {
            return Ok(vec![base]);
        }
        let mut out = Vec::new();
        for h in &self.her {
            let v = match h.as_str() {
                "off" => None,
                s => Some(HerConfig {
                    strategy: s.parse().map_err(|_| {
                        Error::config(
                            "sweep.her",
                            format!("{:?}", self.her),
                            "entries \"off\", \"future\", \"final\" or \"episode\"",
                        )
                    })?,
                    ..base.unwrap_or_default()
                }),
            };
            if out.contains(&v) {
                return Err(Error::config("sweep.her", format!("{:?}", self.her), "distinct entries"));
            }
            out.push(v);
        }
        Ok(out)
    }
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

/// The presets bundled with the library (the files in `configs/presets/`), by name.
pub const BUNDLED_PRESETS: [(&str, &str); 6] = [
    ("smoke", include_str!("../../../../configs/presets/smoke.toml")),
    ("quick", include_str!("../../../../configs/presets/quick.toml")),
    ("tuned", include_str!("../../../../configs/presets/tuned.toml")),
    ("paper", include_str!("../../../../configs/presets/paper.toml")),
    ("learners", include_str!("../../../../configs/presets/learners.toml")),
    ("learners-long", include_str!("../../../../configs/presets/learners-long.toml")),
];

impl Preset {
    /// A bundled preset by name (`smoke`, `quick`, `tuned`, `paper`, `learners`, `learners-long`), else the preset file at that path;
    /// with the preset's text (written to the sweep directory as `preset.toml`).
    pub fn resolve(name_or_path: &str) -> Result<(Preset, String)> {
        if let Some((_, text)) = BUNDLED_PRESETS.iter().find(|(n, _)| *n == name_or_path) {
            let origin = PathBuf::from(format!("configs/presets/{name_or_path}.toml"));
            return Ok((Preset::from_toml_str(text, &origin)?, text.to_string()));
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            let names: Vec<&str> = BUNDLED_PRESETS.iter().map(|(n, _)| *n).collect();
            return Err(Error::InvalidInput(format!(
                "preset `{name_or_path}`: not one of {}, and no such file",
                names.join(", ")
            )));
        }
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Ok((Preset::from_toml_str(&text, path)?, text))
    }

    /// Parse a preset; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Preset> {
        let bad = |m: String| Error::ConfigParse { path: origin.to_path_buf(), message: m };
        let mut table: toml::Table =
            toml::from_str(text).map_err(|e| bad(crate::base::text::bound_message(&e.to_string())))?;
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
        if let Some(a) = self.base.agent.sections().into_iter().find(|a| !s.algorithms.contains(a)) {
            let algos: Vec<&str> = s.algorithms.iter().map(|a| a.name()).collect();
            return Err(Error::config(
                format!("agent.{a}"),
                format!("a [agent.{a}] section"),
                format!("sections of the sweep's algorithms only ({})", algos.join(", ")),
            ));
        }
        for &algo in &s.algorithms {
            self.base.agent.for_algo(algo).validate()?;
        }
        s.her_variants(self.base.agent.her)?;
        Ok(())
    }

    /// Every run of the sweep, in order.
    pub fn runs(&self) -> Vec<RunSpec> {
        // Checked by `validate`, which every constructor runs.
        let variants =
            self.sweep.her_variants(self.base.agent.her).unwrap_or_else(|_| vec![self.base.agent.her]);
        let mut out = Vec::new();
        for &algo in &self.sweep.algorithms {
            for &reward in &self.sweep.rewards {
                // Relabelling is for the off-policy agents: PPO runs once, without.
                let algo_variants: &[Option<HerConfig>] =
                    if algo.is_off_policy() { &variants } else { &[None] };
                for &her in algo_variants {
                    for &seed in &self.sweep.seeds {
                        let mut config = self.base.clone();
                        config.agent = self.base.agent.for_algo(algo);
                        config.agent.her = her;
                        config.reward.function = reward;
                        config.train.seed = seed;
                        out.push(RunSpec { index: out.len(), name: run_name(&config), config });
                    }
                }
            }
        }
        out
    }
}

/// Create the sweep directory `out` and record the preset's text in it (`preset.toml`,
/// atomically, under the sweep directory's lock) unless it already holds `text`: several
/// processes sharing the sweep write it once.
pub fn write_preset(out: &Path, text: &str) -> Result<()> {
    let _lock = crate::run::lock::DirLock::sweep(out)?;
    let path = out.join("preset.toml");
    if std::fs::read(&path).is_ok_and(|old| old == text.as_bytes()) {
        return Ok(());
    }
    crate::io::write_atomic(&path, text.as_bytes())
}

/// The name of a config's run directory: `<algo>-<reward>-seed<seed>`, with hindsight
/// relabelling `<algo>-<reward>-her-<strategy>-seed<seed>`.
pub fn run_name(cfg: &Config) -> String {
    let her = cfg.agent.her.map(|h| format!("-her-{}", h.strategy.name())).unwrap_or_default();
    format!("{}-{}{her}-seed{}", cfg.agent.algo, cfg.reward.function, cfg.train.seed)
}

/// The shard a process runs, `(index, count)`: the flags when given; for each flag that is
/// absent, Slurm's job-array variables (read through `var`): the index is
/// `(SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN) / SLURM_ARRAY_TASK_STEP` (`--array=0-19:2`
/// gives the ids 0, 2, .., 18), the count `SLURM_ARRAY_TASK_COUNT`; else shard 0 of 1. A
/// variable is only read (and only then an error when malformed) when its flag is absent.
pub fn resolve_shard(
    index: Option<usize>,
    count: Option<usize>,
    var: &dyn Fn(&str) -> Option<String>,
) -> Result<(usize, usize)> {
    let num =
        |name: &str| -> Result<Option<usize>> {
            match var(name) {
                None => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    Error::InvalidInput(format!("${name} = {v:?}: expected a whole number >= 0"))
                }),
            }
        };
    let index = match index {
        Some(i) => i,
        None => match num("SLURM_ARRAY_TASK_ID")? {
            None => 0,
            Some(id) => {
                let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
                let step = num("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1);
                let offset = id.checked_sub(min).ok_or_else(|| {
                    Error::InvalidInput(format!(
                        "$SLURM_ARRAY_TASK_ID = {id} is below $SLURM_ARRAY_TASK_MIN = {min}"
                    ))
                })?;
                if step == 0 || offset % step != 0 {
                    return Err(Error::InvalidInput(format!(
                        "$SLURM_ARRAY_TASK_ID = {id} is not $SLURM_ARRAY_TASK_MIN = {min} plus a multiple \
                         of $SLURM_ARRAY_TASK_STEP = {step} (which must be >= 1)"
                    )));
                }
                offset / step
            }
        },
    };
    let count = match count {
        Some(c) => c,
        None => match num("SLURM_ARRAY_TASK_COUNT")? {
            Some(c) => c,
            None if index == 0 => 1,
            None => {
                return Err(Error::InvalidInput(format!(
                    "task index {index} needs a task count (--task-count or $SLURM_ARRAY_TASK_COUNT)"
                )))
            }
        },
    };
    Ok((index, count))
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

/// Where the run `dir` of `spec` stands in `sweep`: done only when its closing evaluation is
/// recorded with the sweep's evaluation settings (also for an archived run, kept without its
/// resumable checkpoint: [`final_eval::is_archived`]).
pub fn status(dir: &Path, spec: &RunSpec, sweep: &SweepSpec) -> Result<RunStatus> {
    let (trials, seed) = (sweep.eval_trials, sweep.eval_seed);
    Ok(match train::checkpointed_episode(dir)? {
        Some((_, true)) if final_eval::is_current(dir, &spec.config, trials, seed) => RunStatus::Done,
        Some((_, true)) if final_eval::recorded(dir, seed).is_some() => RunStatus::StaleEval,
        Some((_, true)) => RunStatus::Trained,
        Some((episode, false)) => RunStatus::Partial { episode },
        None if final_eval::is_archived(dir, &spec.config, trials, seed) => RunStatus::Done,
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
    // One process per run: another process's run is skipped (`Error::Locked`). The status is
    // read under the lock, so a run another process finished is not trained again.
    let _lock = crate::run::lock::DirLock::run(&dir)?;
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
    if run.holds_run() && run.load_config()? != spec.config {
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

/// One run of a sweep, as [`run_sweep`] reports it when the run ends.
pub struct RunReport<'a> {
    pub spec: &'a RunSpec,
    /// Runs ended so far, this one included (in the order they end).
    pub n: usize,
    /// Runs in the sweep (or shard).
    pub total: usize,
    /// Where the run stood before this session, read under its lock (`None` when the run
    /// failed).
    pub before: Option<RunStatus>,
    /// Wall seconds of this session's work on the run.
    pub wall_s: f64,
    /// The run's evaluation, or why there is none ([`Error::Interrupted`] on a stop during
    /// training, [`Error::Stopped`] during its evaluation, [`Error::Locked`] when another
    /// process works on it).
    pub result: &'a Result<EvalSummary>,
}

/// How a sweep ended.
#[derive(Debug)]
pub struct SweepOutcome {
    /// `<name>: <error>` of each failed run.
    pub failures: Vec<String>,
    /// A stop was requested (or a run was interrupted): runs may be left to do.
    pub interrupted: bool,
    /// Runs skipped because another process holds them (it finishes them).
    pub taken: usize,
    pub wall_s: f64,
}

/// Train and evaluate `runs` into `out`, `jobs` at once (threads, each run single-threaded),
/// taking them in order; a finished run is not repeated and a run another process holds is
/// skipped (see [`run_one`]). Setting `stop` interrupts the runs under way (each saves its
/// checkpoint) and starts no other.
/// `on_run` sees each run as it ends.
pub fn run_sweep(
    runs: &[RunSpec],
    out: &Path,
    sweep: &SweepSpec,
    jobs: usize,
    stop: &AtomicBool,
    on_run: &(dyn Fn(&RunReport<'_>) + Sync),
) -> SweepOutcome {
    let total = runs.len();
    let (next, done) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let failures: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let interrupted = AtomicBool::new(false);
    let taken = AtomicUsize::new(0);
    let start = Instant::now();
    let worker = || loop {
        let k = next.fetch_add(1, Ordering::SeqCst);
        if k >= total || stop.load(Ordering::SeqCst) {
            break;
        }
        let spec = &runs[k];
        let t0 = Instant::now();
        let opts = TrainOptions { stop: Some(stop) };
        let (before, result) = match run_one(spec, out, sweep, &opts, &mut |_| {}) {
            Ok((before, summary)) => (Some(before), Ok(summary)),
            Err(e) => (None, Err(e)),
        };
        match &result {
            Ok(_) => {}
            Err(Error::Interrupted { .. } | Error::Stopped { .. }) => {
                interrupted.store(true, Ordering::SeqCst)
            }
            Err(Error::Locked { .. }) => {
                taken.fetch_add(1, Ordering::SeqCst);
            }
            Err(e) => failures.lock().unwrap_or_else(|p| p.into_inner()).push(format!("{}: {e}", spec.name)),
        }
        let n = done.fetch_add(1, Ordering::SeqCst) + 1;
        on_run(&RunReport { spec, n, total, before, wall_s: t0.elapsed().as_secs_f64(), result: &result });
    };
    std::thread::scope(|scope| {
        for _ in 0..jobs.clamp(1, total.max(1)) {
            scope.spawn(worker);
        }
    });
    SweepOutcome {
        failures: failures.into_inner().unwrap_or_else(|p| p.into_inner()),
        interrupted: interrupted.load(Ordering::SeqCst) || stop.load(Ordering::SeqCst),
        taken: taken.into_inner(),
        wall_s: start.elapsed().as_secs_f64(),
    }
}

/// Summarise an existing evaluation file.
pub fn read_eval(dir: &Path, eval_seed: u64) -> Result<EvalSummary> {
    train::eval::read_run_eval(&RunDir::new(dir), eval_seed)
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
    fn shard_from_flags_or_slurm_with_step() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |name: &str| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| v.to_string())
        };
        let none = env(&[]);
        assert_eq!(resolve_shard(None, None, &none).unwrap(), (0, 1));
        assert_eq!(resolve_shard(Some(2), Some(5), &none).unwrap(), (2, 5));
        assert!(resolve_shard(Some(2), None, &none).unwrap_err().to_string().contains("task count"));
        // --array=0-19:2: ids 0, 2, .., 18 are tasks 0 .. 9 of 10.
        let stepped = env(&[
            ("SLURM_ARRAY_TASK_ID", "14"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "10"),
        ]);
        assert_eq!(resolve_shard(None, None, &stepped).unwrap(), (7, 10));
        let offset = env(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "3"),
        ]);
        assert_eq!(resolve_shard(None, Some(4), &offset).unwrap(), (2, 4));
        let off_grid = env(&[
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "10"),
        ]);
        let e = resolve_shard(None, None, &off_grid).unwrap_err().to_string();
        assert!(e.contains("SLURM_ARRAY_TASK_STEP = 2"), "{e}");
        // Explicit flags win: malformed variables are not even read.
        let bad = env(&[("SLURM_ARRAY_TASK_ID", "x"), ("SLURM_ARRAY_TASK_COUNT", "-1")]);
        assert_eq!(resolve_shard(Some(1), Some(3), &bad).unwrap(), (1, 3));
        let e = resolve_shard(None, Some(3), &bad).unwrap_err().to_string();
        assert!(e.contains("SLURM_ARRAY_TASK_ID") && e.contains("\"x\""), "{e}");
        let e = resolve_shard(Some(0), None, &bad).unwrap_err().to_string();
        assert!(e.contains("SLURM_ARRAY_TASK_COUNT"), "{e}");
        let below = env(&[("SLURM_ARRAY_TASK_ID", "0"), ("SLURM_ARRAY_TASK_MIN", "1")]);
        assert!(resolve_shard(None, None, &below).unwrap_err().to_string().contains("below"));
    }

    #[test]
    fn bundled_presets_resolve_by_name_and_paths_by_path() {
        let (p, text) = Preset::resolve("smoke").unwrap();
        assert_eq!(text, BUNDLED_PRESETS[0].1);
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/presets/smoke.toml");
        let (q, from_file) = Preset::resolve(path.to_str().unwrap()).unwrap();
        assert_eq!((p, text), (q, from_file));
        let e = Preset::resolve("nope").unwrap_err().to_string();
        assert!(e.contains("nope") && e.contains("smoke, quick, tuned, paper"), "{e}");
    }

    #[test]
    fn preset_errors_name_the_field() {
        let cases = [
            ("[train]\nepisodes = 3\n", "no [sweep]"),
            ("[sweep]\nalgorithms = []\nrewards = [\"sar\"]\nseeds = [1]\n", "sweep.algorithms"),
            ("[sweep]\nalgorithms = [\"a2c\"]\nrewards = [\"sar\"]\nseeds = [1]\n", "a2c"),
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
    fn each_run_keeps_only_its_algorithms_section() {
        let text = format!(
            "{PRESET}[agent]\ngamma = 0.9\n[agent.ddpg]\nnoise = \"ou\"\n[agent.sac]\ninit_alpha = 0.5\n"
        );
        let p = Preset::from_toml_str(&text, Path::new("p.toml")).unwrap();
        for run in p.runs() {
            let agent = &run.config.agent;
            assert_eq!(agent.gamma, 0.9, "{}", run.name);
            assert_eq!(agent.sections(), vec![agent.algo], "{}", run.name);
            run.config.validate().unwrap();
            let written = run.config.to_toml_string();
            match agent.algo {
                Algo::Ddpg => {
                    assert_eq!(agent.ddpg().noise, crate::agent::NoiseKind::Ou);
                    assert!(
                        written.contains("[agent.ddpg]") && !written.contains("[agent.sac]"),
                        "{written}"
                    );
                }
                Algo::Sac => {
                    assert_eq!(agent.sac().init_alpha, 0.5);
                    assert!(
                        written.contains("[agent.sac]") && !written.contains("[agent.ddpg]"),
                        "{written}"
                    );
                }
                Algo::Td3 | Algo::Ppo => unreachable!("not in the sweep"),
            }
            // The run's resolved config.toml reads back as the same config.
            assert_eq!(Config::from_toml_str(&written, Path::new("config.toml")).unwrap(), run.config);
        }
        // A section of an algorithm outside the sweep is refused, naming it and the sweep's.
        let e =
            Preset::from_toml_str(&format!("{PRESET}[agent.td3]\npolicy_delay = 3\n"), Path::new("p.toml"))
                .unwrap_err()
                .to_string();
        assert!(e.contains("agent.td3") && e.contains("ddpg, sac"), "{e}");
        // A section's values are checked like a run's.
        let e =
            Preset::from_toml_str(&format!("{PRESET}[agent.ddpg]\nnoise_sigma = -1\n"), Path::new("p.toml"))
                .unwrap_err()
                .to_string();
        assert!(e.contains("agent.ddpg.noise_sigma"), "{e}");
    }

    #[test]
    fn her_variants_multiply_the_runs() {
        let text = "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"basic\", \"sar\"]\nseeds = [1, 2]\nher = [\"off\", \"future\"]\n[agent.her]\nk = 2\n";
        let p = Preset::from_toml_str(text, Path::new("t.toml")).unwrap();
        let names: Vec<String> = p.runs().into_iter().map(|r| r.name).collect();
        assert_eq!(
            names,
            [
                "sac-basic-seed1",
                "sac-basic-seed2",
                "sac-basic-her-future-seed1",
                "sac-basic-her-future-seed2",
                "sac-sar-seed1",
                "sac-sar-seed2",
                "sac-sar-her-future-seed1",
                "sac-sar-her-future-seed2"
            ]
        );
        // PPO in the same sweep runs once per reward and seed, without relabelling, also when
        // only `[agent.her]` asks for it.
        let with_ppo = text.replace("[\"sac\"]", "[\"sac\", \"ppo\"]");
        for t in [with_ppo.clone(), with_ppo.replace("her = [\"off\", \"future\"]\n", "")] {
            let runs = Preset::from_toml_str(&t, Path::new("t.toml")).unwrap().runs();
            let ppo: Vec<&str> =
                runs.iter().filter(|r| r.config.agent.algo == Algo::Ppo).map(|r| r.name.as_str()).collect();
            assert_eq!(ppo, ["ppo-basic-seed1", "ppo-basic-seed2", "ppo-sar-seed1", "ppo-sar-seed2"], "{t}");
            assert!(runs.iter().all(|r| r.config.validate().is_ok()));
        }
        let her = p.runs()[2].config.agent.her.unwrap();
        assert_eq!((her.strategy, her.k), (crate::agent::HerStrategy::Future, 2));
        assert_eq!(p.runs()[0].config.agent.her, None);
        for bad in ["[\"sometimes\"]", "[\"off\", \"off\"]"] {
            let t = text.replace("[\"off\", \"future\"]", bad);
            let e = Preset::from_toml_str(&t, Path::new("t.toml")).unwrap_err().to_string();
            assert!(e.contains("sweep.her"), "{e}");
        }
    }

    /// Every file of `configs/` (presets, studies), a preset (bundled or run by path) or a config (`--config`),
    /// parses, and each config validates, so that a documented command never meets a config error.
    #[test]
    fn every_config_file_parses() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
        let mut paths = Vec::new();
        for dir in ["presets", "studies", "studies/pilot-ddpg"] {
            paths.extend(std::fs::read_dir(root.join(dir)).unwrap().map(|e| e.unwrap().path()));
        }
        let mut seen = 0;
        for path in paths {
            if path.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&path).unwrap();
                seen += 1;
                if !text.contains("[sweep]") {
                    let c = crate::config::Config::from_toml_str(&text, &path);
                    c.and_then(|c| c.validate()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                    continue;
                }
                let p =
                    Preset::from_toml_str(&text, &path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                assert!(!p.runs().is_empty(), "{}", path.display());
                for r in p.runs() {
                    r.config.validate().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                }
            }
        }
        assert!(seen >= 25, "{seen} config files under {}", root.display());
    }

    #[test]
    fn bundled_presets_parse() {
        for (name, _) in BUNDLED_PRESETS.iter().filter(|(n, _)| !n.starts_with("learners")) {
            let (p, _) = Preset::resolve(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(p.sweep.algorithms, vec![Algo::Ddpg, Algo::Sac], "{name}");
            // The paper's presets cover its five rewards.
            assert_eq!(p.sweep.rewards.len(), 5, "{name}");
        }
        // DDPG and SAC with and without HER, PPO once: 2 x 3 x 2 x 3 + 3 x 3.
        let (learners, _) = Preset::resolve("learners").unwrap();
        assert_eq!((learners.runs().len(), learners.base.train.episodes), (45, 5000));
        assert!(learners
            .runs()
            .iter()
            .all(|r| r.config.agent.algo.is_off_policy() || r.config.agent.her.is_none()));
        let (long, _) = Preset::resolve("learners-long").unwrap();
        assert_eq!((long.runs().len(), long.base.train.episodes), (6, 30000));
        let (paper, _) = Preset::resolve("paper").unwrap();
        assert_eq!(
            (paper.sweep.seeds.len(), paper.base.train.episodes, paper.sweep.eval_trials),
            (20, 10000, 500)
        );
        assert_eq!(paper.base.task.max_steps, 50);
        // The paper regime: gamma 0.99 and unscaled observations.
        assert_eq!(
            crate::report::reference::Regime::of(paper.base.agent.gamma, paper.base.task.obs_delta_scale),
            crate::report::reference::Regime::Paper
        );
        // The tuned regime: the library's defaults at 10 seeds x 5000 episodes.
        let (tuned, _) = Preset::resolve("tuned").unwrap();
        assert_eq!((tuned.sweep.seeds.len(), tuned.base.train.episodes), (10, 5000));
        let d = Config::default();
        assert_eq!(
            (tuned.base.agent.gamma, tuned.base.task.obs_delta_scale),
            (d.agent.gamma, d.task.obs_delta_scale)
        );
    }
}
