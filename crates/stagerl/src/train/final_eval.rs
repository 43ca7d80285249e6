//! A run's closing evaluation (after training, by `train` and `reproduce`) as a recorded state
//! of the run: `eval-final-seed<S>.csv` holds its trials, and `eval-final-seed<S>.json`, written
//! atomically as the very last step, records the settings it was made with. A run is
//! *evaluated* when that record exists; a run killed during its closing evaluation has none, and
//! resuming it (`train --resume`, `reproduce`) runs the evaluation. A record of other settings
//! (trials, seed, checkpoint, config) marks the evaluation stale: `reproduce` runs it again.
//!
//! `stagerl eval` writes elsewhere ([`eval_file_name`]), so it never replaces the file a report
//! reads.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use super::{config_hash, evaluate_until, load_agent, EvalSummary, RunDir};
use crate::config::Config;
use crate::env::ReachEnv;
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
}

/// The per-trial CSV of a run's closing evaluation on the targets of `seed`.
pub fn csv_path(dir: &Path, seed: u64) -> PathBuf {
    dir.join(format!("eval-final-seed{seed}.csv"))
}

/// The record of a run's closing evaluation on the targets of `seed`.
pub fn record_path(dir: &Path, seed: u64) -> PathBuf {
    dir.join(format!("eval-final-seed{seed}.json"))
}

/// The file `stagerl eval` writes: named by the checkpoint (its file stem), the trial count and
/// the seed, so that evaluations of other settings sit side by side.
pub fn eval_file_name(checkpoint: &Path, trials: u32, seed: u64) -> String {
    let stem = checkpoint.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    format!("eval-{stem}-trials{trials}-seed{seed}.csv")
}

/// The recorded closing evaluation on the targets of `seed`, if the run has one (an unreadable
/// record counts as none: the evaluation runs again).
pub fn recorded(dir: &Path, seed: u64) -> Option<FinalEvalRecord> {
    let text = std::fs::read_to_string(record_path(dir, seed)).ok()?;
    serde_json::from_str(&text).ok().filter(|_| csv_path(dir, seed).is_file())
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
    let mut env = ReachEnv::from_config(cfg, 0)?;
    let mut agent = load_agent(cfg, &env, &checkpoint)?;
    let (summary, records) = evaluate_until(agent.as_mut(), &mut env, trials, seed, stop)?;
    // The record goes last: without it the run is not evaluated, whatever else is on disk.
    let _ = std::fs::remove_file(record_path(dir, seed));
    super::eval::write_trials_csv(&csv_path(dir, seed), &records)?;
    let json = serde_json::to_string_pretty(&record).expect("the record serialises");
    crate::io::write_atomic(&record_path(dir, seed), json.as_bytes())?;
    Ok((summary, checkpoint))
}

/// Summarise a run's closing evaluation on the targets of `seed` from its CSV.
pub fn read(dir: &Path, seed: u64) -> Result<EvalSummary> {
    Ok(super::eval::summarize(&super::eval::read_trials_csv(&csv_path(dir, seed))?))
}
