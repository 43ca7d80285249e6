use anyhow::{bail, Context, Result};
use stagerl::env::ReachEnv;
use stagerl::train::{self, evaluate_until, final_eval, EvalSummary, RunDir, TrialRecord};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// The run directory (holds config.toml and checkpoints/).
    #[arg(long)]
    run: PathBuf,
    /// Checkpoint to evaluate (default: the run's best, else final, else latest).
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// Random targets (1 to 10 000 000; every trial's record is kept for the CSV).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    trials: u32,
    /// Seed of the targets.
    #[arg(long, default_value_t = DEFAULT_SEED)]
    seed: u64,
    /// Print one JSON line instead of text.
    #[arg(long)]
    json: bool,
    /// Replace an existing evaluation file of the same checkpoint, trials and seed that holds
    /// other results (an identical one is left as is).
    #[arg(long)]
    force: bool,
}

/// Seed of the evaluation targets unless told otherwise (differs from `train.eval_seed`, the
/// targets the best checkpoint is chosen on).
pub const DEFAULT_SEED: u64 = 0;

pub fn run(args: Args) -> Result<()> {
    let dir = RunDir::new(&args.run);
    let cfg = dir.load_config().with_context(|| format!("reading the run in {}", args.run.display()))?;
    let checkpoint = match args.checkpoint {
        Some(c) => c,
        None => dir
            .best_available_checkpoint()
            .with_context(|| format!("{} holds no checkpoint yet", dir.checkpoints().display()))?,
    };
    let mut env = ReachEnv::from_config(&cfg, 0)?;
    let mut agent = train::load_agent(&cfg, &env, &checkpoint)?;
    let _lock = super::train::lock_run(&args.run)?; // [runsafe] it writes into the run
                                                    // [runsafe] Its own file, named by checkpoint, trials and seed: never the closing evaluation
                                                    // (eval-final-seed<N>.csv) a report reads.
    let csv = args.run.join(final_eval::eval_file_name(&checkpoint, args.trials, args.seed));
    let stop = super::train::stop_flag()?;
    let (s, trials) = match evaluate_until(agent.as_mut(), &mut env, args.trials, args.seed, Some(&stop)) {
        Err(e @ stagerl::Error::Stopped { .. }) => {
            eprintln!("stagerl: {e}");
            std::process::exit(i32::from(super::train::INTERRUPTED_EXIT));
        }
        other => other?,
    };
    let what = write_evaluation(&csv, &trials, args.force)?;
    if !args.json {
        println!(
            "{} on {} trials (seed {}), per-trial CSV {} ({what})",
            checkpoint.display(),
            args.trials,
            args.seed,
            csv.display()
        );
    }
    print_summary(&s, args.json);
    Ok(())
}

/// Write the per-trial CSV unless `csv` already holds these results; an existing file with other
/// results is replaced only with `force`.
fn write_evaluation(csv: &Path, trials: &[TrialRecord], force: bool) -> Result<&'static str> {
    if csv.exists() {
        let old = train::eval::read_trials_csv(csv).ok();
        if old.as_deref() == Some(trials) {
            return Ok("unchanged: the same results");
        }
        if !force {
            bail!(
                "{} holds another evaluation of this checkpoint, trial count and seed (the checkpoint \
                 changed since?); pass --force to replace it",
                csv.display()
            );
        }
        train::eval::write_trials_csv(csv, trials)?;
        return Ok("replaced (--force)");
    }
    train::eval::write_trials_csv(csv, trials)?;
    Ok("written")
}

pub fn print_summary(s: &EvalSummary, json: bool) {
    if json {
        println!(
            "{}",
            serde_json::json!({
                "success_rate": s.success_rate,
                "mean_reward": s.mean_reward,
                "mean_steps": s.mean_steps,
                "trials": s.trials,
                "median_final_distance_m": s.median_final_distance_m,
            })
        );
    } else {
        println!(
            "evaluation: success {:.1} % of {} trials, mean episode reward {:.3}, mean steps (successful) {}, median final distance {:.4} m",
            100.0 * s.success_rate,
            s.trials,
            s.mean_reward,
            s.mean_steps.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into()),
            s.median_final_distance_m
        );
    }
}
