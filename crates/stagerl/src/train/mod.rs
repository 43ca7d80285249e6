//! The one training loop of every agent, over one of two collectors chosen at construction from
//! the agent's kind ([`crate::agent::Learner`]): the off-policy one (`off_policy.rs`: the paper's
//! Algorithm 1, act, store, update the actor and the critic after every environment step, with
//! HER's relabelling) or the on-policy one (`on_policy.rs`: PPO's parallel environments and
//! rollout). The loop owns what every algorithm shares: the episode log, the periodic evaluation
//! and the best checkpoint, checkpoints, TensorBoard and stops ([`Trainer`]). It writes a run
//! directory.
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
//! - `eval-final-seed<N>.csv` and its record `eval-final-seed<N>.json`: the closing evaluation
//!   (see [`final_eval`]); `eval-<checkpoint>-trials<T>-seed<N>.csv`: evaluations by `stagerl eval`;
//! - `.stagerl.lock`: the advisory lock of the process writing the run (see [`crate::run::lock`]).
//!
//! Metadata in both names the algorithm, the shapes and the config hash. [`resume`] continues a
//! run from `latest.safetensors` so that its `episodes.csv` (but the wall time) and its networks
//! are bit-identical to those of an uninterrupted run.

pub mod demonstrations;
pub mod eval;
pub mod final_eval;
pub mod her;
mod off_policy;
mod on_policy;
pub mod replace;

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::agent::{self, Agent, Learner, UpdateStats};
use crate::base::rng::Rng;
use crate::config::curriculum::StageAdvance;
use crate::config::{Config, Resolved};
use crate::env::{Policy, ReachEnv};
use crate::io::checkpoint::Checkpoint;
use crate::io::csv::{parse_line, push_row, CsvRecord, CsvRow};
use crate::io::csv::{EpisodeCsv, EpisodeRecord, EvalPoint};
use crate::io::tensorboard::EventWriter;
use crate::{Error, Result};
use demonstrations::DemoStats;

use crate::run::dir::RunDir;
use eval::{deterministic, evaluate, EvalOptions, EvalSummary};
use off_policy::OffPolicyCollector;
use on_policy::OnPolicyCollector;

/// What the loop reports after each episode.
pub struct Progress<'a> {
    pub record: &'a EpisodeRecord,
    /// The last update's statistics, once learning has started.
    pub stats: Option<UpdateStats>,
    /// The evaluation run at the end of this episode, if any.
    pub eval: Option<&'a EvalSummary>,
    /// Total episodes of the run (under an episode budget).
    pub episodes: u64,
    /// The run's budget in environment steps, when it has one (`train.env_steps`).
    pub env_steps: Option<u64>,
    /// This episode is the run's last.
    pub last: bool,
    /// With `train.curriculum`: the stage that begins with the next episode, when it changed
    /// after this one (the stage of this episode is in the record).
    pub stage_advance: Option<StageAdvance>,
    /// With `train.demonstrations`: what they stored, on the episode they were stored before.
    pub demonstrations: Option<DemoStats>,
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

/// Build the agent a config describes for `env`, seeded by the run's seed.
pub fn build_agent(cfg: &Config, env: &ReachEnv) -> Result<Box<dyn Agent>> {
    agent::build(&cfg.agent, env.obs_dim(), env.act_dim(), Rng::derived(cfg.train.seed, 3).next_u64())
}

/// Load an agent from a checkpoint, checking that it was written for this config's algorithm and
/// shapes.
pub fn load_agent(cfg: &Config, env: &ReachEnv, path: &Path) -> Result<Box<dyn Agent>> {
    let ck = checkpoint_for(cfg, path)?;
    let mut agent = build_agent(cfg, env)?;
    agent.load(&ck)?; // the checkpoint's errors name its file
    check_policy(&ck, cfg, env, agent.as_ref(), path)?;
    Ok(agent)
}

/// [`load_agent`] for a resolved config, with an environment for it; the checkpoint's policy
/// must be the one the config describes ([`check_policy`]).
fn load_resolved(run: &Resolved, path: &Path) -> Result<(ReachEnv, Box<dyn Agent>)> {
    load_resolved_noting(run, path).map(|(env, agent, _)| (env, agent))
}

/// A config field that differs between the config a checkpoint was trained with and the one it
/// is used with: the field (`reward.function`), its value there and here.
pub type ConfigChange = (String, String, String);

/// [`load_resolved`], with the config fields that differ from the checkpoint's own config (none
/// that changes the policy's inputs or outputs: those are refused).
fn load_resolved_noting(
    run: &Resolved,
    path: &Path,
) -> Result<(ReachEnv, Box<dyn Agent>, Vec<ConfigChange>)> {
    let ck = checkpoint_for(run.config(), path)?;
    let mut agent = run.learner(Rng::derived(run.config().train.seed, 3).next_u64()).into_agent();
    agent.load(&ck)?;
    let env = run.env(0)?;
    check_policy(&ck, run.config(), &env, agent.as_ref(), path)?;
    let changes = ck
        .meta("config")
        .map(|t| crate::run::policy::config_differences(t, run.config()))
        .unwrap_or_default();
    Ok((env, agent, changes))
}

/// An error if checkpoint `ck` (read from `path`) holds a policy with other inputs or outputs
/// than the one `cfg` describes on `env` ([`crate::run::policy::check_same_policy`]), naming
/// the field. A checkpoint written before policies were described is not checked here (its
/// tensors' shapes still are).
fn check_policy(ck: &Checkpoint, cfg: &Config, env: &ReachEnv, agent: &dyn Agent, path: &Path) -> Result<()> {
    use crate::run::policy::{check_same_policy, PolicySpec, POLICY_KEY};
    let Ok(stored) = ck.json::<serde_json::Value>(POLICY_KEY) else { return Ok(()) };
    let current = PolicySpec::new(cfg, env, agent);
    check_same_policy(&stored, &current, ck.meta("config").ok(), cfg, path)
}

/// The checkpoint at `path`, if written for the algorithm of `cfg`.
fn checkpoint_for(cfg: &Config, path: &Path) -> Result<Checkpoint> {
    let ck = Checkpoint::load(path)?;
    let algo = ck.meta("algorithm")?;
    if algo != cfg.agent.algo.name() {
        return Err(Error::InvalidInput(format!(
            "{}: checkpoint of algorithm `{}`, the config says `{}`",
            path.display(),
            crate::base::text::excerpt(algo),
            cfg.agent.algo
        )));
    }
    Ok(ck)
}

/// The checkpoint metadata holding the training state: the loop's [`LoopState`] and its
/// collector's state, as fields of one JSON object.
const TRAIN_STATE: &str = "train_state";

/// What the loop counts, shared with the collectors.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Counters {
    /// Episodes completed.
    episode: u64,
    env_steps: u64,
    updates: u64,
}

/// The loop's counters and progress, saved in every full checkpoint (beside the collector's
/// state, [`Collector::save`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct LoopState {
    #[serde(flatten)]
    n: Counters,
    /// Wall seconds of the run before this session (so `wall_s` keeps counting).
    wall_s: f64,
    finished: bool,
    /// Best periodic evaluation so far: (success rate, mean reward), for `best.safetensors`.
    #[serde(default)]
    best_eval: Option<(f64, f64)>,
    /// A stop came during the periodic evaluation of episode `episode`: it runs first.
    #[serde(default)]
    eval_due: bool,
    /// Environment steps at the end of the last episode (where an evaluation every so many
    /// environment steps counts from).
    #[serde(default)]
    last_episode_env_steps: u64,
}

/// How an episode ended, as its `episodes.csv` row needs it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct EpisodeEnd {
    /// Eq. 16's `R_episode`.
    reward: f64,
    steps: u32,
    success: bool,
    final_distance_m: f64,
    /// Steps that ended in contact (`None` in a checkpoint of an older version).
    #[serde(default)]
    collision_steps: Option<u32>,
    /// What the safety shield did in the episode (`None`: the shield is off, or PPO, whose
    /// vector env starts the next episode in the step that ends one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    shield: Option<crate::sim::shield::ShieldStats>,
    /// With `train.curriculum`: the stage the episode was played at.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    curriculum_stage: Option<u32>,
    /// With `train.curriculum`: the stage that begins after this episode, if it changed.
    #[serde(skip)]
    advance: Option<StageAdvance>,
    /// With `train.demonstrations`: what they stored, when that was done before this episode.
    #[serde(skip)]
    demonstrations: Option<DemoStats>,
}

/// How experience is collected and learnt from: a replay buffer and updates after every step
/// ([`OffPolicyCollector`]) or rollouts of parallel environments ([`OnPolicyCollector`]). The
/// loop asks it for episodes; it owns the agent, its training environments and what they need
/// to resume.
trait Collector {
    /// The agent being trained.
    fn agent(&self) -> &dyn Agent;
    fn agent_mut(&mut self) -> &mut dyn Agent;
    /// Step (and learn) until an episode ends; `None` when `stop_requested` said so first.
    fn next_episode(
        &mut self,
        n: &mut Counters,
        last_stats: &mut Option<UpdateStats>,
        stop_requested: &dyn Fn() -> bool,
    ) -> Result<Option<EpisodeEnd>>;
    /// An episode not yet logged is under way (a checkpoint taken mid-episode).
    fn mid_episode(&self) -> bool;
    /// Write its arrays to `ck`; the rest of its state, a JSON object, is returned to join the
    /// loop's in [`TRAIN_STATE`].
    fn save(&mut self, ck: &mut Checkpoint) -> serde_json::Value;
    /// Restore what [`Collector::save`] wrote (`path` names the checkpoint in errors).
    fn restore(&mut self, ck: &Checkpoint, path: &Path) -> Result<()>;
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
    /// The periodic evaluations' environment (obstacles drawn as the task says).
    eval_env: ReachEnv,
    collector: Box<dyn Collector>,
    state: LoopState,
    eval_csv: String,
}

impl Trainer {
    /// A fresh run.
    fn new(run: &Resolved, dir: RunDir) -> Result<Trainer> {
        let cfg = run.config();
        let seed = cfg.train.seed;
        let env = run.env(Rng::derived(seed, 0).next_u64())?;
        // Evaluations draw obstacles as the task says; only training places them in the way.
        let eval_env = env.clone();
        let collector: Box<dyn Collector> = match run.learner(Rng::derived(seed, 3).next_u64()) {
            Learner::OffPolicy(agent) => Box::new(OffPolicyCollector::new(cfg, env, agent)?),
            Learner::OnPolicy(ppo) => Box::new(OnPolicyCollector::new(run, ppo)?),
        };
        Ok(Trainer {
            hash: config_hash(cfg),
            eval_env,
            collector,
            cfg: cfg.clone(),
            dir,
            state: LoopState {
                n: Counters::default(),
                wall_s: 0.0,
                finished: false,
                best_eval: None,
                eval_due: false,
                last_episode_env_steps: 0,
            },
            eval_csv: format!("{}\n", EvalPoint::HEADER),
        })
    }

    /// Write the full training state to `latest.safetensors` (atomically).
    fn save_latest(&mut self) -> Result<()> {
        let mut ck = self.checkpoint_base();
        let mut state = serde_json::to_value(&self.state).expect("the state serialises");
        if let (Some(all), serde_json::Value::Object(theirs)) =
            (state.as_object_mut(), self.collector.save(&mut ck))
        {
            all.extend(theirs);
        }
        ck.put_json(TRAIN_STATE, &state);
        ck.put_meta("eval_csv", self.eval_csv.clone());
        ck.save(&self.dir.latest())
    }

    /// The agent and the run's identity, shared by both checkpoint kinds.
    fn checkpoint_base(&self) -> Checkpoint {
        let mut ck = Checkpoint::new();
        let (agent, env) = (self.collector.agent(), &self.eval_env);
        agent.save(&mut ck);
        ck.put_meta("algorithm", agent.algo().name());
        ck.put_json(
            crate::run::policy::POLICY_KEY,
            &crate::run::policy::PolicySpec::new(&self.cfg, env, agent),
        );
        ck.put_json("obs_dim", &env.obs_dim());
        ck.put_json("act_dim", &env.act_dim());
        ck.put_json("hidden", &self.cfg.agent.hidden);
        ck.put_meta("config_hash", self.hash.clone());
        ck.put_meta("config", self.cfg.to_toml_string());
        ck.put_json("episode", &self.state.n.episode);
        ck.put_json("env_steps", &self.state.n.env_steps);
        ck.put_json("updates", &self.state.n.updates);
        ck
    }

    /// Restore a run from its `latest.safetensors`.
    fn restore(run: &Resolved, dir: RunDir, ck: &Checkpoint) -> Result<Trainer> {
        let cfg = run.config();
        let mut t = Trainer::new(run, dir)?;
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
        t.collector.agent_mut().load(ck)?;
        t.state = ck.json(TRAIN_STATE)?;
        t.collector.restore(ck, &path)?;
        t.eval_csv = ck.meta("eval_csv")?.to_string();
        Ok(t)
    }

    /// Cut the logs back to what the checkpoint has seen (a killed run may have logged further).
    fn rewind_logs(&self) -> Result<()> {
        let path = self.dir.episodes();
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let keep = self.state.n.episode as usize;
        let mut lines = text.lines();
        let header = lines.next().unwrap_or_default();
        if !EpisodeRecord::known_header(header) {
            return Err(Error::InvalidInput(format!("{}: not an episodes.csv", path.display())));
        }
        // Rows are written again in this version's layout (a run begun by an older version
        // gets the newer columns, empty for its earlier rows).
        let rows: Vec<EpisodeRecord> =
            lines.take(keep).map_while(|r| parse_line::<EpisodeRecord>(r, &path).ok()).collect();
        if rows.len() < keep {
            return Err(Error::InvalidInput(format!(
                "{}: holds fewer complete rows than the checkpoint's {keep} episodes",
                path.display()
            )));
        }
        let header = EpisodeRecord::header(self.cfg.train.curriculum.is_some());
        crate::io::write_atomic(&path, crate::io::csv::to_csv_with_header(header, &rows).as_bytes())?;
        crate::io::write_atomic(&self.dir.eval(), self.eval_csv.as_bytes())?;
        // The TensorBoard log too: each tag's steps up to the checkpoint, once (but an evaluation
        // still due at the checkpoint's episode, which runs again).
        let (ep, eval_due) = (self.state.n.episode as i64, self.state.eval_due);
        let keep =
            |tag: &str, step: i64| step < ep || (step == ep && !(eval_due && tag.starts_with("eval/")));
        crate::io::tensorboard::rewind(&self.dir.tb(), keep).map(|_| ())
    }

    /// Train until `train.episodes` episodes are done or `stop` is set.
    fn run(
        &mut self,
        opts: &TrainOptions<'_>,
        on_episode: &mut dyn FnMut(&Progress<'_>),
    ) -> Result<TrainSummary> {
        let mut logs = self.open_logs()?;
        let (start, wall0) = (Instant::now(), self.state.wall_s);
        let wall = || wall0 + start.elapsed().as_secs_f64();
        let stop_requested = || opts.stop.is_some_and(|s| s.load(Ordering::SeqCst));
        let mut last_stats: Option<UpdateStats> = None;
        let episodes = self.cfg.train.episodes;
        // A periodic evaluation a stop interrupted runs first, as it would have.
        if let Err(e) = self.periodic_eval(&mut logs.tb, opts.stop) {
            return Err(self.stopped(e, wall()));
        }
        let train = self.cfg.train.clone();
        while !train.is_last(self.state.n.episode, self.state.last_episode_env_steps) {
            let next = self.collector.next_episode(&mut self.state.n, &mut last_stats, &stop_requested)?;
            let Some(end) = next else {
                return Err(self.interrupted(wall()));
            };
            let record = self.end_episode(&end, wall(), &mut logs, last_stats.as_ref())?;
            let before = std::mem::replace(&mut self.state.last_episode_env_steps, record.env_steps);
            self.state.eval_due = train.is_eval_point(record.episode, before, record.env_steps);
            let last = train.is_last(record.episode, record.env_steps);
            let eval = match self.periodic_eval(&mut logs.tb, opts.stop) {
                Ok(eval) => eval,
                Err(e) => return Err(self.stopped(e, record.wall_s)),
            };
            self.checkpoint(&record, &mut logs.tb)?;
            on_episode(&Progress {
                record: &record,
                stats: last_stats,
                eval: eval.as_ref(),
                episodes,
                env_steps: train.env_steps,
                last,
                stage_advance: end.advance,
                demonstrations: end.demonstrations,
            });
            if record.episode % 50 == 0 {
                logs.tb.flush()?;
            }
            if stop_requested() && !last {
                return Err(self.interrupted(record.wall_s));
            }
        }
        logs.tb.flush()?;
        self.state.wall_s = wall();
        self.state.finished = true;
        self.checkpoint_base().save(&self.dir.final_checkpoint())?;
        self.save_latest()?;
        Ok(self.summary())
    }

    /// Create the run's directories and open its logs (`episodes.csv` continued on a resume).
    fn open_logs(&self) -> Result<Logs> {
        for d in [self.dir.root.clone(), self.dir.tb(), self.dir.checkpoints()] {
            std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
        }
        let episodes = if self.state.n.episode == 0 && !self.collector.mid_episode() {
            let header = EpisodeRecord::header(self.cfg.train.curriculum.is_some());
            EpisodeCsv::create_with_header(&self.dir.episodes(), header)?
        } else {
            EpisodeCsv::append(&self.dir.episodes())?
        };
        Ok(Logs { episodes, tb: EventWriter::create(&self.dir.tb())? })
    }

    /// A stop request that ended an evaluation ([`Error::Stopped`]) saves the run as any stop;
    /// other errors pass.
    fn stopped(&mut self, e: Error, wall_s: f64) -> Error {
        match e {
            Error::Stopped { .. } => self.interrupted(wall_s),
            other => other,
        }
    }

    /// Save the run on a stop request; the error to return.
    fn interrupted(&mut self, wall_s: f64) -> Error {
        self.state.wall_s = wall_s;
        match self.save_latest() {
            Ok(()) => Error::Interrupted { episode: self.state.n.episode, checkpoint: self.dir.latest() },
            Err(e) => e,
        }
    }

    /// End an episode: check the networks, count it, write its row and its TensorBoard scalars.
    fn end_episode(
        &mut self,
        end: &EpisodeEnd,
        wall_s: f64,
        logs: &mut Logs,
        stats: Option<&UpdateStats>,
    ) -> Result<EpisodeRecord> {
        if let Some(fault) = self.collector.agent().first_non_finite() {
            return Err(Error::NumericalFault(format!(
                "{fault} at episode {}, step {}; the last good checkpoint is left in place",
                self.state.n.episode + 1,
                end.steps
            )));
        }
        self.state.n.episode += 1;
        let record = EpisodeRecord {
            episode: self.state.n.episode,
            reward: end.reward,
            steps: end.steps,
            success: end.success,
            final_distance_m: end.final_distance_m,
            env_steps: self.state.n.env_steps,
            wall_s,
            collision_steps: end.collision_steps,
            curriculum_stage: end.curriculum_stage,
        };
        logs.episodes.write(&record)?;
        let (ep, tb) = (record.episode as i64, &mut logs.tb);
        tb.scalar("train/episode_reward", ep, record.reward)?;
        tb.scalar("train/steps", ep, f64::from(record.steps))?;
        tb.scalar("train/success", ep, f64::from(u8::from(record.success)))?;
        tb.scalar("train/final_distance_m", ep, record.final_distance_m)?;
        if let Some(c) = record.collision_steps {
            tb.scalar("train/collision_steps", ep, f64::from(c))?;
        }
        if let Some(s) = &end.shield {
            tb.scalar("train/shield_interventions", ep, s.interventions as f64)?;
            tb.scalar("train/shield_stops", ep, s.stops as f64)?;
            tb.scalar("train/shield_mean_change_rad_per_s", ep, s.mean_change_rad_per_s())?;
        }
        if let Some(s) = record.curriculum_stage {
            tb.scalar("train/curriculum_stage", ep, f64::from(s))?;
        }
        if let Some(st) = stats {
            tb.scalar("loss/critic", ep, st.critic_loss)?;
            for (tag, v) in
                [("loss/actor", st.actor_loss), ("sac/alpha", st.alpha), ("sac/entropy", st.entropy)]
            {
                if let Some(v) = v {
                    tb.scalar(tag, ep, v)?;
                }
            }
        }
        Ok(record)
    }

    /// The periodic evaluation of the episode just finished, when due (`state.eval_due`, at an
    /// evaluation point): evaluate the deterministic policy on the `eval_seed` targets, append
    /// the row to `eval.csv`, its TensorBoard scalars, and keep the agent as `best.safetensors`
    /// when it is the best so far (success rate, then mean reward). A stop request ends it with
    /// [`Error::Stopped`], `eval_due` still set.
    fn periodic_eval(
        &mut self,
        tb: &mut EventWriter,
        stop: Option<&AtomicBool>,
    ) -> Result<Option<EvalSummary>> {
        let (train, episode) = (&self.cfg.train, self.state.n.episode);
        if !self.state.eval_due {
            return Ok(None);
        }
        let opts = EvalOptions::new(train.eval_trials, train.eval_seed).stopped_by(stop);
        let (summary, _) =
            evaluate(&mut self.eval_env, &mut Policy(deterministic(self.collector.agent_mut())), &opts)?;
        let point = EvalPoint {
            episode,
            env_steps: self.state.n.env_steps,
            success_rate: summary.success_rate,
            mean_reward: summary.mean_reward,
            mean_steps: summary.mean_steps,
            median_final_distance_m: summary.median_final_distance_m,
        };
        push_row(&mut self.eval_csv, &point);
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

    /// Every `checkpoint_every_episodes` episodes (but the last, which [`Trainer::run`] saves
    /// with the final agent): the full state to `latest.safetensors`, after the event log is
    /// flushed (what the checkpoint has seen is on disk, for the rewind of a resume).
    fn checkpoint(&mut self, record: &EpisodeRecord, tb: &mut EventWriter) -> Result<()> {
        if self.cfg.train.is_checkpoint_point(record.episode, record.env_steps) {
            self.state.wall_s = record.wall_s;
            tb.flush()?;
            self.save_latest()?;
        }
        Ok(())
    }

    fn summary(&self) -> TrainSummary {
        TrainSummary {
            episodes: self.state.n.episode,
            env_steps: self.state.n.env_steps,
            updates: self.state.n.updates,
            wall_s: self.state.wall_s,
            final_checkpoint: self.dir.final_checkpoint(),
        }
    }
}

/// The open logs of a training session.
struct Logs {
    episodes: EpisodeCsv,
    tb: EventWriter,
}

/// Train from scratch into `out` (created if needed; files of a previous run there are replaced,
/// the caller decides whether that is allowed). `on_episode` sees every finished episode.
pub fn train(cfg: &Config, out: &Path, mut on_episode: impl FnMut(&Progress<'_>)) -> Result<TrainSummary> {
    train_with(&cfg.resolve()?, out, &TrainOptions::default(), &mut on_episode)
}

/// [`train`] of a config resolved already ([`Config::resolve`]), with options (a stop flag).
pub fn train_with(
    run: &Resolved,
    out: &Path,
    opts: &TrainOptions<'_>,
    on_episode: &mut dyn FnMut(&Progress<'_>),
) -> Result<TrainSummary> {
    let dir = RunDir::new(out);
    std::fs::create_dir_all(&dir.root).map_err(|e| Error::io(&dir.root, e))?;
    // A new run: nothing of an older one may be mistaken for this run's.
    replace::remove_previous_run(&dir)?;
    crate::io::write_atomic(&dir.config(), run.config().to_toml_string().as_bytes())?;
    Trainer::new(run, dir)?.run(opts, on_episode)
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
    let run = dir.load_config()?.resolve()?;
    let latest = dir.latest();
    if !latest.exists() {
        return train_with(&run, out, opts, on_episode).map(Resumed::Finished);
    }
    let ck = Checkpoint::load(&latest)?;
    // The run's other checkpoints are checked too: a corrupted one is refused, not kept.
    for p in [dir.best(), dir.final_checkpoint()] {
        if p.exists() {
            Checkpoint::load(&p)?;
        }
    }
    let mut t = Trainer::restore(&run, dir, &ck)?;
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
    let st: LoopState = ck.json(TRAIN_STATE)?;
    Ok(Some((st.n.episode, st.finished)))
}
