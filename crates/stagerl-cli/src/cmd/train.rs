use anyhow::{bail, Context, Result};
use stagerl::agent::Algo;
use stagerl::reward::RewardFunction;
use stagerl::run::dir::RunDir;
use stagerl::train::{self, final_eval, Resumed, TrainOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::out::RunOutput;
use crate::progress::{print_summary, Reporter};
use crate::run_control::{finish, lock_run, output_ok, stop_flags};

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  stagerl train --algo sac --reward sar --seed 1 --out runs/sac-sar\n  stagerl train --resume runs/sac-sar"
)]
pub struct Args {
    /// Algorithm (overrides agent.algo).
    #[arg(long, value_parser = super::algo_parser())]
    algo: Option<Algo>,
    /// Reward function (overrides reward.function).
    #[arg(long, value_parser = super::reward_parser())]
    reward: Option<RewardFunction>,
    /// Hindsight experience replay with this goal strategy (sets agent.her.strategy, with
    /// agent.her.k from the config or 4).
    #[arg(long, value_parser = ["future", "final", "episode"])]
    her: Option<String>,
    /// Seed (overrides train.seed).
    #[arg(long)]
    seed: Option<u64>,
    /// Training episodes (overrides train.episodes).
    #[arg(long, conflicts_with = "env_steps")]
    episodes: Option<u64>,
    /// Train until this many environment steps instead of an episode count (sets
    /// train.env_steps): the run ends with the episode in which the N-th step falls.
    #[arg(long, value_name = "N")]
    env_steps: Option<u64>,
    /// Evaluate every this many environment steps instead of every train.eval_every_episodes
    /// (sets train.eval_every_env_steps).
    #[arg(long, value_name = "N")]
    eval_every_env_steps: Option<u64>,
    /// Run directory (default: runs/<algo>-<reward>-seed<seed>, with --her
    /// runs/<algo>-<reward>-her-<strategy>-seed<seed>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// A TOML config; defaults otherwise.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Replace a run already in the output directory.
    #[arg(long, conflicts_with = "resume")]
    force: bool,
    /// Continue the run in this directory from its last checkpoint (with its own config); a
    /// trained run without its closing evaluation (killed during it) is evaluated.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["algo", "reward", "her", "seed", "episodes", "env_steps", "eval_every_env_steps", "out", "config"])]
    resume: Option<PathBuf>,
    /// Trials of the closing evaluation (deterministic policy); 0 skips it.
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(0..=10_000_000))]
    eval_trials: u32,
    /// Threads for this run's updates, 1 to 64. The run is the same, bit for bit, on any number
    /// (work is split only into parts that write separate values, see `stagerl::base::par`); wide
    /// networks gain most (hidden 256), hidden 64 less (end to end on two cores: -5 to +40 %,
    /// see docs/performance.md).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    threads: u32,
    /// Filter every command through the safety shield (sets task.shield.enabled; the rest of
    /// `[task.shield]` from the config or its defaults).
    #[arg(long, conflicts_with = "resume")]
    shield: bool,
}

pub fn run(args: Args) -> Result<()> {
    let pool = stagerl::base::par::Pool::new(args.threads as usize)?;
    stagerl::base::par::install(Some(&pool), || run_on_pool(args))
}

fn run_on_pool(args: Args) -> Result<()> {
    if let Some(dir) = &args.resume {
        return resume(dir, args.eval_trials);
    }
    let mut cfg = super::load_config(args.config.as_deref())?;
    if let Some(a) = args.algo {
        cfg.agent.algo = a;
    }
    if let Some(r) = args.reward {
        cfg.reward.function = r;
    }
    if let Some(h) = &args.her {
        let strategy = h.parse::<stagerl::agent::HerStrategy>()?;
        cfg.agent.her = Some(stagerl::agent::HerConfig { strategy, ..cfg.agent.her.unwrap_or_default() });
    }
    if let Some(s) = args.seed {
        cfg.train.seed = s;
    }
    if let Some(e) = args.episodes {
        cfg.train.episodes = e;
    }
    if let Some(n) = args.env_steps {
        cfg.train.env_steps = Some(n);
    }
    if let Some(n) = args.eval_every_env_steps {
        cfg.train.eval_every_env_steps = Some(n);
    }
    if args.shield {
        cfg.task.shield =
            Some(stagerl::sim::shield::ShieldConfig { enabled: true, ..cfg.task.shield.unwrap_or_default() });
    }
    // The config's one check, with the flags applied, and its resolution against the arm.
    let run = cfg.resolve()?;
    // Without --out, the first free runs/<algo>-<reward>-seed<N>[-k]: running the same command
    // again starts a new run beside the old one instead of failing or overwriting it.
    let out = args
        .out
        .unwrap_or_else(|| stagerl::run::dir::first_free(Path::new("runs"), &stagerl::sweep::run_name(&cfg)));
    let dir = RunDir::new(&out);
    let refuse_existing = || -> Result<()> {
        if dir.holds_run() && !args.force {
            stagerl::run::lock::DirLock::check_free(&out)?; // "in use" says more than "exists"
            bail!(
                "{} already holds a run (its config.toml exists): pass --force to replace it, or choose another --out",
                out.display()
            );
        }
        Ok(())
    };
    refuse_existing()?;
    // Hold the run directory's lock from here to the end (a second process fails fast); look
    // again under the lock, another process may have started a run meanwhile.
    let _lock = lock_run(&out)?;
    refuse_existing()?;
    if dir.holds_run() {
        // --force: nothing of the older run may be read as the new one's.
        let removed = train::replace::remove_previous_run(&dir)?;
        outln!("--force: removed the older run's {}", train::replace::describe(&removed))?;
    }
    dir.ensure_writable().with_context(|| format!("the run directory {} is not writable", out.display()))?;

    outln!(
        "training {} with reward {} on `{}`, seed {}, {} -> {}",
        cfg.agent.algo,
        cfg.reward.function,
        cfg.robot.urdf,
        cfg.train.seed,
        match cfg.train.env_steps {
            Some(n) => format!("{n} environment steps"),
            None => format!("{} episodes", cfg.train.episodes),
        },
        out.display()
    )?;
    if let Some(notice) = super::collision_notice(run.chain()) {
        errln!("{notice}")?;
    }
    let (stop, signals) = stop_flags()?;
    let output = RunOutput::new(Arc::clone(&stop));
    let opts = TrainOptions { stop: Some(&stop) };
    let mut reporter = Reporter::new(&cfg.train, &output);
    let summary = finish(train::train_with(&run, &out, &opts, &mut |p| reporter.episode(p)), &out, &output)?;
    reporter.finish();
    print_summary(&summary, &output);
    closing_evaluation(&cfg, &out, args.eval_trials, &signals, &output)?;
    output_ok(&output, &out)
}

fn resume(dir: &std::path::Path, eval_trials: u32) -> Result<()> {
    let run = RunDir::new(dir);
    let cfg = run.load_config().with_context(|| format!("reading the run in {}", dir.display()))?;
    let _lock = lock_run(dir)?;
    match train::checkpointed_episode(dir)? {
        Some((episode, false)) => outln!("resuming {} after episode {episode}", dir.display())?,
        Some((_, true)) => {}
        None => outln!("{} has no checkpoint yet: starting it over", dir.display())?,
    }
    let (stop, signals) = stop_flags()?;
    let output = RunOutput::new(Arc::clone(&stop));
    let opts = TrainOptions { stop: Some(&stop) };
    let mut reporter = Reporter::new(&cfg.train, &output);
    match finish(train::resume(dir, &opts, &mut |p| reporter.episode(p)), dir, &output)? {
        // Trained but never evaluated (killed during its closing evaluation, say): the
        // evaluation runs now.
        Resumed::AlreadyFinished(s)
            if eval_trials > 0 && final_eval::recorded(dir, train::eval::DEFAULT_EVAL_SEED).is_none() =>
        {
            output.line(format_args!(
                "{} already trained ({} episodes) but not evaluated: running its closing evaluation",
                dir.display(),
                s.episodes
            ));
            closing_evaluation(&cfg, dir, eval_trials, &signals, &output)?;
            output_ok(&output, dir)
        }
        Resumed::AlreadyFinished(s) => {
            outln!("{} already finished ({} episodes); nothing to do", dir.display(), s.episodes)
        }
        Resumed::Finished(s) => {
            reporter.finish();
            print_summary(&s, &output);
            closing_evaluation(&cfg, dir, eval_trials, &signals, &output)?;
            output_ok(&output, dir)
        }
    }
}

/// The closing evaluation, recorded as the run's last step (see `train::final_eval`): the
/// checkpoint `stagerl eval` would pick (best, else final), on targets of seed 0, not the
/// `train.eval_seed` targets the best checkpoint was chosen on. A stop ends it (exit 130).
fn closing_evaluation(
    cfg: &stagerl::config::Config,
    out: &Path,
    eval_trials: u32,
    stop: &AtomicBool,
    output: &RunOutput,
) -> Result<()> {
    if eval_trials == 0 {
        return Ok(());
    }
    let seed = train::eval::DEFAULT_EVAL_SEED;
    let (s, checkpoint) = finish(final_eval::run(out, cfg, eval_trials, seed, Some(stop)), out, output)?;
    output.line(format_args!(
        "{} on {eval_trials} new targets (seed {seed}), per-trial CSV {}",
        checkpoint.display(),
        RunDir::new(out).final_eval(seed).display()
    ));
    output.line(format_args!("{}", crate::progress::summary_line(&s, false)));
    Ok(())
}
