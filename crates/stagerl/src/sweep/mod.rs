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
use crate::report::reference::Regime;
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
    /// The regime the study's runs are in (`"paper"` or `"tuned"`), which its report names;
    /// the preset must then use the regime's `agent.gamma` and `task.obs_delta_scale`. Absent:
    /// custom settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub regime: Option<Regime>,
    /// Named variants of the sweep's algorithms (DroQ and REDQ as settings of SAC, say): each
    /// runs beside its algorithm, with its own settings over the preset's, under its own name.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variants: Vec<SweepVariant>,
    /// Combinations left out of the sweep: each entry's keys (`algorithm`, an algorithm's or a
    /// variant's name; `reward`; `her`, an entry of `sweep.her`) all match the runs it removes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exclude: Vec<Exclude>,
}

/// One of `[[sweep.variants]]`: an algorithm of the sweep under another name, with settings of
/// its own (sections of a config: `agent`, `task`, `reward`, `train`) over the preset's.
///
/// ```toml
/// [[sweep.variants]]
/// name = "droq"            # run directories droq-<reward>-seed<seed>
/// algorithm = "sac"
/// [sweep.variants.agent]
/// updates_per_step = 20
/// [sweep.variants.agent.sac]
/// critic_dropout = 0.01
/// critic_layer_norm = true
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepVariant {
    pub name: String,
    pub algorithm: Algo,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agent: Option<toml::Table>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<toml::Table>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reward: Option<toml::Table>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train: Option<toml::Table>,
}

/// One of `[[sweep.exclude]]` (see [`SweepSpec::exclude`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Exclude {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub algorithm: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reward: Option<RewardFunction>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub her: Option<String>,
}

impl Exclude {
    fn matches(&self, learner: &str, reward: RewardFunction, her: &str) -> bool {
        self.algorithm.as_deref().is_none_or(|a| a == learner)
            && self.reward.is_none_or(|r| r == reward)
            && self.her.as_deref().is_none_or(|h| h == her)
    }
}

/// The name `sweep.her` gives a relabelling setting.
fn her_name(her: Option<HerConfig>) -> &'static str {
    her.map_or("off", |h| h.strategy.name())
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
    /// The config each of `sweep.variants` starts from (the preset's with the variant's
    /// settings over it), in the same order.
    pub variant_bases: Vec<Config>,
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
pub const BUNDLED_PRESETS: [(&str, &str); 8] = [
    ("smoke", include_str!("../../../../configs/presets/smoke.toml")),
    ("quick", include_str!("../../../../configs/presets/quick.toml")),
    ("tuned", include_str!("../../../../configs/presets/tuned.toml")),
    ("paper", include_str!("../../../../configs/presets/paper.toml")),
    ("learners", include_str!("../../../../configs/presets/learners.toml")),
    ("learners-long", include_str!("../../../../configs/presets/learners-long.toml")),
    ("sample-efficiency", include_str!("../../../../configs/presets/sample-efficiency.toml")),
    ("crossq-rewards", include_str!("../../../../configs/presets/crossq-rewards.toml")),
];

impl Preset {
    /// A bundled preset by name (`smoke`, `quick`, `tuned`, `paper`, `learners`, `learners-long`,
    /// `sample-efficiency`, `crossq-rewards`), else the preset file at that path;
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
        let text = read_preset(path)?;
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
        let mut variant_bases = Vec::new();
        for (i, v) in sweep.variants.iter().enumerate() {
            let mut t = table.clone();
            for (section, over) in
                [("agent", &v.agent), ("task", &v.task), ("reward", &v.reward), ("train", &v.train)]
            {
                if let Some(over) = over {
                    let into = t.entry(section).or_insert_with(|| toml::Value::Table(toml::Table::new()));
                    if let toml::Value::Table(into) = into {
                        merge_table(into, over);
                    }
                }
            }
            let text = toml::to_string(&t).map_err(|e| bad(e.to_string()))?;
            let named = PathBuf::from(format!("{} (sweep.variants[{i}], `{}`)", origin.display(), v.name));
            variant_bases.push(Config::from_toml_str(&text, &named)?);
        }
        let preset = Preset { sweep, base, variant_bases };
        preset.validate()?;
        Ok(preset)
    }

    /// Read a preset file.
    pub fn load(path: &Path) -> Result<Preset> {
        let text = read_preset(path)?;
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
        self.check_variants()?;
        self.check_regime()?;
        self.check_excludes()
    }

    /// Variants are named safely and distinctly, of an algorithm of the sweep, and do not
    /// change it.
    fn check_variants(&self) -> Result<()> {
        let s = &self.sweep;
        for (i, (v, base)) in s.variants.iter().zip(&self.variant_bases).enumerate() {
            let field = format!("sweep.variants[{i}].name");
            let ok = |c: char| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_';
            if v.name.is_empty() || v.name.len() > 40 || !v.name.chars().all(ok) {
                return Err(Error::config(
                    field,
                    &v.name,
                    "1-40 characters a-z, 0-9 or _ (it names run directories)",
                ));
            }
            if Algo::ALL.iter().any(|a| a.name() == v.name)
                || s.variants[..i].iter().any(|w| w.name == v.name)
            {
                return Err(Error::config(field, &v.name, "a name no algorithm and no other variant has"));
            }
            if !s.algorithms.contains(&v.algorithm) {
                let algos: Vec<&str> = s.algorithms.iter().map(|a| a.name()).collect();
                return Err(Error::config(
                    format!("sweep.variants[{i}].algorithm"),
                    v.algorithm.name(),
                    format!("one of the sweep's algorithms ({})", algos.join(", ")),
                ));
            }
            if v.agent.as_ref().is_some_and(|a| a.contains_key("algo")) {
                return Err(Error::config(
                    format!("sweep.variants[{i}].agent.algo"),
                    "set",
                    "unset: a variant's algorithm is `sweep.variants[].algorithm`",
                ));
            }
            base.agent.for_algo(v.algorithm).validate()?;
            s.her_variants(base.agent.her)?;
        }
        Ok(())
    }

    /// Each `sweep.exclude` entry has a key and removes at least one run (else it is a typo).
    fn check_excludes(&self) -> Result<()> {
        for (i, x) in self.sweep.exclude.iter().enumerate() {
            let field = format!("sweep.exclude[{i}]");
            if x.algorithm.is_none() && x.reward.is_none() && x.her.is_none() {
                return Err(Error::config(field, "{}", "at least one of `algorithm`, `reward`, `her`"));
            }
            let mut any = false;
            self.combinations(|learner, _, _, reward, her| {
                any |= x.matches(learner, reward, her_name(her));
            });
            if !any {
                return Err(Error::config(
                    field,
                    format!("{x:?}"),
                    "an entry that matches some run of the sweep (algorithm or variant names, rewards and \
                     `sweep.her` entries of the sweep)",
                ));
            }
        }
        Ok(())
    }

    /// Every (learner name, algorithm, base config, reward, relabelling) of the sweep before
    /// `sweep.exclude`, in the sweep's order: each algorithm, then its variants.
    fn combinations(&self, mut f: impl FnMut(&str, Algo, &Config, RewardFunction, Option<HerConfig>)) {
        for &algo in &self.sweep.algorithms {
            let variants =
                self.sweep.variants.iter().zip(&self.variant_bases).filter(|(v, _)| v.algorithm == algo);
            let learners =
                std::iter::once((algo.name(), &self.base)).chain(variants.map(|(v, b)| (v.name.as_str(), b)));
            for (learner, base) in learners {
                // Checked by `validate`, which every constructor runs.
                let hers = self.sweep.her_variants(base.agent.her).unwrap_or_else(|_| vec![base.agent.her]);
                for &reward in &self.sweep.rewards {
                    // Relabelling is for the off-policy agents: PPO runs once, without.
                    let hers: &[Option<HerConfig>] = if algo.is_off_policy() { &hers } else { &[None] };
                    for &her in hers {
                        f(learner, algo, base, reward, her);
                    }
                }
            }
        }
    }

    /// A named regime's settings are the preset's (and its variants').
    fn check_regime(&self) -> Result<()> {
        let Some(regime) = self.sweep.regime else { return Ok(()) };
        let Some((gamma, scale)) = regime.settings() else { return Ok(()) };
        for base in std::iter::once(&self.base).chain(&self.variant_bases) {
            let (agent, task) = (&base.agent, &base.task);
            for (field, value, want) in
                [("agent.gamma", agent.gamma, gamma), ("task.obs_delta_scale", task.obs_delta_scale, scale)]
            {
                if value != want {
                    return Err(Error::config(
                        field,
                        value,
                        format!(
                            "{want}: the value of the regime `sweep.regime` names ({})",
                            regime.describe()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The arm and the task every run shares, resolved once before any run starts: an error
    /// there (a URDF that does not load, per-joint settings an arm that is not six-jointed
    /// lacks) is reported once, not once per run.
    pub fn check_shared(&self) -> Result<()> {
        match self.runs().first() {
            Some(run) => run.config.resolve().map(|_| ()),
            None => Ok(()),
        }
    }

    /// Every run of the sweep, in order: algorithm-major (each followed by its variants), then
    /// reward, relabelling and seed; without the combinations `sweep.exclude` removes.
    pub fn runs(&self) -> Vec<RunSpec> {
        let mut out = Vec::new();
        self.combinations(|learner, algo, base, reward, her| {
            if self.sweep.exclude.iter().any(|x| x.matches(learner, reward, her_name(her))) {
                return;
            }
            for &seed in &self.sweep.seeds {
                let mut config = base.clone();
                config.agent = base.agent.for_algo(algo);
                config.agent.her = her;
                config.reward.function = reward;
                config.train.seed = seed;
                let name = run_name_as(learner, &config);
                out.push(RunSpec { index: out.len(), name, config });
            }
        });
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
    run_name_as(cfg.agent.algo.name(), cfg)
}

/// [`run_name`] with `learner` (a variant's name) in place of the algorithm's.
fn run_name_as(learner: &str, cfg: &Config) -> String {
    let her = cfg.agent.her.map(|h| format!("-her-{}", h.strategy.name())).unwrap_or_default();
    format!("{learner}-{}{her}-seed{}", cfg.reward.function, cfg.train.seed)
}

/// `over`'s values into `into`, tables merged key by key (the rest replaced).
fn merge_table(into: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (into.get_mut(k), v) {
            (Some(toml::Value::Table(a)), toml::Value::Table(b)) => merge_table(a, b),
            _ => {
                into.insert(k.clone(), v.clone());
            }
        }
    }
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
            train::train_with(&spec.config.resolve()?, &dir, opts, on_episode)?;
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

/// A preset file's text: a regular file of at most [`crate::config::MAX_CONFIG_BYTES`] (a FIFO
/// or a device is refused unread).
fn read_preset(path: &Path) -> Result<String> {
    let bytes = crate::io::read_regular(path, crate::config::MAX_CONFIG_BYTES, "preset")?;
    String::from_utf8(bytes)
        .map_err(|e| Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error())))
}

#[cfg(test)]
mod tests;
