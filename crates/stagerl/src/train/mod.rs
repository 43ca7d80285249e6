//! The off-policy training loop shared by every agent (the paper's Algorithm 1: act, compute the
//! reward, update the actor and the critic after every environment step), and the run directory
//! it writes.
//!
//! A run directory holds:
//! - `config.toml`: the resolved configuration (seed included);
//! - `episodes.csv`: one row per episode (see [`EpisodeRecord`]);
//! - `eval.csv`: the periodic evaluations;
//! - `tb/`: TensorBoard event files with the same scalars and the losses;
//! - `checkpoints/latest.safetensors` (every `checkpoint_every_episodes`) and
//!   `checkpoints/final.safetensors` (at the end): networks, targets, optimiser states, random
//!   states, counters, with metadata naming the algorithm, the shapes and the config hash.

pub mod eval;

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::agent::{self, Agent, UpdateStats};
use crate::checkpoint::Checkpoint;
use crate::config::Config;
use crate::env::ReachEnv;
use crate::log::{EpisodeCsv, EpisodeRecord, EventWriter};
use crate::replay::{Batch, ReplayBuffer};
use crate::rng::Rng;
use crate::{Error, Result};

pub use eval::{evaluate, EvalSummary, TrialRecord};

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
    /// The checkpoint a finished run is evaluated from: final, else latest.
    pub fn best_available_checkpoint(&self) -> Option<PathBuf> {
        [self.final_checkpoint(), self.latest()].into_iter().find(|p| p.exists())
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
    agent.load(&ck).map_err(|e| Error::InvalidInput(format!("{}: {e}", path.display())))?;
    Ok(agent)
}

/// Train from scratch into `out` (created if needed; any previous run there is replaced, the
/// caller decides whether that is allowed). `on_episode` sees every finished episode.
pub fn train(cfg: &Config, out: &Path, mut on_episode: impl FnMut(&Progress<'_>)) -> Result<TrainSummary> {
    cfg.validate()?;
    let dir = RunDir::new(out);
    for d in [dir.root.clone(), dir.tb(), dir.checkpoints()] {
        std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
    }
    crate::io::write_atomic(&dir.config(), cfg.to_toml_string().as_bytes())?;
    let hash = config_hash(cfg);

    let seed = cfg.train.seed;
    let mut env = ReachEnv::from_config(cfg, Rng::derived(seed, 0).next_u64())?;
    let mut eval_env = env.clone();
    let (od, ad) = (env.obs_dim(), env.act_dim());
    let mut agent = build_agent(cfg, &env)?;
    let mut buffer = ReplayBuffer::new(cfg.agent.buffer_size, od, ad)?;
    let mut batch = Batch::new(cfg.agent.batch_size, od, ad);
    let mut replay_rng = Rng::derived(seed, 1);
    let mut warmup_rng = Rng::derived(seed, 2);

    let mut csv = EpisodeCsv::create(&dir.episodes())?;
    let mut eval_csv =
        String::from("episode,env_steps,success_rate,mean_reward,mean_steps,median_final_distance_m\n");
    let mut tb = EventWriter::create(&dir.tb())?;
    let start = Instant::now();
    let (mut env_steps, mut updates) = (0u64, 0u64);
    let mut obs = vec![0.0f32; od];
    let mut action = vec![0.0f32; ad];
    let mut last_stats: Option<UpdateStats> = None;

    let save = |agent: &dyn Agent, path: &Path, episode: u64, env_steps: u64, updates: u64| -> Result<()> {
        let mut ck = Checkpoint::new();
        agent.save(&mut ck);
        ck.put_meta("algorithm", agent.algo().name());
        ck.put_json("obs_dim", &od);
        ck.put_json("act_dim", &ad);
        ck.put_json("hidden", &cfg.agent.hidden);
        ck.put_meta("config_hash", hash.clone());
        ck.put_meta("config", cfg.to_toml_string());
        ck.put_json("episode", &episode);
        ck.put_json("env_steps", &env_steps);
        ck.put_json("updates", &updates);
        ck.save(path)
    };

    for episode in 1..=cfg.train.episodes {
        obs.copy_from_slice(env.reset());
        agent.begin_episode();
        let mut episode_reward = 0.0;
        let step = loop {
            if env_steps < cfg.agent.learning_starts {
                for a in action.iter_mut() {
                    *a = warmup_rng.uniform_range(-1.0, 1.0) as f32;
                }
            } else {
                agent.act(&obs, &mut action);
            }
            let s = env.step(&action)?;
            episode_reward += s.total();
            buffer.push(&obs, &action, s.total(), env.observation(), s.terminated);
            obs.copy_from_slice(env.observation());
            env_steps += 1;
            if env_steps >= cfg.agent.learning_starts {
                for _ in 0..cfg.agent.updates_per_step {
                    buffer.sample_into(&mut replay_rng, &mut batch);
                    let stats = agent.update(&batch);
                    updates += 1;
                    for (what, v) in
                        [("critic loss", Some(stats.critic_loss)), ("actor loss", stats.actor_loss)]
                    {
                        if let Some(v) = v.filter(|v| !v.is_finite()) {
                            return Err(Error::InvalidInput(format!(
                                "numerical fault: {what} = {v} at episode {episode}, step {} (update {updates}); \
                                 the last good checkpoint is left in place",
                                env.steps()
                            )));
                        }
                    }
                    last_stats = Some(stats);
                }
            }
            if s.done() {
                break s;
            }
        };
        if let Some(fault) = agent.first_non_finite() {
            return Err(Error::InvalidInput(format!(
                "numerical fault: {fault} at episode {episode}, step {}; the last good checkpoint is left in place",
                env.steps()
            )));
        }
        let record = EpisodeRecord {
            episode,
            reward: episode_reward,
            steps: env.steps(),
            success: step.terminated,
            final_distance_m: step.terms.distance,
            env_steps,
            wall_s: start.elapsed().as_secs_f64(),
        };
        csv.write(&record)?;
        let ep = episode as i64;
        tb.scalar("train/episode_reward", ep, record.reward)?;
        tb.scalar("train/steps", ep, f64::from(record.steps))?;
        tb.scalar("train/success", ep, f64::from(u8::from(record.success)))?;
        tb.scalar("train/final_distance_m", ep, record.final_distance_m)?;
        if let Some(st) = &last_stats {
            tb.scalar("loss/critic", ep, st.critic_loss)?;
            if let Some(v) = st.actor_loss {
                tb.scalar("loss/actor", ep, v)?;
            }
            if let Some(v) = st.alpha {
                tb.scalar("sac/alpha", ep, v)?;
            }
            if let Some(v) = st.entropy {
                tb.scalar("sac/entropy", ep, v)?;
            }
        }
        let every = cfg.train.eval_every_episodes;
        let eval = if every > 0 && (episode % every == 0 || episode == cfg.train.episodes) {
            let (summary, _) =
                evaluate(agent.as_mut(), &mut eval_env, cfg.train.eval_trials, cfg.train.eval_seed)?;
            eval_csv.push_str(&format!(
                "{episode},{env_steps},{},{},{},{}\n",
                summary.success_rate,
                summary.mean_reward,
                summary.mean_steps.map(|s| s.to_string()).unwrap_or_default(),
                summary.median_final_distance_m
            ));
            crate::io::write_atomic(&dir.eval(), eval_csv.as_bytes())?;
            tb.scalar("eval/success_rate", ep, summary.success_rate)?;
            tb.scalar("eval/mean_reward", ep, summary.mean_reward)?;
            tb.scalar("eval/median_final_distance_m", ep, summary.median_final_distance_m)?;
            Some(summary)
        } else {
            None
        };
        let k = cfg.train.checkpoint_every_episodes;
        if k > 0 && episode % k == 0 {
            save(agent.as_ref(), &dir.latest(), episode, env_steps, updates)?;
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
    }
    tb.flush()?;
    let final_checkpoint = dir.final_checkpoint();
    save(agent.as_ref(), &final_checkpoint, cfg.train.episodes, env_steps, updates)?;
    save(agent.as_ref(), &dir.latest(), cfg.train.episodes, env_steps, updates)?;
    Ok(TrainSummary {
        episodes: cfg.train.episodes,
        env_steps,
        updates,
        wall_s: start.elapsed().as_secs_f64(),
        final_checkpoint,
    })
}
