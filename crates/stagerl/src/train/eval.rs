//! Evaluation: the deterministic policy on random targets (the paper's 500 trials), and the one
//! path that evaluates a run directory's checkpoint and writes its per-trial CSV.

use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::agent::Agent;
use crate::config::Config;
use crate::env::{rollout, Driver, Flow, Observed, Outcome, ReachEnv, Scratch, Transition};
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

/// Run `trials` episodes of `agent`'s deterministic policy. The environment's target stream is
/// reseeded with `seed`, so the same seed gives the same targets whatever ran before.
pub fn evaluate(
    agent: &mut dyn Agent,
    env: &mut ReachEnv,
    trials: u32,
    seed: u64,
) -> Result<(EvalSummary, Vec<TrialRecord>)> {
    evaluate_until(agent, env, trials, seed, None)
}

/// [`evaluate`] that a stop request (`stop` set) ends within a step, with [`Error::Stopped`]
/// (the environment's target stream is restored either way).
pub fn evaluate_until(
    agent: &mut dyn Agent,
    env: &mut ReachEnv,
    trials: u32,
    seed: u64,
    stop: Option<&AtomicBool>,
) -> Result<(EvalSummary, Vec<TrialRecord>)> {
    evaluate_with(env, trials, seed, &mut Observed(deterministic(agent), stop_when(stop)))
}

/// A rollout observer that stops the rollout ([`Flow::Stop`]) once `stop` is set.
pub fn stop_when(stop: Option<&AtomicBool>) -> impl FnMut(&Transition<'_>) -> Result<Flow> + '_ {
    move |_| Ok(if stop.is_some_and(|s| s.load(Ordering::SeqCst)) { Flow::Stop } else { Flow::Continue })
}

/// The deterministic policy of `agent` as a rollout policy; a non-finite action is a
/// numerical fault.
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

/// Run `trials` episodes (eq. 16 rollouts) of `driver` on the targets of `seed` (the
/// environment's own target stream is left as it was). A driver that stops a rollout
/// ([`Flow::Stop`], on a stop request) ends the evaluation with [`Error::Stopped`], for the
/// caller that owns the stop request to report; nothing of it is returned.
pub fn evaluate_with(
    env: &mut ReachEnv,
    trials: u32,
    seed: u64,
    driver: &mut impl Driver,
) -> Result<(EvalSummary, Vec<TrialRecord>)> {
    if trials == 0 || trials > MAX_EVAL_TRIALS {
        return Err(Error::InvalidInput(format!("{trials} evaluation trials: need 1 to {MAX_EVAL_TRIALS}")));
    }
    let saved_rng = env.rng().clone();
    let result = run_trials(env, trials, seed, driver);
    env.set_rng(saved_rng);
    let records = result?;
    let summary = EvalSummary::of(&records).expect("at least one trial");
    Ok((summary, records))
}

/// The trials of [`evaluate_with`].
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
            collision_steps: Some(env.collision_steps()),
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
    let checkpoint = match checkpoint {
        Some(c) => c.to_path_buf(),
        None => run.best_available_checkpoint().ok_or_else(|| {
            Error::InvalidInput(format!("{} holds no checkpoint yet", run.checkpoints().display()))
        })?,
    };
    let env = ReachEnv::from_config(cfg, 0)?;
    let agent = super::load_agent(cfg, &env, &checkpoint)?;
    Ok((checkpoint, env, agent))
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
    let env = ReachEnv::from_config(&cfg, 0)?;
    let agent = super::load_agent(&cfg, &env, path)?;
    Ok((path.to_path_buf(), env, agent))
}

/// What [`evaluate_run`] found.
#[derive(Clone, Debug)]
pub struct RunEval {
    /// The checkpoint evaluated.
    pub checkpoint: PathBuf,
    pub summary: EvalSummary,
    /// Every trial, for the per-trial CSV.
    pub trials: Vec<TrialRecord>,
}

/// Evaluate a run directory's checkpoint (`checkpoint`, else the best available: best, final,
/// latest) on `trials` targets of `seed`, stopped by `stop` ([`Error::Stopped`]). Writes
/// nothing: the closing evaluation ([`super::final_eval::run`]) and `stagerl eval`
/// ([`write_command_eval`]) write their own files.
pub fn evaluate_run(
    run: &RunDir,
    cfg: &Config,
    checkpoint: Option<&Path>,
    trials: u32,
    seed: u64,
    stop: Option<&AtomicBool>,
) -> Result<RunEval> {
    evaluate_loaded(load_run_agent(run, cfg, checkpoint)?, trials, seed, stop)
}

/// The evaluation of [`evaluate_run`] on an agent [`load_run_agent`] loaded (for a caller that
/// has something to do between the two, such as taking the run's lock once the agent is known
/// to load).
pub fn evaluate_loaded(
    (checkpoint, mut env, mut agent): (PathBuf, ReachEnv, Box<dyn Agent>),
    trials: u32,
    seed: u64,
    stop: Option<&AtomicBool>,
) -> Result<RunEval> {
    let (summary, trials) = evaluate_until(agent.as_mut(), &mut env, trials, seed, stop)?;
    Ok(RunEval { checkpoint, summary, trials })
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
    e: &RunEval,
    seed: u64,
    variant: crate::run::dir::EvalVariant,
    force: bool,
) -> Result<(PathBuf, Written)> {
    let trials = u32::try_from(e.trials.len()).expect("at most MAX_EVAL_TRIALS trials");
    let csv = run.eval_command_in(&e.checkpoint, trials, seed, variant);
    let written = if !csv.exists() {
        Written::New
    } else if read_trials_csv(&csv).ok().as_deref() == Some(&e.trials[..]) {
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
    write_trials_csv(&csv, &e.trials)?;
    Ok((csv, written))
}

/// Summarise a run's closing evaluation on the targets of `seed`.
pub fn read_run_eval(run: &RunDir, seed: u64) -> Result<EvalSummary> {
    let path = run.final_eval(seed);
    EvalSummary::of(&read_trials_csv(&path)?)
        .ok_or_else(|| Error::InvalidInput(format!("{}: holds no trials", path.display())))
}
