//! The off-policy collector (DDPG, TD3, SAC; the paper's Algorithm 1): one environment, a step at
//! a time: explore (uniform actions before `learning_starts`, then the agent's exploring
//! policy), store the transition in the replay buffer, then `updates_per_step` updates on sampled
//! batches; with `agent.her`, the episode's relabelled transitions join the buffer when it ends.
//!
//! Everything it holds (the environment mid-episode, the buffer, the random streams, the updates
//! left of a step a stop interrupted, HER's episode log) is saved in `latest.safetensors`, so a
//! resumed run is bit-identical to an uninterrupted one. A stop is honoured between two updates.

use serde::{Deserialize, Serialize};
use std::path::Path;

use super::demonstrations::{self, DemoStats};
use super::her::{HerState, Relabeller};
use super::{Collector, Counters, EpisodeEnd};
use crate::agent::replay::{Batch, ReplayBuffer};
use crate::agent::{Agent, AgentConfig, OffPolicy, UpdateStats};
use crate::base::rng::Rng;
use crate::config::curriculum::StageAdvance;
use crate::config::{Config, CurriculumConfig, CurriculumState, DemonstrationsConfig};
use crate::env::{rollout, Driver, EnvState, Flow, Outcome, ReachEnv, Scratch, Step, Transition};
use crate::io::checkpoint::Checkpoint;
use crate::{Error, Result};

/// The collector's saved state (the replay buffer's arrays are tensors beside it). Its fields are
/// those of the training state of every earlier version, so older checkpoints resume.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct OffPolicyState {
    /// A checkpoint taken mid-episode: the episode `episode + 1` is under way.
    in_episode: bool,
    /// The eq. 16 reward of the episode under way so far.
    episode_reward: f64,
    env: EnvState,
    replay_rng: Rng,
    warmup_rng: Rng,
    replay_len: usize,
    replay_pos: usize,
    /// Transitions kept for good at the buffer's start (`train.demonstrations`).
    #[serde(default, skip_serializing_if = "is_zero")]
    replay_protected: usize,
    /// A stop came between the updates of this environment step: they go on first.
    #[serde(default)]
    step_under_way: Option<StepUnderWay>,
    /// Hindsight relabelling (`agent.her`): the episode under way and the goal sampler.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    her: Option<HerState>,
    /// The obstacle curriculum (`train.curriculum`): the stage and its window of outcomes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    curriculum: Option<CurriculumState>,
    /// `train.demonstrations`: what was stored, once it was (before the first episode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    demonstrations: Option<DemoStats>,
}

/// An environment step taken whose updates are not all done yet; once they are, what the
/// episode's end needs of it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct StepUnderWay {
    /// Updates of this step still to do.
    updates_left: u32,
    /// The target was reached (older checkpoints: `terminated`, which meant the same).
    #[serde(alias = "terminated")]
    reached: bool,
    done: bool,
    /// D_PT after the step, metres, as `f64::to_bits` (exact through JSON).
    final_distance_m_bits: u64,
}

impl StepUnderWay {
    /// The step `step` with `updates_left` updates to do.
    fn of(step: &Step, updates_left: u32) -> StepUnderWay {
        StepUnderWay {
            updates_left,
            reached: step.reached(),
            done: step.done(),
            final_distance_m_bits: step.terms.distance.to_bits(),
        }
    }
}

/// The off-policy agent, its training environment and its replay buffer.
pub(super) struct OffPolicyCollector {
    agent: Box<dyn OffPolicy>,
    env: ReachEnv,
    scratch: Scratch,
    buffer: ReplayBuffer,
    batch: Batch,
    /// The `[agent]` section (`her`: hindsight relabelling's settings).
    cfg: AgentConfig,
    /// The `[train.curriculum]` section, if any.
    curriculum: Option<CurriculumConfig>,
    /// The `[train.demonstrations]` section and the environment they are planned in (the
    /// training one as the task makes it), until they are stored.
    demonstrations: Option<(DemonstrationsConfig, ReachEnv)>,
    seed: u64,
    relabeller: Relabeller,
    state: OffPolicyState,
}

impl OffPolicyCollector {
    /// The collector of run `cfg`: `agent` trained on `env` (obstacles placed in the way as
    /// `train.obstacles_in_path` says, or as the first stage of `train.curriculum`), its random
    /// streams drawn from the run's seed.
    pub(super) fn new(
        cfg: &Config,
        mut env: ReachEnv,
        agent: Box<dyn OffPolicy>,
    ) -> Result<OffPolicyCollector> {
        let seed = cfg.train.seed;
        let curriculum = cfg.train.curriculum.clone();
        let demonstrations = cfg.train.demonstrations.clone().map(|d| (d, env.clone()));
        match &curriculum {
            Some(c) => apply_stage(c, 0, &mut env)?,
            None => env.set_obstacles_in_path(cfg.train.obstacles_in_path)?,
        }
        let (od, ad) = (env.obs_dim(), env.act_dim());
        Ok(OffPolicyCollector {
            agent,
            scratch: Scratch::new(&env),
            buffer: ReplayBuffer::new(cfg.agent.buffer_size, od, ad)?,
            batch: Batch::new(cfg.agent.batch_size, od, ad),
            cfg: cfg.agent.clone(),
            relabeller: Relabeller::default(),
            curriculum,
            demonstrations,
            seed,
            state: OffPolicyState {
                in_episode: false,
                episode_reward: 0.0,
                env: env.state(),
                replay_rng: Rng::derived(seed, 1),
                warmup_rng: Rng::derived(seed, 2),
                replay_len: 0,
                replay_pos: 0,
                replay_protected: 0,
                step_under_way: None,
                her: cfg.agent.her.map(|_| HerState::new(Rng::derived(seed, 4))),
                curriculum: cfg.train.curriculum.as_ref().map(|_| CurriculumState::default()),
                demonstrations: None,
            },
            env,
        })
    }

    /// Collect a step at a time until the episode under way (or a new one) ends: the eq. 16
    /// rollout of the exploring agent, storing every transition and updating after each step
    /// (first the updates left of a step a stop interrupted). `None` when a stop request left
    /// it unfinished.
    fn collect_episode(
        &mut self,
        n: &mut Counters,
        last_stats: &mut Option<UpdateStats>,
        stop_requested: &dyn Fn() -> bool,
    ) -> Result<Option<StepUnderWay>> {
        let steps = self.env.steps();
        let mut explorer = Explorer {
            agent: self.agent.as_mut(),
            buffer: &mut self.buffer,
            batch: &mut self.batch,
            state: &mut self.state,
            n,
            cfg: &self.cfg,
            last_stats,
            stop_requested,
        };
        if let Some(step) = explorer.state.step_under_way.take() {
            if !explorer.update(step, steps)? {
                return Ok(None);
            }
            if step.done {
                return Ok(Some(step));
            }
        }
        if !explorer.state.in_episode {
            self.env.reset();
            if let Some(her) = &mut explorer.state.her {
                her.log.begin(self.env.ee_pose().position);
            }
            explorer.agent.begin_episode();
            explorer.state.episode_reward = 0.0;
            explorer.state.in_episode = true;
        }
        match rollout(&mut self.env, &mut self.scratch, &mut explorer)? {
            // A stop between the last step's updates leaves them (and the episode's end) to do.
            Outcome::Finished { .. } if explorer.state.step_under_way.is_some() => Ok(None),
            Outcome::Finished { last, .. } => Ok(Some(StepUnderWay::of(&last, 0))),
            Outcome::Stopped => Ok(None),
        }
    }

    /// With `agent.her`: store the relabelled transitions of the episode just ended.
    fn relabel_episode(&mut self) {
        let (Some(cfg), Some(her)) = (self.cfg.her, self.state.her.as_mut()) else {
            return;
        };
        let buffer = &mut self.buffer;
        let (task, reward) = (self.env.task(), self.env.reward_config());
        self.relabeller.relabel(&cfg, task, reward, &her.log, &mut her.rng, |x| {
            buffer.push(x.obs, x.action, x.terms.total, x.next_obs, x.terminal)
        });
        her.log.begin(self.env.ee_pose().position);
    }
}

impl Collector for OffPolicyCollector {
    fn agent(&self) -> &dyn Agent {
        self.agent.as_ref()
    }

    fn agent_mut(&mut self) -> &mut dyn Agent {
        self.agent.as_mut()
    }

    fn next_episode(
        &mut self,
        n: &mut Counters,
        last_stats: &mut Option<UpdateStats>,
        stop_requested: &dyn Fn() -> bool,
    ) -> Result<Option<EpisodeEnd>> {
        let demonstrated = self.demonstrate()?;
        let Some(last) = self.collect_episode(n, last_stats, stop_requested)? else {
            return Ok(None);
        };
        self.relabel_episode();
        self.state.in_episode = false;
        let (curriculum_stage, advance) = self.next_stage(last.reached)?;
        Ok(Some(EpisodeEnd {
            reward: self.state.episode_reward,
            steps: self.env.steps(),
            success: last.reached,
            final_distance_m: f64::from_bits(last.final_distance_m_bits),
            collision_steps: self.env.collisions_checked().then(|| self.env.collision_steps()),
            shield: self.env.episode_shield_stats(),
            curriculum_stage,
            advance,
            demonstrations: demonstrated,
        }))
    }

    fn mid_episode(&self) -> bool {
        self.state.in_episode
    }

    fn save(&mut self, ck: &mut Checkpoint) -> serde_json::Value {
        self.state.env = self.env.state();
        self.state.replay_len = self.buffer.len();
        self.state.replay_pos = self.buffer.position();
        self.state.replay_protected = self.buffer.protected();
        for (name, data) in self.buffer.arrays() {
            ck.put_tensor(name, &[data.len()], data);
        }
        serde_json::to_value(&self.state).expect("the state serialises")
    }

    fn restore(&mut self, ck: &Checkpoint, path: &Path) -> Result<()> {
        let state: OffPolicyState = ck.json(super::TRAIN_STATE)?;
        if state.her.is_some() != self.cfg.her.is_some() {
            return Err(Error::InvalidInput(format!(
                "{}: its training state {} hindsight relabelling, the run's config (agent.her) {}",
                path.display(),
                if state.her.is_some() { "has" } else { "lacks" },
                if self.cfg.her.is_some() { "sets it" } else { "does not" }
            )));
        }
        let data: Vec<&[f32]> =
            ReplayBuffer::ARRAY_NAMES.iter().map(|n| ck.tensor(n).map(|(_, d)| d)).collect::<Result<_>>()?;
        self.buffer.restore(
            state.replay_len,
            state.replay_pos,
            [data[0], data[1], data[2], data[3], data[4]],
        )?;
        self.buffer.set_protected(state.replay_protected)?;
        self.env.restore(&state.env)?;
        self.state = state;
        self.restore_stage(path)
    }
}

impl OffPolicyCollector {
    /// With `train.demonstrations`, before the first episode: plan and store them (once; a
    /// resumed run has them in its buffer already). What they gave, when they were stored now.
    fn demonstrate(&mut self) -> Result<Option<DemoStats>> {
        if self.state.demonstrations.is_some() {
            return Ok(None);
        }
        let Some((cfg, env)) = self.demonstrations.take() else {
            return Ok(None);
        };
        let stats = demonstrations::demonstrate(&cfg, self.seed, env, self.agent.as_mut(), &mut self.buffer)?;
        // Kept for good, as DDPGfD keeps them: the ring overwrites only what comes after.
        self.buffer.protect_filled()?;
        self.state.demonstrations = Some(stats);
        Ok(Some(stats))
    }

    /// With `train.curriculum`: count the episode just ended (`success`) and, when the stage
    /// changes, set the environment to the next one from the next episode on. The stage the
    /// episode was played at, and the change.
    fn next_stage(&mut self, success: bool) -> Result<(Option<u32>, Option<StageAdvance>)> {
        let (Some(cfg), Some(state)) = (&self.curriculum, self.state.curriculum.as_mut()) else {
            return Ok((None, None));
        };
        let played = state.stage as u32;
        let advance = state.record(cfg, success);
        if let Some(a) = advance {
            apply_stage(cfg, a.stage, &mut self.env)?;
        }
        Ok((Some(played), advance))
    }

    /// After a restore: the stage saved, checked against the config, set on the environment.
    fn restore_stage(&mut self, path: &Path) -> Result<()> {
        let stage = self.state.curriculum.as_ref().map(|c| c.stage);
        match (&self.curriculum, stage) {
            (None, None) => Ok(()),
            (Some(cfg), Some(stage)) if stage < cfg.stages() => apply_stage(cfg, stage, &mut self.env),
            (cfg, stage) => Err(Error::InvalidInput(format!(
                "{}: its training state has {}, the run's config (train.curriculum) {}",
                path.display(),
                stage.map_or("no curriculum stage".into(), |s| format!("curriculum stage {s}")),
                cfg.as_ref().map_or("none".into(), |c| format!("{} stages", c.stages()))
            ))),
        }
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Set `env` to stage `stage` of curriculum `cfg` (from its next episode on).
fn apply_stage(cfg: &CurriculumConfig, stage: usize, env: &mut ReachEnv) -> Result<()> {
    let (in_path, max_obstacles) = cfg.stage(stage);
    env.set_obstacles_in_path(in_path)?;
    env.set_max_random_obstacles(max_obstacles)
}

/// Algorithm 1 at each step of a training episode: explore (uniform actions before
/// `learning_starts`, then the agent's exploring policy), store the transition, update.
struct Explorer<'a> {
    agent: &'a mut dyn OffPolicy,
    buffer: &'a mut ReplayBuffer,
    batch: &'a mut Batch,
    state: &'a mut OffPolicyState,
    n: &'a mut Counters,
    cfg: &'a AgentConfig,
    last_stats: &'a mut Option<UpdateStats>,
    stop_requested: &'a dyn Fn() -> bool,
}

impl Explorer<'_> {
    fn check_loss(&self, what: &str, v: Option<f64>, steps: u32) -> Result<()> {
        match v {
            Some(v) if !v.is_finite() => Err(Error::NumericalFault(format!(
                "{what} = {v} at episode {}, step {steps} (update {}); the last good checkpoint is left in place",
                self.n.episode + 1,
                self.n.updates
            ))),
            _ => Ok(()),
        }
    }

    /// The updates left of `step` (the environment's step `steps` of the episode). A stop
    /// request between two updates keeps the step under way in the state and returns `false`
    /// (many `updates_per_step` do not delay a stop).
    fn update(&mut self, mut step: StepUnderWay, steps: u32) -> Result<bool> {
        while step.updates_left > 0 {
            if (self.stop_requested)() {
                self.state.step_under_way = Some(step);
                return Ok(false);
            }
            self.buffer.sample_into(&mut self.state.replay_rng, self.batch);
            let stats = self.agent.update(self.batch);
            self.n.updates += 1;
            step.updates_left -= 1;
            self.check_loss("critic loss", Some(stats.critic_loss), steps)?;
            self.check_loss("actor loss", stats.actor_loss, steps)?;
            *self.last_stats = Some(stats);
        }
        Ok(true)
    }
}

impl Driver for Explorer<'_> {
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()> {
        // `agent.norm_obs`: every observation collected, the warm-up's included, joins the
        // statistics (never the replay samples).
        self.agent.observe(env.observation());
        if self.n.env_steps < self.cfg.learning_starts {
            for a in action.iter_mut() {
                *a = self.state.warmup_rng.uniform_range(-1.0, 1.0) as f32;
            }
            return Ok(());
        }
        self.agent.act(env.observation(), action);
        match action.iter().position(|a| !a.is_finite()) {
            None => Ok(()),
            Some(i) => Err(Error::NumericalFault(format!(
                "the actor's action[{i}] = {} at episode {}, step {} (update {}); \
                 the last good checkpoint is left in place",
                action[i],
                self.n.episode + 1,
                env.steps() + 1,
                self.n.updates
            ))),
        }
    }

    fn on_step(&mut self, t: &Transition<'_>) -> Result<Flow> {
        let reward = t.step.total();
        self.state.episode_reward += reward;
        self.buffer.push(t.obs, t.action, reward, t.env.observation(), t.step.terminated);
        if let Some(her) = &mut self.state.her {
            her.log.push(t);
        }
        self.n.env_steps += 1;
        let learning = self.n.env_steps >= self.cfg.learning_starts;
        let step = StepUnderWay::of(t.step, if learning { self.cfg.updates_per_step } else { 0 });
        let finished = self.update(step, t.env.steps())?;
        Ok(if !finished || (self.stop_requested)() { Flow::Stop } else { Flow::Continue })
    }
}
