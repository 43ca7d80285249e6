use anyhow::{bail, Context, Result};
use stagerl::experiment::{self, Preset, RunSpec, RunStatus};
use stagerl::train::TrainOptions;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
    /// `smoke`, `quick`, `paper` (bundled, see configs/), or a path to a preset TOML file.
    #[arg(long)]
    preset: String,
    /// Output directory: one run directory per algorithm x reward x seed.
    #[arg(long)]
    out: PathBuf,
    /// Runs trained at once (threads, each single-threaded).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Run only the runs whose index is congruent to this modulo --task-count (default:
    /// $SLURM_ARRAY_TASK_ID - $SLURM_ARRAY_TASK_MIN when set).
    #[arg(long)]
    task_index: Option<usize>,
    /// Number of shards (default: $SLURM_ARRAY_TASK_COUNT when set, else 1).
    #[arg(long)]
    task_count: Option<usize>,
}

const BUNDLED: [(&str, &str); 3] = [
    ("smoke", include_str!("../../../../configs/smoke.toml")),
    ("quick", include_str!("../../../../configs/quick.toml")),
    ("paper", include_str!("../../../../configs/paper.toml")),
];

fn load_preset(name: &str) -> Result<(Preset, String)> {
    if let Some((_, text)) = BUNDLED.iter().find(|(n, _)| *n == name) {
        return Ok((
            Preset::from_toml_str(text, Path::new(&format!("configs/{name}.toml")))?,
            text.to_string(),
        ));
    }
    let path = Path::new(name);
    if !path.exists() {
        bail!("preset `{name}`: not one of smoke, quick, paper, and no such file");
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok((Preset::from_toml_str(&text, path)?, text))
}

fn env_usize(name: &str) -> Result<Option<usize>> {
    match std::env::var(name) {
        Ok(v) => {
            Ok(Some(v.trim().parse().with_context(|| format!("${name} = {v:?} is not a whole number"))?))
        }
        Err(_) => Ok(None),
    }
}

/// The shard to run: flags first, then Slurm's job-array variables, else everything.
fn shard_of(args: &Args) -> Result<(usize, usize)> {
    let slurm_index = match (env_usize("SLURM_ARRAY_TASK_ID")?, env_usize("SLURM_ARRAY_TASK_MIN")?) {
        (Some(id), min) => {
            Some(id.checked_sub(min.unwrap_or(0)).context("SLURM_ARRAY_TASK_ID below SLURM_ARRAY_TASK_MIN")?)
        }
        (None, _) => None,
    };
    let index = args.task_index.or(slurm_index).unwrap_or(0);
    let count = match args.task_count.or(env_usize("SLURM_ARRAY_TASK_COUNT")?) {
        Some(c) => c,
        None if index == 0 => 1,
        None => bail!("--task-index {index} needs --task-count"),
    };
    Ok((index, count))
}

pub fn run(args: Args) -> Result<()> {
    if args.jobs == 0 {
        bail!("--jobs 0: need at least 1");
    }
    let (preset, text) = load_preset(&args.preset)?;
    let (index, count) = shard_of(&args)?;
    let runs = experiment::shard(preset.runs(), index, count)?;
    // [runsafe] Check every run first: a refusal writes nothing. preset.toml is written under
    // the sweep's lock, once (left as is when it already holds this text).
    experiment::check_all_existing(&runs, &args.out)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    experiment::write_preset(&args.out, &text)?;
    let total = runs.len();
    println!(
        "reproduce `{}`: {} runs in this shard ({} of {}), {} at once -> {}",
        args.preset,
        total,
        index,
        count,
        args.jobs,
        args.out.display()
    );
    let stop = super::train::stop_flag()?;
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let failures: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let taken = AtomicUsize::new(0);
    let interrupted = AtomicBool::new(false);
    let start = Instant::now();
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.min(total.max(1)) {
            scope.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::SeqCst);
                if k >= total || stop.load(Ordering::SeqCst) {
                    break;
                }
                let spec = &runs[k];
                let t0 = Instant::now();
                let result = one(spec, &args.out, &preset, &stop);
                let n = done.fetch_add(1, Ordering::SeqCst) + 1;
                match result {
                    Ok((before, s)) => {
                        println!("[{n}/{total}] {}: {}", spec.name, done_line(before, &s, t0.elapsed()));
                    }
                    Err(stagerl::Error::Interrupted { episode, .. }) => {
                        interrupted.store(true, Ordering::SeqCst);
                        println!("[{n}/{total}] {}: interrupted after episode {episode}, saved", spec.name);
                    }
                    Err(stagerl::Error::Stopped { .. }) => {
                        interrupted.store(true, Ordering::SeqCst);
                        println!(
                            "[{n}/{total}] {}: interrupted during its evaluation (runs again)",
                            spec.name
                        );
                    }
                    Err(stagerl::Error::Locked { holder, .. }) => {
                        taken.fetch_add(1, Ordering::SeqCst);
                        let pid = holder.map(|p| format!(" (pid {p})")).unwrap_or_default();
                        println!(
                            "[{n}/{total}] {}: taken by another process{pid}, finishes there",
                            spec.name
                        );
                    }
                    Err(e) => {
                        println!("[{n}/{total}] {}: FAILED: {e}", spec.name);
                        failures.lock().expect("no poisoning").push(format!("{}: {e}", spec.name));
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().expect("no poisoning");
    if interrupted.load(Ordering::SeqCst) || stop.load(Ordering::SeqCst) {
        eprintln!(
            "stagerl: interrupted after {:.0} s; finished runs are kept. Run the same command again to continue.",
            start.elapsed().as_secs_f64()
        );
        std::process::exit(i32::from(super::train::INTERRUPTED_EXIT));
    }
    if !failures.is_empty() {
        bail!("{} of {total} runs failed:\n  {}", failures.len(), failures.join("\n  "));
    }
    let taken = taken.into_inner();
    if taken > 0 {
        println!(
            "{} of {total} runs done here in {:.0} s, {taken} taken by other processes (they finish there). \
             Once all are done, tables and figures: stagerl report {}",
            total - taken,
            start.elapsed().as_secs_f64(),
            args.out.display()
        );
        return Ok(());
    }
    println!(
        "all {total} runs done in {:.0} s. Tables and figures: stagerl report {}",
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(())
}

/// What a finished run's line says: what was done, how long it took, its evaluation.
fn done_line(before: RunStatus, s: &stagerl::train::EvalSummary, took: std::time::Duration) -> String {
    let what = match before {
        RunStatus::Done => "already done".to_string(),
        RunStatus::Partial { episode } => format!("resumed after episode {episode}, done"),
        RunStatus::Trained => "trained before, evaluated, done".to_string(),
        RunStatus::StaleEval => "re-evaluated (its evaluation had other settings), done".to_string(),
        RunStatus::New => "done".to_string(),
    };
    format!(
        "{what} in {:.0} s: success {:.1} %, mean reward {:.3}, mean steps {}",
        took.as_secs_f64(),
        100.0 * s.success_rate,
        s.mean_reward,
        s.mean_steps.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into())
    )
}

fn one(
    spec: &RunSpec,
    out: &Path,
    preset: &Preset,
    stop: &Arc<AtomicBool>,
) -> stagerl::Result<(RunStatus, stagerl::train::EvalSummary)> {
    let opts = TrainOptions { stop: Some(stop) };
    experiment::run_one(spec, out, &preset.sweep, &opts, &mut |_| {})
}
