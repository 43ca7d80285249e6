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
    /// Median milliseconds per agent update (one gradient step of every network), one thread.
    Update(UpdateArgs),
    /// End-to-end training throughput: environment steps per second at one update per step.
    Train(TrainArgs),
}

#[derive(clap::Args)]
pub struct UpdateArgs {
    #[arg(long, default_value = "sac")]
    algo: stagerl::agent::Algo,
    /// Width of both hidden layers.
    #[arg(long, default_value_t = 256)]
    hidden: usize,
    #[arg(long, default_value_t = 256)]
    batch: usize,
    /// Timed updates (after 20 warm-up updates), 1 to 1 000 000.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    updates: u32,
}

#[derive(clap::Args)]
pub struct TrainArgs {
    #[arg(long, default_value = "sac")]
    algo: stagerl::agent::Algo,
    #[arg(long, default_value_t = 64)]
    hidden: usize,
    /// Environment steps to time (after `learning_starts` = 1000 random steps, which are timed
    /// too), 1 to 100 000 000.
    #[arg(long, default_value_t = 20_000, value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    steps: u64,
}

#[derive(clap::Args)]
pub struct EnvArgs {
    /// Steps to time.
    #[arg(long, default_value_t = 5_000_000, value_parser = clap::value_parser!(u64).range(1..=10_000_000_000))]
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
        Bench::Update(a) => update(a),
        Bench::Train(a) => train(a),
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
    outln!(
        "env: {} steps ({} episodes) in {:.3} s, {:.0} steps/s, {:.1} ns/step (single thread, UR5, reward {}, checksum {:.3})",
        a.steps,
        episodes,
        secs,
        sps,
        1e9 / sps,
        a.reward,
        checksum
    )?;
    outln!("{}", serde_json::json!({ "steps_per_sec": sps }))?;
    Ok(())
}

fn update(a: UpdateArgs) -> Result<()> {
    use stagerl::agent::{build, AgentConfig};
    use stagerl::replay::Batch;
    let (od, ad) = (16, 6);
    let cfg = AgentConfig {
        algo: a.algo,
        hidden: vec![a.hidden, a.hidden],
        batch_size: a.batch,
        ..AgentConfig::default()
    };
    // The whole config's validation: its memory estimate refuses networks too large to allocate.
    Config { agent: cfg.clone(), ..Config::default() }.validate()?;
    let mut agent = build(&cfg, od, ad, 0)?;
    let mut rng = Rng::new(1);
    let mut batch = Batch::new(a.batch, od, ad);
    for x in batch.obs.iter_mut().chain(batch.next_obs.iter_mut()).chain(batch.act.iter_mut()) {
        *x = rng.uniform_range(-1.0, 1.0) as f32;
    }
    for r in batch.reward.iter_mut() {
        *r = rng.normal() as f32;
    }
    for _ in 0..20 {
        agent.update(&batch);
    }
    let mut times: Vec<f64> = (0..a.updates)
        .map(|_| {
            let t = Instant::now();
            agent.update(&batch);
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    outln!(
        "update: {} hidden {}x{} batch {}: median {:.3} ms, min {:.3} ms over {} updates (obs {od}, act {ad}, one thread)",
        a.algo, a.hidden, a.hidden, a.batch, median, times[0], times.len()
    )?;
    outln!("{}", serde_json::json!({ "ms_per_update": median }))?;
    Ok(())
}

fn train(a: TrainArgs) -> Result<()> {
    let mut cfg = Config::default();
    cfg.agent.algo = a.algo;
    cfg.agent.hidden = vec![a.hidden, a.hidden];
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 0;
    // Enough episodes to cover the steps; stopped by counting steps below.
    cfg.train.episodes = a.steps.div_ceil(u64::from(cfg.task.max_steps)).max(1);
    let dir = std::env::temp_dir().join(format!("stagerl-bench-train-{}", std::process::id()));
    let start = Instant::now();
    let summary = stagerl::train::train(&cfg, &dir, |_| {}).context("training")?;
    let secs = start.elapsed().as_secs_f64();
    std::fs::remove_dir_all(&dir).ok();
    let sps = summary.env_steps as f64 / secs;
    outln!(
        "train: {} hidden {}x{}: {} env steps, {} updates in {:.2} s, {:.0} env steps/s end to end (one update per step, one thread)",
        a.algo, a.hidden, a.hidden, summary.env_steps, summary.updates, secs, sps
    )?;
    outln!("{}", serde_json::json!({ "steps_per_sec": sps }))?;
    Ok(())
}
