use anyhow::{Context, Result};
use stagerl::controller::JacobianController;
use stagerl::env::ReachEnv;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(clap::Args)]
pub struct Args {
    /// A TOML config (arm, task, reward); defaults otherwise.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Seed of the target stream.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Episodes printed step by step.
    #[arg(long, default_value_t = 1)]
    show: u32,
    /// Random targets in the closing evaluation.
    #[arg(long, default_value_t = 500)]
    trials: u32,
}

pub fn run(args: Args) -> Result<()> {
    let cfg = super::load_config(args.config.as_deref())?;
    let mut env = ReachEnv::from_config(&cfg, args.seed).context("building the environment")?;
    let chain = env.chain().clone();
    let dt = env.task().dt_s;
    let mut ctl = JacobianController::new(&chain);
    let mut action = vec![0.0f32; env.act_dim()];
    println!(
        "scripted Jacobian controller on `{}` ({} joints, tip `{}`), reward {}, seed {}",
        cfg.robot.urdf,
        chain.dof(),
        chain.tip_link(),
        cfg.reward.function,
        args.seed
    );
    let stop = super::train::stop_flag()?;
    for ep in 1..=args.show {
        if stop.load(Ordering::SeqCst) {
            stopped(ep - 1, "episodes shown"); // [runsafe]
        }
        env.reset();
        let t = env.target();
        println!(
            "\nepisode {ep}: target ({:.4}, {:.4}, {:.4}) m, start distance {:.4} m",
            t.x,
            t.y,
            t.z,
            env.distance()
        );
        println!(
            "{:>4} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>6} {:>6} {:>9} {:>5} {:>9}",
            "step",
            "D_PT(m)",
            "position",
            "direction",
            "posture",
            "move",
            "stride",
            "alpha1",
            "alpha2",
            "reward",
            "bonus",
            "total"
        );
        let mut episode_reward = 0.0;
        loop {
            ctl.act(&chain, env.joint_positions(), &env.target(), dt, &mut action);
            let s = env.step(&action)?;
            let r = s.terms;
            episode_reward += s.total();
            println!(
                "{:>4} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>6.3} {:>6.3} {:>9.5} {:>5} {:>9.5}",
                env.steps(),
                r.distance,
                r.position,
                r.direction,
                r.posture,
                r.movement,
                r.stride,
                r.alpha1,
                r.alpha2,
                r.reward,
                r.bonus,
                r.total
            );
            if s.done() {
                println!(
                    "{} after {} steps, episode reward (eq. 16) {:.4}",
                    if s.terminated { "reached" } else { "truncated" },
                    env.steps(),
                    episode_reward
                );
                break;
            }
        }
    }
    if args.trials > 0 {
        evaluate_controller(&mut env, &mut ctl, args.trials, &stop)?;
    }
    Ok(())
}

/// Exit 130 after a stop request, saying how far the loop got. [runsafe]
fn stopped(done: u32, what: &str) -> ! {
    eprintln!("stagerl: stopped on request after {done} {what}");
    std::process::exit(i32::from(super::train::INTERRUPTED_EXIT));
}

/// The controller on `trials` random targets: success rate, mean reward and steps.
fn evaluate_controller(
    env: &mut ReachEnv,
    ctl: &mut JacobianController,
    trials: u32,
    stop: &AtomicBool,
) -> Result<()> {
    let chain = env.chain().clone();
    let dt = env.task().dt_s;
    let mut action = vec![0.0f32; env.act_dim()];
    let (mut successes, mut success_steps, mut total_reward) = (0u32, 0u64, 0.0);
    for trial in 0..trials {
        if stop.load(Ordering::SeqCst) {
            stopped(trial, "evaluation trials"); // [runsafe]
        }
        env.reset();
        let mut r = 0.0;
        loop {
            ctl.act(&chain, env.joint_positions(), &env.target(), dt, &mut action);
            let s = env.step(&action)?;
            r += s.total();
            if s.done() {
                if s.terminated {
                    successes += 1;
                    success_steps += u64::from(env.steps());
                }
                break;
            }
        }
        total_reward += r;
    }
    let n = f64::from(trials);
    let mean_steps = if successes > 0 { success_steps as f64 / f64::from(successes) } else { f64::NAN };
    println!(
        "\nevaluation over {} random targets: success {:.1} %, mean episode reward {:.3}, mean steps (successful) {:.2}",
        trials,
        100.0 * f64::from(successes) / n,
        total_reward / n,
        mean_steps
    );
    Ok(())
}
