use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use stagerl::agent::Algo;
use stagerl::reward::RewardFunction;
use stagerl::run::dir::RunDir;
use stagerl::train::{self, final_eval, Progress, Resumed, TrainOptions};
use std::collections::VecDeque;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::out::RunOutput;

#[derive(clap::Args)]
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
    #[arg(long)]
    episodes: Option<u64>,
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
    #[arg(long, value_name = "DIR", conflicts_with_all = ["algo", "reward", "her", "seed", "episodes", "out", "config"])]
    resume: Option<PathBuf>,
    /// Trials of the closing evaluation (deterministic policy); 0 skips it.
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(0..=10_000_000))]
    eval_trials: u32,
    /// Threads for this run's updates, 1 to 64. The run is the same, bit for bit, on any number
    /// (work is split only into parts that write separate values, see `stagerl::base::par`); wide
    /// networks gain most (hidden 256), hidden 64 less (end to end on two cores: -5 to +40 %,
    /// see the README's Performance section).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    threads: u32,
}

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
fn stop_flags() -> Result<(Arc<AtomicBool>, Arc<AtomicBool>)> {
    Ok((stop_flag()?, stop_flag()?))
}

/// Take the lock of the run directory `dir` (created if needed) for this process.
pub fn lock_run(dir: &Path) -> Result<stagerl::run::lock::DirLock> {
    stagerl::run::lock::DirLock::run(dir)
        .with_context(|| format!("taking the run directory {}", dir.display()))
}

/// Map an interruption to a message and the interrupted exit code; a stop caused by standard
/// output failing (closed pipe, full disk) is an error saying how to resume.
fn finish<T>(r: stagerl::Result<T>, dir: &std::path::Path, output: &RunOutput) -> Result<T> {
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
fn output_ok(output: &RunOutput, dir: &std::path::Path) -> Result<()> {
    match output.failed() {
        Some(e) => bail!(
            "{e}: the run in {} finished and its files are complete, but its output was not all printed",
            dir.display()
        ),
        None => Ok(()),
    }
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
    cfg.validate()?;
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
        "training {} with reward {} on `{}`, seed {}, {} episodes -> {}",
        cfg.agent.algo,
        cfg.reward.function,
        cfg.robot.urdf,
        cfg.train.seed,
        cfg.train.episodes,
        out.display()
    )?;
    let (stop, signals) = stop_flags()?;
    let output = RunOutput::new(Arc::clone(&stop));
    let opts = TrainOptions { stop: Some(&stop) };
    let mut reporter = Reporter::new(cfg.train.episodes, &output);
    let summary = finish(train::train_with(&cfg, &out, &opts, &mut |p| reporter.episode(p)), &out, &output)?;
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
    let mut reporter = Reporter::new(cfg.train.episodes, &output);
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

fn print_summary(summary: &train::TrainSummary, output: &RunOutput) {
    output.line(format_args!(
        "trained {} episodes, {} env steps, {} updates in {:.1} s ({:.0} env steps/s)",
        summary.episodes,
        summary.env_steps,
        summary.updates,
        summary.wall_s,
        summary.env_steps as f64 / summary.wall_s
    ));
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
    output.line(format_args!("{}", super::eval::summary_line(&s, false)));
    Ok(())
}

/// A progress bar on a terminal; plain log lines every 10 s otherwise.
struct Reporter<'a> {
    output: &'a RunOutput,
    bar: Option<ProgressBar>,
    last_log: Instant,
    recent: VecDeque<(f64, bool)>,
    last_eval: Option<(u64, f64)>,
}

impl<'a> Reporter<'a> {
    fn new(episodes: u64, output: &'a RunOutput) -> Reporter<'a> {
        let bar = std::io::stdout().is_terminal().then(|| {
            let b = ProgressBar::new(episodes);
            b.set_style(
                ProgressStyle::with_template(
                    "{bar:30} {pos}/{len} episodes {elapsed_precise} (eta {eta}) {msg}",
                )
                .expect("valid template"),
            );
            b
        });
        Reporter { output, bar, last_log: Instant::now(), recent: VecDeque::new(), last_eval: None }
    }

    fn episode(&mut self, p: &Progress<'_>) {
        let r = p.record;
        self.recent.push_back((r.reward, r.success));
        if self.recent.len() > 100 {
            self.recent.pop_front();
        }
        if let Some(e) = p.eval {
            self.last_eval = Some((r.episode, e.success_rate));
        }
        let n = self.recent.len() as f64;
        let mean_r = self.recent.iter().map(|x| x.0).sum::<f64>() / n;
        let succ = self.recent.iter().filter(|x| x.1).count() as f64 / n;
        let mut msg = format!("reward(100) {mean_r:.2} success(100) {:.0}%", 100.0 * succ);
        if let Some((ep, s)) = self.last_eval {
            msg.push_str(&format!(" eval@{ep} {:.0}%", 100.0 * s));
        }
        if let Some(st) = &p.stats {
            msg.push_str(&format!(" critic {:.3}", st.critic_loss));
            if let Some(a) = st.alpha {
                msg.push_str(&format!(" alpha {a:.3}"));
            }
        }
        match &self.bar {
            Some(b) => {
                b.set_position(r.episode);
                b.set_message(msg);
            }
            None => {
                if self.last_log.elapsed() >= Duration::from_secs(10)
                    || p.eval.is_some()
                    || r.episode == p.episodes
                {
                    self.output.line(format_args!(
                        "episode {}/{} env steps {} {:.0} s {msg}",
                        r.episode, p.episodes, r.env_steps, r.wall_s
                    ));
                    self.last_log = Instant::now();
                }
            }
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish();
        }
    }
}
