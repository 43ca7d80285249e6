use anyhow::{Context, Result};
use stagerl::env::{rollout, Flow, Observed, Outcome, Policy, ReachEnv, Scratch, Transition};
use stagerl::plan::controller::JacobianController;
use stagerl::train::eval::{evaluate, EvalOptions};
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl demo --show 1 --trials 500")]
pub struct Args {
    /// A TOML config (arm, task, reward); defaults otherwise.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Seed of the target stream (also of the closing evaluation's targets).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Episodes printed step by step (0 to 1000).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=1000))]
    show: u32,
    /// Random targets in the closing evaluation (1 to 10 000 000).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    trials: u32,
}

pub fn run(args: Args) -> Result<()> {
    let cfg = super::load_config(args.config.as_deref())?;
    let mut env = ReachEnv::from_config(&cfg, args.seed).context("building the environment")?;
    let chain = env.chain().clone();
    let mut ctl = JacobianController::new(&chain);
    outln!(
        "scripted Jacobian controller on `{}` ({} joints, tip `{}`), reward {}, seed {}",
        cfg.robot.urdf,
        chain.dof(),
        chain.tip_link(),
        cfg.reward.function,
        args.seed
    )?;
    let mut scratch = Scratch::new(&env);
    let stop = crate::run_control::stop_flag()?;
    for ep in 1..=args.show {
        if stop.load(std::sync::atomic::Ordering::SeqCst) {
            stopped(&format!("stopped on request after {} episodes shown", ep - 1));
        }
        env.reset();
        let t = env.target();
        outln!(
            "\nepisode {ep}: target ({:.4}, {:.4}, {:.4}) m, start distance {:.4} m",
            t.x,
            t.y,
            t.z,
            env.distance()
        )?;
        // The columns: the step, then every reported term but `reached` (D_PT in metres).
        let columns =
            |t: &stagerl::reward::RewardTerms| t.reported().into_iter().filter(|(n, _)| *n != "reached");
        let header: String = columns(&Default::default())
            .map(|(n, _)| format!(" {:>9}", if n == "distance" { "D_PT(m)" } else { n }))
            .collect();
        outln!("{:>4}{header}", "step")?;
        // The rows are gathered during the episode and printed after it (a write error is the
        // CLI's to report, not the rollout's).
        let mut rows = String::new();
        let print_step = |t: &Transition<'_>| {
            let row: String = columns(&t.step.terms).map(|(_, v)| format!(" {v:>9.5}")).collect();
            rows.push_str(&format!("{:>4}{row}\n", t.env.steps()));
            Ok(Flow::Continue)
        };
        let outcome = rollout(&mut env, &mut scratch, &mut Observed(ctl.policy(), print_step))?;
        crate::out::text(&rows)?;
        if let Outcome::Finished { reward, last } = outcome {
            outln!(
                "{} after {} steps, episode reward (eq. 16) {reward:.4}",
                if last.reached() {
                    "reached"
                } else if last.terminated {
                    "collided"
                } else {
                    "truncated"
                },
                env.steps()
            )?;
        }
    }
    if args.trials > 0 {
        let opts = EvalOptions::new(args.trials, args.seed).stopped_by(Some(&stop));
        let (s, _) = match evaluate(&mut env, &mut Policy(ctl.policy()), &opts) {
            Err(e @ stagerl::Error::Stopped { .. }) => stopped(&e.to_string()),
            other => other?,
        };
        outln!("\n{}", crate::progress::summary_line(&s, false))?;
    }
    Ok(())
}

/// Exit 130 after a stop request, saying how far the demo got.
fn stopped(what: &str) -> ! {
    // Standard error may be closed too; the exit code still tells.
    let _ = errln!("stagerl: {what}");
    std::process::exit(i32::from(crate::run_control::INTERRUPTED_EXIT));
}
