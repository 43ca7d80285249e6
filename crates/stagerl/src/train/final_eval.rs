//! A run's closing evaluation (after training, by `train` and `reproduce`) as a recorded state
//! of the run: `eval-final-seed<S>.csv` holds the trials of the selected checkpoint (best, else
//! final), `eval-final-seed<S>-final-checkpoint.csv` those of the final checkpoint on the same
//! targets (the paper's protocol), and `eval-final-seed<S>.json`, written
//! atomically as the very last step, records the settings it was made with. A run is
//! *evaluated* when that record exists; a run killed during its closing evaluation has none, and
//! resuming it (`train --resume`, `reproduce`) runs the evaluation. A record of other settings
//! (trials, seed, checkpoint, config) marks the evaluation stale: `reproduce` runs it again.
//!
//! `stagerl eval` writes elsewhere ([`RunDir::eval_command`]), so it never replaces the file a
//! report reads.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use super::config_hash;
use super::eval::{deterministic, evaluate, load_run_agent, EvalOptions, EvalSummary};
use crate::config::Config;
use crate::env::Policy;
use crate::io::csv::TrialRecord;
use crate::run::dir::RunDir;
use crate::{Error, Result};

/// What a closing evaluation was made with.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FinalEvalRecord {
    /// The evaluated checkpoint's file name in `checkpoints/` (best, else final, else latest).
    pub checkpoint: String,
    pub trials: u32,
    /// Seed of the evaluation targets.
    pub seed: u64,
    /// [`config_hash`] of the run's config.
    pub config_hash: String,
    /// The stagerl version that evaluated.
    pub version: String,
    /// The final checkpoint was evaluated too (`eval-final-seed<S>-final-checkpoint.csv`): the
    /// paper's protocol evaluates the trained model, the selected (best) checkpoint is ours.
    #[serde(default)]
    pub final_checkpoint: bool,
}

/// The recorded closing evaluation on the targets of `seed`, if the run has one (an unreadable
/// record counts as none: the evaluation runs again).
pub fn recorded(dir: &Path, seed: u64) -> Option<FinalEvalRecord> {
    let run = RunDir::new(dir);
    let text = std::fs::read_to_string(run.final_eval_record(seed)).ok()?;
    serde_json::from_str(&text).ok().filter(|_| run.final_eval(seed).is_file())
}

/// What the closing evaluation of the run in `dir` with `trials` trials on the targets of `seed`
/// would record now; `None` when the run has no checkpoint.
pub fn planned(dir: &Path, cfg: &Config, trials: u32, seed: u64) -> Option<(PathBuf, FinalEvalRecord)> {
    let checkpoint = RunDir::new(dir).best_available_checkpoint()?;
    let record = FinalEvalRecord {
        checkpoint: checkpoint.file_name()?.to_string_lossy().into_owned(),
        trials,
        seed,
        config_hash: config_hash(cfg),
        version: env!("CARGO_PKG_VERSION").to_string(),
        final_checkpoint: RunDir::new(dir).final_checkpoint().is_file(),
    };
    Some((checkpoint, record))
}

/// Whether the run's recorded closing evaluation is the one [`planned`] now (the version that
/// made it is recorded, not compared: a new version does not re-evaluate every run).
pub fn is_current(dir: &Path, cfg: &Config, trials: u32, seed: u64) -> bool {
    match (recorded(dir, seed), planned(dir, cfg, trials, seed)) {
        (Some(r), Some((_, p))) => FinalEvalRecord { version: p.version.clone(), ..r } == p,
        _ => false,
    }
}

/// Whether `dir` holds an *archived* run: trained and evaluated on the targets of `seed` with
/// `trials` trials for the config `cfg`, then stripped of its resumable checkpoint
/// (`checkpoints/latest.safetensors`, which carries the replay buffer: tens of MB for a
/// 10 000-episode run) so that its results can be kept small (the CSVs, the record, and the
/// best and final checkpoints where kept). The record is written after training finished, so
/// it alone shows that the run is complete; nothing needs to train or evaluate it again.
pub fn is_archived(dir: &Path, cfg: &Config, trials: u32, seed: u64) -> bool {
    let run = RunDir::new(dir);
    !run.latest().exists()
        && recorded(dir, seed).is_some_and(|r| r.trials == trials && r.config_hash == config_hash(cfg))
}

/// Run the closing evaluation (stopped between trials by `stop`, with [`Error::Stopped`] and
/// nothing written): the trials' CSV, then the record. Returns the summary and the checkpoint.
pub fn run(
    dir: &Path,
    cfg: &Config,
    trials: u32,
    seed: u64,
    stop: Option<&AtomicBool>,
) -> Result<(EvalSummary, PathBuf)> {
    let (checkpoint, record) = planned(dir, cfg, trials, seed)
        .ok_or_else(|| Error::InvalidInput(format!("{}: trained but no checkpoint", dir.display())))?;
    let run = RunDir::new(dir);
    let opts = EvalOptions::new(trials, seed).stopped_by(stop);
    let (summary, records) = evaluate_checkpoint(&run, cfg, &checkpoint, &opts)?;
    // The final checkpoint on the same targets (the same trials when it is the one selected).
    let final_trials = if !record.final_checkpoint {
        None
    } else if checkpoint == run.final_checkpoint() {
        Some(records.clone())
    } else {
        Some(evaluate_checkpoint(&run, cfg, &run.final_checkpoint(), &opts)?.1)
    };
    // The record goes last: without it the run is not evaluated, whatever else is on disk.
    let _ = std::fs::remove_file(run.final_eval_record(seed));
    crate::io::csv::write_trials_csv(&run.final_eval(seed), &records)?;
    if let Some(t) = &final_trials {
        crate::io::csv::write_trials_csv(&run.final_checkpoint_eval(seed), t)?;
    }
    let json = serde_json::to_string_pretty(&record).expect("the record serialises");
    crate::io::write_atomic(&run.final_eval_record(seed), json.as_bytes())?;
    Ok((summary, checkpoint))
}

/// The deterministic policy of the run's checkpoint `checkpoint`, evaluated.
fn evaluate_checkpoint(
    run: &RunDir,
    cfg: &Config,
    checkpoint: &Path,
    opts: &EvalOptions<'_>,
) -> Result<(EvalSummary, Vec<TrialRecord>)> {
    let (_, mut env, mut agent) = load_run_agent(run, cfg, Some(checkpoint))?;
    let (summary, records) = evaluate(&mut env, &mut Policy(deterministic(agent.as_mut())), opts)?;
    Ok((summary, records))
}
