//! Evaluation: the deterministic policy on random targets (the paper's 500 trials).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::agent::Agent;
use crate::env::ReachEnv;
use crate::Result;

/// One evaluation episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrialRecord {
    pub trial: u32,
    /// Eq. 16 episode reward (bonus included).
    pub reward: f64,
    pub steps: u32,
    pub success: bool,
    /// D_PT at the start, metres.
    pub start_distance_m: f64,
    /// D_PT at the end, metres.
    pub final_distance_m: f64,
    /// The target, metres.
    pub target: [f64; 3],
}

/// What an evaluation measured.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct EvalSummary {
    pub trials: u32,
    /// Fraction of trials that reached the target, in [0, 1].
    pub success_rate: f64,
    /// Mean eq. 16 episode reward over all trials.
    pub mean_reward: f64,
    /// Mean steps of the successful trials (`None` when none succeeded).
    pub mean_steps: Option<f64>,
    /// Median final distance, metres.
    pub median_final_distance_m: f64,
    /// Mean final distance, metres.
    pub mean_final_distance_m: f64,
}

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

/// [`evaluate`] that stops before any trial once `stop` is set (a trial lasts at most
/// `task.max_steps` steps), with [`Error::Stopped`](crate::Error::Stopped); the environment's
/// target stream is restored either way.
pub fn evaluate_until(
    agent: &mut dyn Agent,
    env: &mut ReachEnv,
    trials: u32,
    seed: u64,
    stop: Option<&AtomicBool>,
) -> Result<(EvalSummary, Vec<TrialRecord>)> {
    let saved_rng = env.rng().clone();
    let result = run_trials(agent, env, trials, seed, stop);
    env.set_rng(saved_rng);
    result.map(|records| (summarize(&records), records))
}

fn run_trials(
    agent: &mut dyn Agent,
    env: &mut ReachEnv,
    trials: u32,
    seed: u64,
    stop: Option<&AtomicBool>,
) -> Result<Vec<TrialRecord>> {
    if trials > super::MAX_EVAL_TRIALS {
        return Err(crate::Error::InvalidInput(format!(
            "{trials} evaluation trials: at most {}",
            super::MAX_EVAL_TRIALS
        )));
    }
    env.reset_with_seed(seed);
    let mut action = vec![0.0f32; env.act_dim()];
    let mut records = Vec::with_capacity(trials as usize);
    for trial in 0..trials {
        if stop.is_some_and(|s| s.load(Ordering::SeqCst)) {
            return Err(crate::Error::Stopped {
                what: format!("an evaluation of {trials} trials (after {trial})"),
            });
        }
        if trial > 0 {
            env.reset();
        }
        let start = env.distance();
        let target = env.target();
        let mut reward = 0.0;
        let success = loop {
            agent.predict(env.observation(), &mut action);
            if let Some(i) = action.iter().position(|a| !a.is_finite()) {
                return Err(crate::Error::NumericalFault(format!(
                    "the policy's action[{i}] = {} in evaluation trial {}, step {}",
                    action[i],
                    trial + 1,
                    env.steps() + 1
                )));
            }
            let s = env.step(&action)?;
            reward += s.total();
            if s.done() {
                break s.terminated;
            }
        };
        records.push(TrialRecord {
            trial: trial + 1,
            reward,
            steps: env.steps(),
            success,
            start_distance_m: start,
            final_distance_m: env.distance(),
            target: [target.x, target.y, target.z],
        });
    }
    Ok(records)
}

/// Summary statistics of evaluation trials.
pub fn summarize(records: &[TrialRecord]) -> EvalSummary {
    let n = records.len().max(1) as f64;
    let successes: Vec<&TrialRecord> = records.iter().filter(|r| r.success).collect();
    let mut d: Vec<f64> = records.iter().map(|r| r.final_distance_m).collect();
    d.sort_by(f64::total_cmp);
    let median = match d.len() {
        0 => f64::NAN,
        k if k % 2 == 1 => d[k / 2],
        k => 0.5 * (d[k / 2 - 1] + d[k / 2]),
    };
    EvalSummary {
        trials: records.len() as u32,
        success_rate: successes.len() as f64 / n,
        mean_reward: records.iter().map(|r| r.reward).sum::<f64>() / n,
        mean_steps: (!successes.is_empty())
            .then(|| successes.iter().map(|r| f64::from(r.steps)).sum::<f64>() / successes.len() as f64),
        median_final_distance_m: median,
        mean_final_distance_m: d.iter().sum::<f64>() / n,
    }
}

/// The header of the per-trial evaluation CSV.
pub const TRIALS_HEADER: &str =
    "trial,reward,steps,success,start_distance_m,final_distance_m,target_x_m,target_y_m,target_z_m";

/// Write trial records as CSV (atomically).
pub fn write_trials_csv(path: &Path, records: &[TrialRecord]) -> Result<()> {
    let mut s = format!("{TRIALS_HEADER}\n");
    for r in records {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.trial,
            r.reward,
            r.steps,
            u8::from(r.success),
            r.start_distance_m,
            r.final_distance_m,
            r.target[0],
            r.target[1],
            r.target[2]
        ));
    }
    crate::io::write_atomic(path, s.as_bytes())
}

/// Read a per-trial evaluation CSV (written by [`write_trials_csv`]).
pub fn read_trials_csv(path: &Path) -> Result<Vec<TrialRecord>> {
    let text = std::fs::read_to_string(path).map_err(|e| crate::Error::io(path, e))?;
    let mut lines = text.lines();
    if lines.next().map(str::trim_end) != Some(TRIALS_HEADER) {
        return Err(crate::Error::InvalidInput(format!(
            "{}: expected the header {TRIALS_HEADER:?}",
            path.display()
        )));
    }
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let bad = || crate::Error::InvalidInput(format!("{}: malformed row {line:?}", path.display()));
            let f: Vec<&str> = line.trim_end().split(',').collect();
            if f.len() != 9 {
                return Err(bad());
            }
            let num = |i: usize| f[i].parse::<f64>().map_err(|_| bad());
            Ok(TrialRecord {
                trial: f[0].parse().map_err(|_| bad())?,
                reward: num(1)?,
                steps: f[2].parse().map_err(|_| bad())?,
                success: match f[3] {
                    "1" => true,
                    "0" => false,
                    _ => return Err(bad()),
                },
                start_distance_m: num(4)?,
                final_distance_m: num(5)?,
                target: [num(6)?, num(7)?, num(8)?],
            })
        })
        .collect()
}
