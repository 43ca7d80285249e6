//! Evaluation: the deterministic policy on random targets (the paper's 500 trials), and the one
//! path that evaluates a run directory's checkpoint and writes its per-trial CSV.

use std::path::{Path, PathBuf};

use crate::agent::Agent;
use crate::config::Config;
use crate::env::{rollout, Driver, Outcome, Policy, ReachEnv, Scratch};
use crate::rundir::RunDir;
use crate::{Error, Result};

pub use crate::log::csv::{read_trials_csv, write_trials_csv, TrialRecord};
pub use crate::metrics::EvalSummary;

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
    evaluate_with(env, trials, seed, &mut Policy(deterministic(agent)))
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
/// ([`crate::env::Flow::Stop`]) ends the evaluation with [`Error::Interrupted`] (episode 0, no
/// checkpoint), for the caller that owns the stop request to report.
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
            return Err(Error::Interrupted { episode: 0, checkpoint: PathBuf::new() });
        };
        records.push(TrialRecord {
            trial,
            reward,
            steps: env.steps(),
            success: last.terminated,
            start_distance_m: start,
            final_distance_m: env.distance(),
            target: [target.x, target.y, target.z],
        });
    }
    env.set_rng(saved_rng);
    let summary = EvalSummary::of(&records).expect("at least one trial");
    Ok((summary, records))
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

/// What [`evaluate_run`] did.
#[derive(Clone, Debug)]
pub struct RunEval {
    /// The checkpoint evaluated.
    pub checkpoint: PathBuf,
    pub summary: EvalSummary,
    /// The per-trial CSV written.
    pub csv: PathBuf,
}

/// Evaluate a run directory's checkpoint (`checkpoint`, else the best available: best, final,
/// latest) on `trials` targets of `seed` and write the per-trial CSV, `eval-seed<seed>.csv`.
pub fn evaluate_run(
    run: &RunDir,
    cfg: &Config,
    checkpoint: Option<&Path>,
    trials: u32,
    seed: u64,
) -> Result<RunEval> {
    let (checkpoint, mut env, mut agent) = load_run_agent(run, cfg, checkpoint)?;
    let (summary, records) = evaluate(agent.as_mut(), &mut env, trials, seed)?;
    let csv = run.trial_eval(seed);
    write_trials_csv(&csv, &records)?;
    Ok(RunEval { checkpoint, summary, csv })
}

/// Summarise a run's per-trial evaluation on the targets of `seed`.
pub fn read_run_eval(run: &RunDir, seed: u64) -> Result<EvalSummary> {
    let path = run.trial_eval(seed);
    EvalSummary::of(&read_trials_csv(&path)?)
        .ok_or_else(|| Error::InvalidInput(format!("{}: holds no trials", path.display())))
}
