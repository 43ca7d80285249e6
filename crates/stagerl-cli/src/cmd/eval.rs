use anyhow::{Context, Result};
use stagerl::env::{Policy, Sim};
use stagerl::run::dir::{EvalVariant, RunDir};
use stagerl::train::eval::{deterministic, evaluate, EvalOptions};
use stagerl::train::{self};

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl eval --run runs/sac-sar --trials 500 --seed 0")]
pub struct Args {
    #[command(flatten)]
    run: super::RunArgs,
    /// Random targets (1 to 10 000 000; every trial's record is kept for the CSV).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    trials: u32,
    /// Seed of the targets.
    #[arg(long, default_value_t = train::eval::DEFAULT_EVAL_SEED)]
    seed: u64,
    /// Evaluate in this simulator instead of the run's own (`task.sim`): the transfer of a policy
    /// trained kinematically to the dynamic arm, or back. Its per-trial CSV is named for it.
    #[arg(long, value_parser = ["kinematic", "dynamic"])]
    sim: Option<String>,
    /// Place each trial's first random obstacle in the way from the start end effector to the
    /// target with this probability (0 to 1; the placement of `train.obstacles_in_path`), where
    /// the run's own evaluations draw them anywhere in the region: how well the policy goes round
    /// an obstacle. Needs `[task.random_obstacles]`. Its per-trial CSV is named for it.
    #[arg(long, value_name = "P")]
    obstacles_in_path: Option<f64>,
    /// Filter every command through the safety shield (`[task.shield]`); the summary adds the
    /// `shield_*` counts.
    #[arg(long)]
    shield: bool,
    /// Evaluate without the safety shield a run trained with `[task.shield] enabled = true`
    /// (the policy alone). Its per-trial CSV is named for it.
    #[arg(long, conflicts_with = "shield")]
    no_shield: bool,
    /// Print one JSON line instead of text.
    #[arg(long)]
    json: bool,
    /// Replace an existing evaluation file of the same checkpoint, trials and seed that holds
    /// other results (an identical one is left as is).
    #[arg(long)]
    force: bool,
}

pub fn run(args: Args) -> Result<()> {
    let dir = RunDir::new(&args.run.run);
    let mut cfg =
        dir.load_config().with_context(|| format!("reading the run in {}", args.run.run.display()))?;
    let trained_in = cfg.task.sim;
    let sim = args.sim.as_deref().map(str::parse::<Sim>).transpose()?.filter(|s| *s != trained_in);
    if let Some(s) = sim {
        cfg.task.sim = s;
    }
    let (checkpoint, mut env, mut agent, changes) =
        train::eval::load_run_agent_noting(&dir, &cfg, args.run.checkpoint.as_deref())?;
    // The evaluation runs under the run's config.toml: say so when it is not the config the
    // checkpoint was trained with (--sim's own change aside).
    let changes: Vec<String> = changes
        .into_iter()
        .filter(|(field, _, _)| !(sim.is_some() && field == "task.sim"))
        .map(|(field, was, is)| format!("`{field}` = {was} there, {is} here"))
        .collect();
    if !changes.is_empty() {
        errln!(
            "stagerl: warning: {} was trained under another config than {} ({}{}); evaluating under {}",
            checkpoint.display(),
            dir.config().display(),
            changes.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
            if changes.len() > 3 { format!(" and {} more", changes.len() - 3) } else { String::new() },
            dir.config().display()
        )?;
    }
    let in_path = args.obstacles_in_path.filter(|&p| p != 0.0);
    if let Some(p) = in_path {
        env.set_obstacles_in_path(p).context("--obstacles-in-path")?;
    }
    let run_shield = cfg.task.shield.is_some_and(|s| s.enabled);
    let shield = (args.shield || args.no_shield).then_some(args.shield).filter(|&on| on != run_shield);
    if let Some(on) = shield {
        env.set_shield(on).context(if on { "--shield" } else { "--no-shield" })?;
    }
    let variant = EvalVariant { sim, obstacles_in_path: in_path, shield };
    // It writes into the run: its lock, once the agent loads (a refused checkpoint leaves the
    // directory untouched).
    let _lock = crate::run_control::lock_run(&args.run.run)?;
    let stop = crate::run_control::stop_flag()?;
    let opts = EvalOptions::new(args.trials, args.seed).stopped_by(Some(&stop));
    let (summary, records) = match evaluate(&mut env, &mut Policy(deterministic(agent.as_mut())), &opts) {
        Err(e @ stagerl::Error::Stopped { .. }) => {
            // Standard error may be closed too; the exit code still tells.
            let _ = errln!("stagerl: {e}");
            std::process::exit(i32::from(crate::run_control::INTERRUPTED_EXIT));
        }
        other => other?,
    };
    // Its own file, named by checkpoint, trials and seed: never the closing evaluation
    // (eval-final-seed<N>.csv) a report reads.
    let (csv, written) =
        train::eval::write_command_eval(&dir, &checkpoint, &records, args.seed, variant, args.force)?;
    if !args.json {
        let other = sim.map(|s| format!(" in the {} simulation (trained {})", s.name(), trained_in.name()));
        let in_path = in_path.map(|p| format!(" with the first obstacle in the way with probability {p}"));
        let shield = shield.map(|on| if on { " with the shield" } else { " without the shield" });
        outln!(
            "{}{}{}{} on {} trials (seed {}), per-trial CSV {} ({written})",
            checkpoint.display(),
            other.unwrap_or_default(),
            in_path.unwrap_or_default(),
            shield.unwrap_or_default(),
            args.trials,
            args.seed,
            csv.display()
        )?;
    }
    let line = crate::progress::summary_line(&summary, args.json);
    outln!("{}", crate::progress::with_shield(line, env.shield_stats(), args.json))
}
