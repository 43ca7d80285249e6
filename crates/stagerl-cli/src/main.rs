//! `stagerl`: a thin command-line layer over the `stagerl` library.

#[macro_use]
mod out;
mod cmd;
mod jsonl;
mod obstacles_bench;
mod plan_batch;
mod plan_bench;
mod progress;
mod run_control;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "stagerl",
    version,
    about = "Deep RL for robot-arm reaching with the stage-incentive dense rewards"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Train an agent (DDPG, TD3, SAC, PPO, CrossQ) on the reaching task; ends with an evaluation.
    Train(cmd::train::Args),
    /// Evaluate a trained run's deterministic policy on random targets.
    Eval(cmd::eval::Args),
    /// Run a sweep of algorithms x rewards x seeds (the paper's protocol or a reduced one),
    /// resumable and shardable; each run is trained, then evaluated.
    Reproduce(cmd::reproduce::Args),
    /// Run the scripted Jacobian controller on the reaching task, printing every reward term
    /// step by step, then its success rate over many random targets.
    Demo(cmd::demo::Args),
    /// Plan a joint trajectory from a start pose to a target with a trained run's deterministic
    /// policy (or the Jacobian controller): one JSON line (or CSV row) per state, then a summary.
    Plan(cmd::plan::Args),
    /// Export a trained run's policy as an ONNX model (the actor, the deterministic action rule
    /// and the speed-limit scaling: observation in, joint velocities in rad/s out).
    Export(cmd::export::Args),
    /// Write an animated 3D view of a trained run's planned trajectories: one self-contained
    /// HTML file (the arm, the targets, the end-effector paths; play/pause, a step slider, an
    /// orbit camera).
    View(cmd::view::Args),
    /// Forward kinematics: JSON lines {"joints":[...]} on stdin (radians), one
    /// {"position":[x,y,z],"quaternion":[x,y,z,w]} line out per input (metres, base frame).
    Fk(cmd::fk::Args),
    /// Reward terms: JSON lines {"ee_pos","ee_quat","target","joint_vel"} on stdin (`joint_vel`:
    /// one value per joint of --robot, 6 for the default UR5), one line of every term out per
    /// input.
    Reward(cmd::reward::Args),
    /// What stagerl sees in a URDF: the chain, its joints and limits, the collision shapes per
    /// link, the self-collision pairs; a suggested home pose and target range (with
    /// --config-out, a config that trains on the arm).
    Robot(cmd::robot::Args),
    /// Table 1, the paper's claims, Figures 7 and 8 and trajectories from finished run directories.
    Report(cmd::report::Args),
    /// Benchmarks.
    #[command(subcommand, after_help = "Example:\n  stagerl bench update --algo sac --hidden 256")]
    Bench(cmd::bench::Bench),
    /// Print every config section and field with its default and help (a valid config), or the
    /// config's JSON Schema.
    Config(cmd::config::Args),
}

fn main() -> ExitCode {
    stagerl::run::provenance::Code::record_build(env!("STAGERL_GIT_COMMIT"), env!("STAGERL_GIT_DIRTY"));
    let cli = match negative_numbers(Cli::command()).try_get_matches().and_then(|m| Cli::from_arg_matches(&m))
    {
        Ok(cli) => cli,
        Err(e) => return usage(&e),
    };
    let result =
        stagerl::base::simd::simd_cap().map_err(anyhow::Error::from).and_then(|_| match cli.command {
            Command::Train(a) => cmd::train::run(a),
            Command::Eval(a) => cmd::eval::run(a),
            Command::Reproduce(a) => cmd::reproduce::run(a),
            Command::Demo(a) => cmd::demo::run(a),
            Command::Plan(a) => cmd::plan::run(a),
            Command::Export(a) => cmd::export::run(a),
            Command::View(a) => cmd::view::run(a),
            Command::Fk(a) => cmd::fk::run(a),
            Command::Reward(a) => cmd::reward::run(a),
            Command::Robot(a) => cmd::robot::run(a),
            Command::Report(a) => cmd::report::run(a),
            Command::Bench(b) => cmd::bench::run(b),
            Command::Config(a) => cmd::config::run(a),
        });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // With standard error closed too, the exit code alone tells.
            let _ = errln!("stagerl: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Every flag that takes a value takes a negative number as its value (`--obstacles-in-path
/// -0.5`, `--seed -1`): the value then reaches the flag's own check and its message, instead of
/// clap reading it as an unknown flag `-0`.
fn negative_numbers(cmd: clap::Command) -> clap::Command {
    cmd.mut_args(|a| if a.get_action().takes_values() { a.allow_negative_numbers(true) } else { a })
        .mut_subcommands(negative_numbers)
}

/// Print clap's help, version or usage error through [`out`] (so a failing output is an error,
/// not ignored) and exit with clap's code (0 for help and version, 2 for a usage error).
fn usage(e: &clap::Error) -> ExitCode {
    let text = e.render().to_string();
    let written = if e.use_stderr() { errln!("{}", text.trim_end()) } else { out::text(&text) };
    match written {
        Ok(()) => ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2)),
        Err(err) => {
            let _ = errln!("stagerl: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
