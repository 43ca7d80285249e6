//! Evaluation: the deterministic policy on random targets (the paper's 500 trials), and the one
//! path that evaluates a run directory's checkpoint and writes its per-trial CSV.

use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::agent::Agent;
use crate::config::Config;
use crate::env::{rollout, Driver, Flow, Outcome, ReachEnv, Scratch, Transition};
use crate::run::dir::RunDir;
use crate::{Error, Result};

use crate::base::math::mean;
use crate::io::csv::{read_trials_csv, write_trials_csv, TrialRecord};

/// Evaluation indicators of one run (the paper's 500 trials): what an evaluation measured.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct EvalSummary {
    pub trials: u32,
    /// Mean eq. 16 reward over all trials.
    pub mean_reward: f64,
    /// Mean steps of the successful trials; `None` when none succeeded.
    #[serde(rename = "mean_steps_success")]
    pub mean_steps: Option<f64>,
    /// Fraction of trials that reached the target, in [0, 1].
    pub success_rate: f64,
    /// Median final distance, metres.
    pub median_final_distance_m: f64,
    /// Mean final distance, metres.
    pub mean_final_distance_m: f64,
    /// Fraction of trials with at least one step in contact (floor, self, obstacle), in [0, 1];
    /// `None` when a trial's file predates contact recording.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub collision_rate: Option<f64>,
}

impl EvalSummary {
    /// The summary of per-trial records; `None` for no trials.
    pub fn of(trials: &[TrialRecord]) -> Option<EvalSummary> {
        if trials.is_empty() {
            return None;
        }
        let rewards: Vec<f64> = trials.iter().map(|t| t.reward).collect();
        let ok: Vec<f64> = trials.iter().filter(|t| t.success).map(|t| f64::from(t.steps)).collect();
        let mut d: Vec<f64> = trials.iter().map(|r| r.final_distance_m).collect();
        d.sort_by(f64::total_cmp);
        let k = d.len();
        let median = if k % 2 == 1 { d[k / 2] } else { 0.5 * (d[k / 2 - 1] + d[k / 2]) };
        Some(EvalSummary {
            trials: trials.len() as u32,
            mean_reward: mean(&rewards)?,
            mean_steps: mean(&ok),
            success_rate: ok.len() as f64 / trials.len() as f64,
            median_final_distance_m: median,
            mean_final_distance_m: mean(&d)?,
            collision_rate: trials
                .iter()
                .map(|t| t.collision_steps.map(|c| u32::from(c > 0)))
                .sum::<Option<u32>>()
                .map(|n| f64::from(n) / trials.len() as f64),
        })
    }
}

/// The largest evaluation asked for at once (its per-trial records are kept in memory).
pub const MAX_EVAL_TRIALS: u32 = 10_000_000;

/// Seed of the evaluation targets of `stagerl train`'s closing evaluation and `stagerl eval`
/// unless told otherwise (differs from `train.eval_seed`, the targets the best checkpoint is
/// chosen on).
pub const DEFAULT_EVAL_SEED: u64 = 0;

/// What an evaluation runs: how many trials, on the targets of which seed, until what stop.
#[derive(Clone, Copy, Debug)]
pub struct EvalOptions<'a> {
    /// Episodes (1 to [`MAX_EVAL_TRIALS`]).
    pub trials: u32,
    /// Seed of the targets: the same seed gives the same targets whatever ran before (the
    /// environment's own target stream is left as it was).
    pub seed: u64,
    /// Once set (by a signal handler, say), the evaluation ends within a step with
    /// [`Error::Stopped`], and nothing of it is returned.
    pub stop: Option<&'a AtomicBool>,
}

impl<'a> EvalOptions<'a> {
    /// `trials` trials on the targets of `seed`, not stoppable.
    pub fn new(trials: u32, seed: u64) -> EvalOptions<'a> {
        EvalOptions { trials, seed, stop: None }
    }

    /// The same, ended early once `stop` is set.
    pub fn stopped_by(self, stop: Option<&'a AtomicBool>) -> EvalOptions<'a> {
        EvalOptions { stop, ..self }
    }
}

/// The deterministic policy of `agent` as a rollout policy (what evaluation and deployment run;
/// [`crate::env::Policy`]`(deterministic(agent))` is its driver); a non-finite action is a numerical fault.
pub fn deterministic(agent: &mut dyn Agent) -> impl FnMut(&ReachEnv, &mut [f32]) -> Result<()> + '_ {
    move |env, action| {
        agent.predict(env.observation(), action);
        match action.iter().position(|a| !a.is_finite()) {
            None => Ok(()),
            Some(i) => Err(Error::NumericalFault(format!(
                "the policy's action[{i}] = {} in evaluation, step {}",
                action[i],
                env.steps() + 1
            ))),
        }
    }
}

/// A driver that also stops its rollout once `stop` is set.
struct UntilStop<'a, 'b, D: ?Sized> {
    driver: &'a mut D,
    stop: Option<&'b AtomicBool>,
}

impl<D: Driver + ?Sized> Driver for UntilStop<'_, '_, D> {
    fn act(&mut self, env: &ReachEnv, action: &mut [f32]) -> Result<()> {
        self.driver.act(env, action)
    }
    fn on_step(&mut self, t: &Transition<'_>) -> Result<Flow> {
        let flow = self.driver.on_step(t)?;
        Ok(if self.stop.is_some_and(|s| s.load(Ordering::SeqCst)) { Flow::Stop } else { flow })
    }
}

/// The one evaluation (as Stable-Baselines3's `evaluate_policy`): `opts.trials` episodes (eq. 16
/// rollouts) of `policy` (an agent's deterministic policy as `Policy(deterministic(agent))`,
/// the Jacobian controller, any [`Driver`]) on the targets of `opts.seed`; the summary and every trial's record. A stop
/// (`opts.stop`, or the driver stopping a rollout with [`Flow::Stop`]) ends it with
/// [`Error::Stopped`], for the caller that owns the stop request to report.
pub fn evaluate<D: Driver + ?Sized>(
    env: &mut ReachEnv,
    policy: &mut D,
    opts: &EvalOptions<'_>,
) -> Result<(EvalSummary, Vec<TrialRecord>)> {
    let trials = opts.trials;
    if trials == 0 || trials > MAX_EVAL_TRIALS {
        return Err(Error::InvalidInput(format!("{trials} evaluation trials: need 1 to {MAX_EVAL_TRIALS}")));
    }
    let saved_rng = env.rng().clone();
    let result = run_trials(env, trials, opts.seed, &mut UntilStop { driver: policy, stop: opts.stop });
    env.set_rng(saved_rng);
    let records = result?;
    let summary = EvalSummary::of(&records).expect("at least one trial");
    Ok((summary, records))
}

/// The trials of [`evaluate`].
fn run_trials(
    env: &mut ReachEnv,
    trials: u32,
    seed: u64,
    driver: &mut impl Driver,
) -> Result<Vec<TrialRecord>> {
    let mut scratch = Scratch::new(env);
    let mut records = Vec::with_capacity(trials as usize);
    for trial in 1..=trials {
        if trial == 1 {
            env.reset_with_seed(seed);
        } else {
            env.reset();
        }
        let (start, target) = (env.distance(), env.target());
        let result = rollout(env, &mut scratch, driver);
        let Outcome::Finished { reward, last } = result.map_err(|e| in_trial(e, trial))? else {
            let what = format!("an evaluation of {trials} trials (after {})", trial - 1);
            return Err(Error::Stopped { what });
        };
        records.push(TrialRecord {
            trial,
            reward,
            steps: env.steps(),
            success: last.reached(),
            start_distance_m: start,
            final_distance_m: env.distance(),
            target: [target.x, target.y, target.z],
            collision_steps: env.collisions_checked().then(|| env.collision_steps()),
        });
    }
    Ok(records)
}

/// A numerical fault names the trial it happened in.
fn in_trial(e: Error, trial: u32) -> Error {
    match e {
        Error::NumericalFault(m) => Error::NumericalFault(format!("{m} of evaluation trial {trial}")),
        other => other,
    }
}

/// The agent of a run directory's checkpoint (`checkpoint`, else the best available one), with
/// an environment for it; the checkpoint's path first.
pub fn load_run_agent(
    run: &RunDir,
    cfg: &Config,
    checkpoint: Option<&Path>,
) -> Result<(PathBuf, ReachEnv, Box<dyn Agent>)> {
    let (path, env, agent, _) = load_run_agent_noting(run, cfg, checkpoint)?;
    Ok((path, env, agent))
}

/// What [`load_run_agent_noting`] loads: the checkpoint's path, an environment, the agent and the
/// config fields changed since training.
pub type NotedAgent = (PathBuf, ReachEnv, Box<dyn Agent>, Vec<super::ConfigChange>);

/// [`load_run_agent`], with the fields of `cfg` that differ from the config the checkpoint was
/// trained with (a `config.toml` edited since, say), for the caller to report: none of them
/// changes the policy's inputs or outputs (such a checkpoint is refused).
pub fn load_run_agent_noting(run: &RunDir, cfg: &Config, checkpoint: Option<&Path>) -> Result<NotedAgent> {
    let checkpoint = match checkpoint {
        Some(c) => c.to_path_buf(),
        None => run.best_available_checkpoint().ok_or_else(|| {
            Error::InvalidInput(format!("{} holds no checkpoint yet", run.checkpoints().display()))
        })?,
    };
    let (env, agent, changes) = super::load_resolved_noting(&cfg.resolve()?, &checkpoint)?;
    Ok((checkpoint, env, agent, changes))
}

/// A trained policy from `path`: a run directory (its best available checkpoint, with its
/// `config.toml`, as [`load_run_agent`]) or a checkpoint file (with the config every checkpoint
/// embeds as its `config` metadata); the checkpoint's path first.
pub fn load_policy(path: &Path) -> Result<(PathBuf, ReachEnv, Box<dyn Agent>)> {
    if path.is_dir() {
        let run = RunDir::new(path);
        return load_run_agent(&run, &run.load_config()?, None);
    }
    let ck = crate::io::checkpoint::Checkpoint::load(path)?;
    let cfg = Config::from_toml_str(ck.meta("config")?, path)?;
    let (env, agent) = super::load_resolved(&cfg.resolve()?, path)?;
    Ok((path.to_path_buf(), env, agent))
}

/// What [`write_command_eval`] did with the per-trial CSV.
use crate::io::Written;

/// Write the per-trial CSV of an evaluation by `stagerl eval`, its own file
/// ([`RunDir::eval_command`], never the closing evaluation a report reads), unless it already
/// holds these results; a file with other results is replaced only with `force`. Returns the file.
///
/// `variant`: how the evaluated task differs from the run's own (`stagerl eval --sim`,
/// `--obstacles-in-path`); the file is [`RunDir::eval_command_in`]'s.
pub fn write_command_eval(
    run: &RunDir,
    checkpoint: &Path,
    records: &[TrialRecord],
    seed: u64,
    variant: crate::run::dir::EvalVariant,
    force: bool,
) -> Result<(PathBuf, Written)> {
    let trials = u32::try_from(records.len()).expect("at most MAX_EVAL_TRIALS trials");
    let csv = run.eval_command_in(checkpoint, trials, seed, variant);
    let written = if !csv.exists() {
        Written::New
    } else if read_trials_csv(&csv).ok().as_deref() == Some(records) {
        return Ok((csv, Written::Unchanged));
    } else if force {
        Written::Replaced
    } else {
        return Err(Error::InvalidInput(format!(
            "{} holds another evaluation of this checkpoint, trial count and seed (the checkpoint \
             changed since?); pass --force to replace it",
            csv.display()
        )));
    };
    write_trials_csv(&csv, records)?;
    Ok((csv, written))
}

/// Summarise a run's closing evaluation on the targets of `seed`.
pub fn read_run_eval(run: &RunDir, seed: u64) -> Result<EvalSummary> {
    let path = run.final_eval(seed);
    EvalSummary::of(&read_trials_csv(&path)?)
        .ok_or_else(|| Error::InvalidInput(format!("{}: holds no trials", path.display())))
}
