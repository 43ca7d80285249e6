use anyhow::{bail, Result};
use stagerl::sweep::{self, Preset, RunReport, RunStatus};
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl reproduce --preset quick --out runs/quick --jobs 2")]
pub struct Args {
    /// `smoke`, `quick`, `tuned`, `paper`, `learners`, `learners-long`, `sample-efficiency`, `crossq-rewards` (bundled, see configs/presets/), or a path to a preset TOML file.
    #[arg(long)]
    preset: String,
    /// Output directory: one run directory per algorithm x reward x seed.
    #[arg(long)]
    out: PathBuf,
    /// Runs trained at once (threads, each single-threaded).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Run only the runs whose index is congruent to this modulo --task-count (default, when
    /// set: ($SLURM_ARRAY_TASK_ID - $SLURM_ARRAY_TASK_MIN) / $SLURM_ARRAY_TASK_STEP).
    #[arg(long)]
    task_index: Option<usize>,
    /// Number of shards (default: $SLURM_ARRAY_TASK_COUNT when set, else 1).
    #[arg(long)]
    task_count: Option<usize>,
}

pub fn run(args: Args) -> Result<()> {
    if args.jobs == 0 {
        bail!("--jobs 0: need at least 1");
    }
    let (preset, text) = Preset::resolve(&args.preset)?;
    preset.check_shared()?;
    let (index, count) =
        sweep::resolve_shard(args.task_index, args.task_count, &|name| std::env::var(name).ok())?;
    let runs = sweep::shard(preset.runs(), index, count)?;
    // Check every run first: a refusal writes nothing. preset.toml is written under the sweep's
    // lock, once (left as is when it already holds this text).
    sweep::check_all_existing(&runs, &args.out)?;
    sweep::write_preset(&args.out, &text)?;
    // provenance.json: this session's command, code version, machine and times.
    let argv: Vec<String> = std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect();
    let recorder = stagerl::run::provenance::Recorder::start(&args.out, argv)?;
    let total = runs.len();
    outln!(
        "reproduce `{}`: {} runs in this shard ({} of {}), {} at once -> {}",
        args.preset,
        total,
        index,
        count,
        args.jobs,
        args.out.display()
    )?;
    let stop = crate::run_control::stop_flag()?;
    // A failing standard output stops the sweep as SIGINT does: runs save themselves.
    let output = crate::out::RunOutput::new(Arc::clone(&stop));
    let outcome =
        sweep::run_sweep(&runs, &args.out, &preset.sweep, args.jobs, &stop, &|r| print_run(&output, r));
    let ended = if output.failed().is_some() {
        "stopped: standard output failed".to_string()
    } else if outcome.interrupted || stop.load(std::sync::atomic::Ordering::SeqCst) {
        "interrupted".to_string()
    } else if !outcome.failures.is_empty() {
        format!("{} of {total} runs failed", outcome.failures.len())
    } else {
        format!("finished ({} runs taken by other processes)", outcome.taken)
    };
    recorder.finish(&args.out, &ended)?;
    if let Some(e) = output.failed() {
        bail!("{e}: the sweep stopped; finished runs are kept and interrupted ones saved. Run the same command again to continue.");
    }
    if outcome.interrupted || stop.load(std::sync::atomic::Ordering::SeqCst) {
        // Standard error may be closed too; the exit code still tells.
        let _ = errln!(
            "stagerl: interrupted after {:.0} s; finished runs are kept. Run the same command again to continue.",
            outcome.wall_s
        );
        std::process::exit(i32::from(crate::run_control::INTERRUPTED_EXIT));
    }
    if !outcome.failures.is_empty() {
        bail!("{} of {total} runs failed:\n  {}", outcome.failures.len(), outcome.failures.join("\n  "));
    }
    if outcome.taken > 0 {
        return outln!(
            "{} of {total} runs done here in {:.0} s, {} taken by other processes (they finish there). \
             Once all are done, tables and figures: stagerl report {}",
            total - outcome.taken,
            outcome.wall_s,
            outcome.taken,
            args.out.display()
        );
    }
    outln!(
        "all {total} runs done in {:.0} s. Tables and figures: stagerl report {}",
        outcome.wall_s,
        args.out.display()
    )
}

fn print_run(output: &crate::out::RunOutput, r: &RunReport<'_>) {
    let (n, total, name) = (r.n, r.total, &r.spec.name);
    match r.result {
        Ok(s) => {
            let what = match r.before {
                Some(RunStatus::Done) => "already done".to_string(),
                Some(RunStatus::Partial { episode }) => format!("resumed after episode {episode}, done"),
                Some(RunStatus::Trained) => "trained before, evaluated, done".to_string(),
                Some(RunStatus::StaleEval) => {
                    "re-evaluated (its evaluation had other settings), done".to_string()
                }
                Some(RunStatus::New) | None => "done".to_string(),
            };
            output.line(format_args!(
                "[{n}/{total}] {name}: {what} in {:.0} s: success {:.1} %, mean reward {:.3}, mean steps {}",
                r.wall_s,
                100.0 * s.success_rate,
                s.mean_reward,
                s.mean_steps.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into())
            ));
        }
        Err(stagerl::Error::Interrupted { episode, .. }) => {
            output.line(format_args!("[{n}/{total}] {name}: interrupted after episode {episode}, saved"));
        }
        Err(stagerl::Error::Stopped { .. }) => {
            output.line(format_args!("[{n}/{total}] {name}: interrupted during its evaluation (runs again)"));
        }
        Err(stagerl::Error::Locked { holder, .. }) => {
            let pid = holder.map(|p| format!(" (pid {p})")).unwrap_or_default();
            output.line(format_args!("[{n}/{total}] {name}: taken by another process{pid}, finishes there"));
        }
        Err(e) => output.line(format_args!("[{n}/{total}] {name}: FAILED: {e}")),
    }
}
