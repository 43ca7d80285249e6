//! What every command that writes a run shares: the stop flag raised by SIGINT and SIGTERM, the
//! run directory's lock, and the exit codes and messages of a run that was stopped.

use anyhow::{bail, Context, Result};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::out::RunOutput;

/// Exit code of a run stopped by SIGINT or SIGTERM (after saving it).
pub const INTERRUPTED_EXIT: u8 = 130;

/// A stop flag raised by SIGINT and SIGTERM: the loop then saves the run and returns.
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&flag)).context("installing the signal handler")?;
    }
    Ok(flag)
}

/// The stop flag of training (raised by SIGINT, SIGTERM and a failing output, see
/// [`RunOutput`]) and that of the closing evaluation (signals alone: output that fails after the
/// last episode lets the run finish, evaluation included).
pub fn stop_flags() -> Result<(Arc<AtomicBool>, Arc<AtomicBool>)> {
    Ok((stop_flag()?, stop_flag()?))
}

/// Take the lock of the run directory `dir` (created if needed) for this process.
pub fn lock_run(dir: &Path) -> Result<stagerl::run::lock::DirLock> {
    stagerl::run::lock::DirLock::run(dir)
        .with_context(|| format!("taking the run directory {}", dir.display()))
}

/// Map an interruption to a message and the interrupted exit code; a stop caused by standard
/// output failing (closed pipe, full disk) is an error saying how to resume.
pub fn finish<T>(r: stagerl::Result<T>, dir: &std::path::Path, output: &RunOutput) -> Result<T> {
    match r {
        Err(stagerl::Error::Interrupted { episode, checkpoint }) => {
            let (saved, resume) = (checkpoint.display(), dir.display());
            if let Some(e) = output.failed() {
                bail!(
                    "{e}: the run stopped after episode {episode} and was saved to {saved}. Continue with: stagerl train --resume {resume}"
                );
            }
            // Standard error may be closed too; the exit code still tells.
            let _ = errln!(
                "stagerl: interrupted after episode {episode}; saved to {saved}. Continue with: stagerl train --resume {resume}"
            );
            std::process::exit(i32::from(INTERRUPTED_EXIT));
        }
        Err(e @ stagerl::Error::Stopped { .. }) => {
            let resume = dir.display();
            if let Some(failed) = output.failed() {
                bail!("{failed}: {e}. Continue with: stagerl train --resume {resume}");
            }
            let _ = errln!("stagerl: {e}. Continue with: stagerl train --resume {resume}");
            std::process::exit(i32::from(INTERRUPTED_EXIT));
        }
        other => other.context("training"),
    }
}

/// An error if some output of a run that finished could not be printed.
pub fn output_ok(output: &RunOutput, dir: &std::path::Path) -> Result<()> {
    match output.failed() {
        Some(e) => bail!(
            "{e}: the run in {} finished and its files are complete, but its output was not all printed",
            dir.display()
        ),
        None => Ok(()),
    }
}
