//! The off-policy training loop shared by every agent (the paper's Algorithm 1: act, compute the
//! reward, update the actor and the critic after every environment step), and the run directory
//! it writes.
//!
//! A run directory holds:
//! - `config.toml`: the resolved configuration (seed included);
//! - `episodes.csv`: one row per episode (see [`EpisodeRecord`]);
//! - `eval.csv`: the periodic evaluations;
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
//!
//! - `eval-final-seed<N>.csv` and its record `eval-final-seed<N>.json`: the closing evaluation
//!   (see [`final_eval`]); `eval-<checkpoint>-trials<T>-seed<N>.csv`: evaluations by `stagerl eval`;
//! - `.stagerl.lock`: the advisory lock of the process writing the run (see [`crate::lock`]).
//!
//! Metadata in both names the algorithm, the shapes and the config hash. [`resume`] continues a
//! run from `latest.safetensors` so that its `episodes.csv` (but the wall time) and its networks
//! are bit-identical to those of an uninterrupted run.

pub mod eval;
pub mod final_eval;
pub mod replace;

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::agent::{self, Agent, UpdateStats};
use crate::checkpoint::Checkpoint;
use crate::config::Config;
use crate::env::{EnvState, ReachEnv};
use crate::log::{EpisodeCsv, EpisodeRecord, EventWriter};
use crate::replay::{Batch, ReplayBuffer};
use crate::rng::Rng;
use crate::{Error, Result};

pub use eval::{evaluate, evaluate_until, EvalSummary, TrialRecord};

/// The largest evaluation asked for at once (its per-trial records are kept in memory).
pub const MAX_EVAL_TRIALS: u32 = 10_000_000;

/// Training settings (the `[train]` section).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The run's seed: environment targets, initial weights, exploration, replay sampling.
    pub seed: u64,
    /// Training episodes (paper: 10000). Default 5000: DDPG + SAR reaches 99 % by then, SAC + SAR
    /// by about 1500.
    pub episodes: u64,
    /// Evaluate the deterministic policy every this many episodes; 0 disables.
    pub eval_every_episodes: u64,
    /// Trials of each periodic evaluation.
    pub eval_trials: u32,
    /// Seed of the evaluation targets (the same targets at every evaluation point).
    pub eval_seed: u64,
    /// Write `checkpoints/latest.safetensors` every this many episodes; 0 only at the end.
    pub checkpoint_every_episodes: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            seed: 0,
            episodes: 5000,
            eval_every_episodes: 250,
            eval_trials: 100,
            eval_seed: 1_000_003,
            checkpoint_every_episodes: 250,
        }
    }
}

impl TrainConfig {
    pub fn validate(&self) -> Result<()> {
        if self.episodes == 0 {
            return Err(Error::config("train.episodes", 0, "an integer >= 1"));
        }
        if self.eval_trials > MAX_EVAL_TRIALS {
            return Err(Error::config(
                "train.eval_trials",
                self.eval_trials,
                format!("at most {MAX_EVAL_TRIALS}"),
            ));
        }
        if self.eval_every_episodes > 0 && self.eval_trials == 0 {
            return Err(Error::config(
                "train.eval_trials",
                0,
                "an integer >= 1 (or set train.eval_every_episodes = 0 to disable evaluation)",
            ));
        }
        Ok(())
    }
}

/// What the loop reports after each episode.
pub struct Progress<'a> {
    pub record: &'a EpisodeRecord,
    /// The last update's statistics, once learning has started.
    pub stats: Option<UpdateStats>,
    /// The evaluation run at the end of this episode, if any.
    pub eval: Option<&'a EvalSummary>,
    /// Total episodes of the run.
    pub episodes: u64,
}

/// How a run ended.
#[derive(Clone, Debug)]
pub struct TrainSummary {
    pub episodes: u64,
    pub env_steps: u64,
    pub updates: u64,
    pub wall_s: f64,
    pub final_checkpoint: PathBuf,
}

/// FNV-1a 64 of the config's TOML, recorded in checkpoints to tell configs apart.
pub fn config_hash(cfg: &Config) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in cfg.to_toml_string().bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Paths inside a run directory.
pub struct RunDir {
    pub root: PathBuf,
}

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
    /// Read the run's resolved config.
    pub fn load_config(&self) -> Result<Config> {
        Config::load(&self.config())
    }
}

/// Build the agent a config describes for `env`, seeded by the run's seed.
pub fn build_agent(cfg: &Config, env: &ReachEnv) -> Result<Box<dyn Agent>> {
    agent::build(&cfg.agent, env.obs_dim(), env.act_dim(), Rng::derived(cfg.train.seed, 3).next_u64())
}

/// Load an agent from a checkpoint, checking that it was written for this config's algorithm and
/// shapes.
pub fn load_agent(cfg: &Config, env: &ReachEnv, path: &Path) -> Result<Box<dyn Agent>> {
    let ck = Checkpoint::load(path)?;
    let algo = ck.meta("algorithm")?;
    if algo != cfg.agent.algo.name() {
        return Err(Error::InvalidInput(format!(
            "{}: checkpoint of algorithm `{algo}`, the config says `{}`",
            path.display(),
            cfg.agent.algo
        )));
    }
    let mut agent = build_agent(cfg, env)?;
    agent.load(&ck)?; // the checkpoint's errors name its file
    Ok(agent)
}

/// Counters and random states of a run, saved in every full checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct LoopState {
    /// Episodes completed.
    episode: u64,
    env_steps: u64,
    updates: u64,
    /// A checkpoint taken mid-episode: the episode `episode + 1` is under way.
    in_episode: bool,
    /// The eq. 16 reward of the episode under way so far.
    episode_reward: f64,
    env: EnvState,
    replay_rng: Rng,
    warmup_rng: Rng,
    replay_len: usize,
    replay_pos: usize,
    /// Wall seconds of the run before this session (so `wall_s` keeps counting).
    wall_s: f64,
    finished: bool,
    /// Best periodic evaluation so far: (success rate, mean reward), for `best.safetensors`.
    #[serde(default)]
    best_eval: Option<(f64, f64)>,
    /// [runsafe] A stop came between the updates of this environment step: they go on first.
    #[serde(default)]
    step_under_way: Option<StepUnderWay>,
    /// [runsafe] A stop came during the periodic evaluation of episode `episode`: it runs first.
    #[serde(default)]
    eval_due: bool,
}

/// An environment step taken whose updates are not all done yet (see [`LoopState`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct StepUnderWay {
    /// Updates of this step still to do.
    updates_left: u32,
    terminated: bool,
    done: bool,
    /// D_PT after the step, metres, as `f64::to_bits` (exact through JSON).
    final_distance_m_bits: u64,
}

/// Options of a training session.
#[derive(Default)]
pub struct TrainOptions<'a> {
    /// Set (by a signal handler, say) to stop: the run is saved and [`Error::Interrupted`] returned.
    pub stop: Option<&'a AtomicBool>,
}

/// A run in progress.
struct Trainer {
    cfg: Config,
    dir: RunDir,
    hash: String,
    env: ReachEnv,
    eval_env: ReachEnv,
    agent: Box<dyn Agent>,
    buffer: ReplayBuffer,
    batch: Batch,
    state: LoopState,
    eval_csv: String,
}

/// The header of a run's `eval.csv`.
pub const EVAL_HEADER: &str = "episode,env_steps,success_rate,mean_reward,mean_steps,median_final_distance_m";

impl Trainer {
    /// A fresh run.
    fn new(cfg: &Config, dir: RunDir) -> Result<Trainer> {
        let seed = cfg.train.seed;
        let env = ReachEnv::from_config(cfg, Rng::derived(seed, 0).next_u64())?;
        let (od, ad) = (env.obs_dim(), env.act_dim());
        let agent = build_agent(cfg, &env)?;
        let state = LoopState {
            episode: 0,
            env_steps: 0,
            updates: 0,
            in_episode: false,
            episode_reward: 0.0,
            env: env.state(),
            replay_rng: Rng::derived(seed, 1),
            warmup_rng: Rng::derived(seed, 2),
            replay_len: 0,
            replay_pos: 0,
            wall_s: 0.0,
            finished: false,
            best_eval: None,
            step_under_way: None,
            eval_due: false,
        };
        Ok(Trainer {
            hash: config_hash(cfg),
            eval_env: env.clone(),
            buffer: ReplayBuffer::new(cfg.agent.buffer_size, od, ad)?,
            batch: Batch::new(cfg.agent.batch_size, od, ad),
            cfg: cfg.clone(),
            dir,
            env,
            agent,
            state,
            eval_csv: format!("{EVAL_HEADER}\n"),
        })
    }

    /// Write the full training state to `latest.safetensors` (atomically).
    fn save_latest(&mut self) -> Result<()> {
        let mut ck = self.checkpoint_base();
        self.state.env = self.env.state();
        self.state.replay_len = self.buffer.len();
        self.state.replay_pos = self.buffer.position();
        for (name, data) in self.buffer.arrays() {
            ck.put_tensor(name, &[data.len()], data);
        }
        ck.put_json("train_state", &self.state);
        ck.put_meta("eval_csv", self.eval_csv.clone());
        ck.save(&self.dir.latest())
    }

    /// The agent and the run's identity, shared by both checkpoint kinds.
    fn checkpoint_base(&self) -> Checkpoint {
        let mut ck = Checkpoint::new();
        self.agent.save(&mut ck);
        ck.put_meta("algorithm", self.agent.algo().name());
        ck.put_json("obs_dim", &self.env.obs_dim());
        ck.put_json("act_dim", &self.env.act_dim());
        ck.put_json("hidden", &self.cfg.agent.hidden);
        ck.put_meta("config_hash", self.hash.clone());
        ck.put_meta("config", self.cfg.to_toml_string());
        ck.put_json("episode", &self.state.episode);
        ck.put_json("env_steps", &self.state.env_steps);
        ck.put_json("updates", &self.state.updates);
        ck
    }

    /// Restore a run from its `latest.safetensors`.
    fn restore(cfg: &Config, dir: RunDir, ck: &Checkpoint) -> Result<Trainer> {
        let mut t = Trainer::new(cfg, dir)?;
        let path = t.dir.latest();
        let hash = ck.meta("config_hash")?;
        if hash != t.hash {
            return Err(Error::InvalidInput(format!(
                "{}: written for another config (hash {hash}, the run's config.toml gives {}); \
                 was config.toml edited?",
                path.display(),
                t.hash
            )));
        }
        let algo = ck.meta("algorithm")?;
        if algo != cfg.agent.algo.name() {
            return Err(Error::InvalidInput(format!(
                "{}: checkpoint of algorithm `{algo}`, the run's config says `{}`",
                path.display(),
                cfg.agent.algo
            )));
        }
        t.agent.load(ck)?;
        t.state = ck.json("train_state")?;
        let data: Vec<&[f32]> =
            ReplayBuffer::ARRAY_NAMES.iter().map(|n| ck.tensor(n).map(|(_, d)| d)).collect::<Result<_>>()?;
        t.buffer.restore(
            t.state.replay_len,
            t.state.replay_pos,
            [data[0], data[1], data[2], data[3], data[4]],
        )?;
        t.env.restore(&t.state.env)?;
        t.eval_csv = ck.meta("eval_csv")?.to_string();
        Ok(t)
    }

    /// Cut the logs back to what the checkpoint has seen (a killed run may have logged further).
    fn rewind_logs(&self) -> Result<()> {
        let path = self.dir.episodes();
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let keep = self.state.episode as usize;
        let mut lines = text.lines();
        let mut out = String::new();
        match lines.next() {
            Some(h) if h == EpisodeRecord::HEADER => out.push_str(h),
            _ => return Err(Error::InvalidInput(format!("{}: not an episodes.csv", path.display()))),
        }
        out.push('\n');
        let rows: Vec<&str> = lines.take(keep).collect();
        if rows.len() < keep || rows.iter().any(|r| EpisodeRecord::from_csv(r).is_err()) {
            return Err(Error::InvalidInput(format!(
                "{}: holds fewer complete rows than the checkpoint's {keep} episodes",
                path.display()
            )));
        }
        for r in rows {
            out.push_str(r);
            out.push('\n');
        }
        crate::io::write_atomic(&path, out.as_bytes())?;
        crate::io::write_atomic(&self.dir.eval(), self.eval_csv.as_bytes())?;
        // [runsafe] The TensorBoard log too: each tag's steps up to the checkpoint, once (but an
        // evaluation still due at the checkpoint's episode, which runs again).
        let (ep, eval_due) = (self.state.episode as i64, self.state.eval_due);
        let keep =
            |tag: &str, step: i64| step < ep || (step == ep && !(eval_due && tag.starts_with("eval/")));
        crate::log::tensorboard::rewind(&self.dir.tb(), keep).map(|_| ())
    }

    /// One environment step of the episode under way (a random action before learning starts,
    /// the agent's otherwise), stored in the replay buffer; its updates are still to do.
    fn env_step(&mut self, obs: &mut [f32], action: &mut [f32]) -> Result<StepUnderWay> {
        let cfg = &self.cfg;
        if self.state.env_steps < cfg.agent.learning_starts {
            for a in action.iter_mut() {
                *a = self.state.warmup_rng.uniform_range(-1.0, 1.0) as f32;
            }
        } else {
            self.agent.act(obs, action);
            if let Some(i) = action.iter().position(|a| !a.is_finite()) {
                return Err(Error::NumericalFault(format!(
                    "the actor's action[{i}] = {} at episode {}, step {} (update {}); \
                     the last good checkpoint is left in place",
                    action[i],
                    self.state.episode + 1,
                    self.env.steps() + 1,
                    self.state.updates
                )));
            }
        }
        let s = self.env.step(action)?;
        self.state.episode_reward += s.total();
        self.buffer.push(obs, action, s.total(), self.env.observation(), s.terminated);
        obs.copy_from_slice(self.env.observation());
        self.state.env_steps += 1;
        let learning = self.state.env_steps >= cfg.agent.learning_starts;
        Ok(StepUnderWay {
            updates_left: if learning { cfg.agent.updates_per_step } else { 0 },
            terminated: s.terminated,
            done: s.done(),
            final_distance_m_bits: s.terms.distance.to_bits(),
        })
    }

    /// The periodic evaluation of the episode just finished, when due (`state.eval_due`): the
    /// row of `eval.csv`, its TensorBoard scalars and `best.safetensors` when it is the best.
    /// A stop request ends it with [`Error::Stopped`], `eval_due` still set. [runsafe]
    fn periodic_eval(
        &mut self,
        tb: &mut EventWriter,
        stop: Option<&AtomicBool>,
    ) -> Result<Option<EvalSummary>> {
        if !self.state.eval_due {
            return Ok(None);
        }
        let (episode, cfg) = (self.state.episode, &self.cfg);
        let (summary, _) = evaluate_until(
            self.agent.as_mut(),
            &mut self.eval_env,
            cfg.train.eval_trials,
            cfg.train.eval_seed,
            stop,
        )?;
        self.eval_csv.push_str(&format!(
            "{episode},{},{},{},{},{}\n",
            self.state.env_steps,
            summary.success_rate,
            summary.mean_reward,
            summary.mean_steps.map(|s| s.to_string()).unwrap_or_default(),
            summary.median_final_distance_m
        ));
        crate::io::write_atomic(&self.dir.eval(), self.eval_csv.as_bytes())?;
        let ep = episode as i64;
        tb.scalar("eval/success_rate", ep, summary.success_rate)?;
        tb.scalar("eval/mean_reward", ep, summary.mean_reward)?;
        tb.scalar("eval/median_final_distance_m", ep, summary.median_final_distance_m)?;
        let score = (summary.success_rate, summary.mean_reward);
        if self.state.best_eval.is_none_or(|best| score > best) {
            self.state.best_eval = Some(score);
            let mut ck = self.checkpoint_base();
            ck.put_json("eval_success_rate", &summary.success_rate);
            ck.put_json("eval_mean_reward", &summary.mean_reward);
            ck.save(&self.dir.best())?;
        }
        self.state.eval_due = false;
        Ok(Some(summary))
    }

    fn check_loss(&self, what: &str, v: Option<f64>) -> Result<()> {
        match v {
            Some(v) if !v.is_finite() => Err(Error::NumericalFault(format!(
                "{what} = {v} at episode {}, step {} (update {}); the last good checkpoint is left in place",
                self.state.episode + 1,
                self.env.steps(),
                self.state.updates
            ))),
            _ => Ok(()),
        }
    }

    /// Train until `train.episodes` episodes are done or `stop` is set.
    fn run(
        &mut self,
        opts: &TrainOptions<'_>,
        on_episode: &mut dyn FnMut(&Progress<'_>),
    ) -> Result<TrainSummary> {
        let cfg = self.cfg.clone();
        for d in [self.dir.root.clone(), self.dir.tb(), self.dir.checkpoints()] {
            std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
        }
        let mut csv = if self.state.episode == 0 && !self.state.in_episode {
            EpisodeCsv::create(&self.dir.episodes())?
        } else {
            EpisodeCsv::append(&self.dir.episodes())?
        };
        let mut tb = EventWriter::create(&self.dir.tb())?;
        let start = Instant::now();
        let wall0 = self.state.wall_s;
        let (od, ad) = (self.env.obs_dim(), self.env.act_dim());
        let mut obs = vec![0.0f32; od];
        let mut action = vec![0.0f32; ad];
        let mut last_stats: Option<UpdateStats> = None;
        let stop_requested = || opts.stop.is_some_and(|s| s.load(Ordering::SeqCst));
        let interrupted = |t: &mut Trainer, wall: f64| -> Error {
            t.state.wall_s = wall;
            match t.save_latest() {
                Ok(()) => Error::Interrupted { episode: t.state.episode, checkpoint: t.dir.latest() },
                Err(e) => e,
            }
        };

        // [runsafe] A periodic evaluation a stop interrupted runs first, as it would have.
        match self.periodic_eval(&mut tb, opts.stop) {
            Err(Error::Stopped { .. }) => return Err(interrupted(self, wall0)),
            other => {
                other?;
            }
        }
        while self.state.episode < cfg.train.episodes {
            if self.state.in_episode {
                obs.copy_from_slice(self.env.observation());
            } else {
                obs.copy_from_slice(self.env.reset());
                self.agent.begin_episode();
                self.state.episode_reward = 0.0;
                self.state.in_episode = true;
            }
            let step = loop {
                // [runsafe] A step whose updates a stop interrupted goes on with them.
                let mut step = match self.state.step_under_way.take() {
                    Some(s) => s,
                    None => self.env_step(&mut obs, &mut action)?,
                };
                while step.updates_left > 0 {
                    if stop_requested() {
                        // [runsafe] Between updates: many updates_per_step no longer delay a stop.
                        self.state.step_under_way = Some(step);
                        return Err(interrupted(self, wall0 + start.elapsed().as_secs_f64()));
                    }
                    self.buffer.sample_into(&mut self.state.replay_rng, &mut self.batch);
                    let stats = self.agent.update(&self.batch);
                    self.state.updates += 1;
                    step.updates_left -= 1;
                    self.check_loss("critic loss", Some(stats.critic_loss))?;
                    self.check_loss("actor loss", stats.actor_loss)?;
                    last_stats = Some(stats);
                }
                if step.done {
                    break step;
                }
                if stop_requested() {
                    return Err(interrupted(self, wall0 + start.elapsed().as_secs_f64()));
                }
            };
            if let Some(fault) = self.agent.first_non_finite() {
                return Err(Error::NumericalFault(format!(
                    "{fault} at episode {}, step {}; the last good checkpoint is left in place",
                    self.state.episode + 1,
                    self.env.steps()
                )));
            }
            self.state.in_episode = false;
            self.state.episode += 1;
            let episode = self.state.episode;
            let record = EpisodeRecord {
                episode,
                reward: self.state.episode_reward,
                steps: self.env.steps(),
                success: step.terminated,
                final_distance_m: f64::from_bits(step.final_distance_m_bits),
                env_steps: self.state.env_steps,
                wall_s: wall0 + start.elapsed().as_secs_f64(),
            };
            csv.write(&record)?;
            let ep = episode as i64;
            tb.scalar("train/episode_reward", ep, record.reward)?;
            tb.scalar("train/steps", ep, f64::from(record.steps))?;
            tb.scalar("train/success", ep, f64::from(u8::from(record.success)))?;
            tb.scalar("train/final_distance_m", ep, record.final_distance_m)?;
            if let Some(st) = &last_stats {
                tb.scalar("loss/critic", ep, st.critic_loss)?;
                for (tag, v) in
                    [("loss/actor", st.actor_loss), ("sac/alpha", st.alpha), ("sac/entropy", st.entropy)]
                {
                    if let Some(v) = v {
                        tb.scalar(tag, ep, v)?;
                    }
                }
            }
            let every = cfg.train.eval_every_episodes;
            self.state.eval_due = every > 0 && (episode % every == 0 || episode == cfg.train.episodes);
            let eval = match self.periodic_eval(&mut tb, opts.stop) {
                Err(Error::Stopped { .. }) => return Err(interrupted(self, record.wall_s)), // [runsafe]
                other => other?,
            };
            let k = cfg.train.checkpoint_every_episodes;
            if k > 0 && episode % k == 0 && episode < cfg.train.episodes {
                self.state.wall_s = record.wall_s;
                tb.flush()?; // [runsafe] what the checkpoint has seen is on disk (for the rewind)
                self.save_latest()?;
            }
            on_episode(&Progress {
                record: &record,
                stats: last_stats,
                eval: eval.as_ref(),
                episodes: cfg.train.episodes,
            });
            if episode % 50 == 0 {
                tb.flush()?;
            }
            if stop_requested() && episode < cfg.train.episodes {
                return Err(interrupted(self, record.wall_s));
            }
        }
        tb.flush()?;
        self.state.wall_s = wall0 + start.elapsed().as_secs_f64();
        self.state.finished = true;
        self.checkpoint_base().save(&self.dir.final_checkpoint())?;
        self.save_latest()?;
        Ok(self.summary())
    }

    fn summary(&self) -> TrainSummary {
        TrainSummary {
            episodes: self.state.episode,
            env_steps: self.state.env_steps,
            updates: self.state.updates,
            wall_s: self.state.wall_s,
            final_checkpoint: self.dir.final_checkpoint(),
        }
    }
}

/// Train from scratch into `out` (created if needed; files of a previous run there are replaced,
/// the caller decides whether that is allowed). `on_episode` sees every finished episode.
pub fn train(cfg: &Config, out: &Path, mut on_episode: impl FnMut(&Progress<'_>)) -> Result<TrainSummary> {
    train_with(cfg, out, &TrainOptions::default(), &mut on_episode)
}

/// [`train`] with options (a stop flag).
pub fn train_with(
    cfg: &Config,
    out: &Path,
    opts: &TrainOptions<'_>,
    on_episode: &mut dyn FnMut(&Progress<'_>),
) -> Result<TrainSummary> {
    cfg.validate()?;
    let dir = RunDir::new(out);
    std::fs::create_dir_all(&dir.root).map_err(|e| Error::io(&dir.root, e))?;
    // A new run: nothing of an older one may be mistaken for this run's. [runsafe]
    replace::remove_previous_run(&dir)?;
    crate::io::write_atomic(&dir.config(), cfg.to_toml_string().as_bytes())?;
    Trainer::new(cfg, dir)?.run(opts, on_episode)
}

/// What [`resume`] found and did.
pub enum Resumed {
    /// The run was continued (or restarted, when killed before its first checkpoint) and finished.
    Finished(TrainSummary),
    /// The run had already finished; nothing was done.
    AlreadyFinished(TrainSummary),
}

/// Continue the run in `out` from its last checkpoint, with the config stored in the run. A run
/// killed before its first checkpoint starts over. The result is bit-identical (but wall time) to
/// an uninterrupted run with the same seed on one thread.
pub fn resume(
    out: &Path,
    opts: &TrainOptions<'_>,
    on_episode: &mut dyn FnMut(&Progress<'_>),
) -> Result<Resumed> {
    let dir = RunDir::new(out);
    let cfg = dir.load_config()?;
    let latest = dir.latest();
    if !latest.exists() {
        return train_with(&cfg, out, opts, on_episode).map(Resumed::Finished);
    }
    let ck = Checkpoint::load(&latest)?;
    let mut t = Trainer::restore(&cfg, dir, &ck)?;
    if t.state.finished {
        return Ok(Resumed::AlreadyFinished(t.summary()));
    }
    t.rewind_logs()?;
    t.run(opts, on_episode).map(Resumed::Finished)
}

/// The episode count of the last full checkpoint of a run, if any (`None` before the first).
pub fn checkpointed_episode(out: &Path) -> Result<Option<(u64, bool)>> {
    let latest = RunDir::new(out).latest();
    if !latest.exists() {
        return Ok(None);
    }
    let ck = Checkpoint::load(&latest)?;
    let st: LoopState = ck.json("train_state")?;
    Ok(Some((st.episode, st.finished)))
}
