use anyhow::{Context, Result};
use stagerl::config::Config;
use stagerl::env::ReachEnv;
use stagerl::reward::RewardFunction;
use stagerl::rng::Rng;
use std::time::Instant;

#[derive(clap::Subcommand)]
pub enum Bench {
    /// Environment steps per second, single thread (UR5, SAR by default, random actions).
    Env(EnvArgs),
}

#[derive(clap::Args)]
pub struct EnvArgs {
    /// Steps to time.
    #[arg(long, default_value_t = 5_000_000)]
    steps: u64,
    /// Reward function.
    #[arg(long, default_value = "sar")]
    reward: RewardFunction,
    /// Seed of targets and actions.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(b: Bench) -> Result<()> {
    match b {
        Bench::Env(a) => env(a),
    }
}

fn env(a: EnvArgs) -> Result<()> {
    let mut cfg = Config::default();
    cfg.reward.function = a.reward;
    let mut env = ReachEnv::from_config(&cfg, a.seed).context("building the environment")?;
    let dim = env.act_dim();
    // A fixed table of random actions, so the timed loop only steps the environment.
    let mut rng = Rng::new(a.seed ^ 0xBE7C);
    let table: Vec<f32> = (0..1021 * dim).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
    let rows = table.len() / dim;
    let run = |env: &mut ReachEnv, steps: u64| -> Result<(u64, f64)> {
        env.reset();
        let (mut episodes, mut checksum) = (0u64, 0.0);
        for k in 0..steps as usize {
            let row = k % rows;
            let s = env.step(&table[row * dim..(row + 1) * dim])?;
            checksum += s.total();
            if s.done() {
                env.reset();
                episodes += 1;
            }
        }
        Ok((episodes, checksum))
    };
    run(&mut env, (a.steps / 10).max(1000))?; // warm-up
    let start = Instant::now();
    let (episodes, checksum) = run(&mut env, a.steps)?;
    let secs = start.elapsed().as_secs_f64();
    let sps = a.steps as f64 / secs;
    println!(
        "env: {} steps ({} episodes) in {:.3} s, {:.0} steps/s, {:.1} ns/step (single thread, UR5, reward {}, checksum {:.3})",
        a.steps,
        episodes,
        secs,
        sps,
        1e9 / sps,
        a.reward,
        checksum
    );
    println!("{}", serde_json::json!({ "steps_per_sec": sps }));
    Ok(())
}
