use anyhow::{Context, Result};
use stagerl::base::rng::Rng;
use stagerl::config::Config;
use stagerl::env::ReachEnv;
use stagerl::reward::RewardFunction;
use std::time::Instant;

#[derive(clap::Subcommand)]
pub enum Bench {
    /// Environment steps per second, single thread (UR5, SAR by default, random actions).
    Env(EnvArgs),
    /// Median milliseconds per agent update (one gradient step of every network), one thread.
    Update(UpdateArgs),
    /// End-to-end training throughput: environment steps per second at one update per step.
    Train(TrainArgs),
    /// Plans per second in batch mode (`stagerl plan --targets`: parsing, planning and JSON
    /// output included), one thread, on targets of the task's distribution.
    Plan(PlanArgs),
    /// Every planner on fixed, seeded problem sets among obstacles (free, one in the way, 3 and
    /// 6 random, a narrow gap): success, collisions, path length, joint travel, plan time.
    Obstacles(crate::obstacles_bench::ObstaclesArgs),
    /// RRT-Connect on seeded problems with one obstacle across the straight line (the set of
    /// `stagerl eval --obstacles-in-path 1`): solved, contacts, plan time (median, p95), one thread.
    #[command(name = "rrt-connect")]
    RrtConnect(RrtArgs),
}

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl bench rrt-connect --problems 200 --seed 0")]
pub struct RrtArgs {
    /// Problems (episodes of evaluation seed --problem-seed), 1 to 100 000.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    problems: u32,
    /// The evaluation seed the problems are drawn with.
    #[arg(long, default_value_t = 42)]
    problem_seed: u64,
    /// RRT-Connect's seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Wall-time budget per plan, seconds.
    #[arg(long, default_value_t = stagerl::sim::rrt_connect::DEFAULT_BUDGET_S)]
    planner_budget_s: f64,
    /// Most tree extensions per plan, 1 to 100 000 000.
    #[arg(long, default_value_t = stagerl::sim::rrt_connect::DEFAULT_ITERATIONS,
          value_parser = clap::value_parser!(u32).range(1..=100_000_000))]
    planner_iterations: u32,
}

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl bench plan --plans 2000")]
pub struct PlanArgs {
    /// A trained run to plan with; unset: an untrained agent of --algo and --hidden (whose plans
    /// rarely reach the target, so each runs the full max_steps: the slowest case).
    #[arg(long)]
    run: Option<std::path::PathBuf>,
    #[arg(long, value_parser = super::algo_parser(), default_value = "sac")]
    algo: stagerl::agent::Algo,
    /// Width of both hidden layers of the untrained agent.
    #[arg(long, default_value_t = 64)]
    hidden: usize,
    /// Plans to time (after a tenth as many for warm-up; the fastest of three passes), 1 to
    /// 10 000 000.
    #[arg(long, default_value_t = 20_000, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    plans: u32,
    /// Plan with the damped-least-squares Jacobian controller instead of an agent.
    #[arg(long, value_enum, conflicts_with = "run")]
    controller: Option<BenchController>,
    /// Filter every command through the safety shield (`[task.shield]` defaults).
    #[arg(long)]
    shield: bool,
    /// One random obstacle per plan, across the straight line from the start end effector to
    /// the target with probability P (default 1; as `eval --obstacles-in-path`); reports reached
    /// and contact rates, the shield's interventions and the time per plan.
    #[arg(long, value_name = "P", num_args = 0..=1, default_missing_value = "1")]
    obstacles_in_path: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchController {
    /// The damped-least-squares Jacobian controller.
    Jacobian,
}

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl bench update --algo sac --hidden 256 --batch 256")]
pub struct UpdateArgs {
    #[arg(long, value_parser = super::algo_parser(), default_value = "sac")]
    algo: stagerl::agent::Algo,
    /// Width of both hidden layers.
    #[arg(long, default_value_t = 256)]
    hidden: usize,
    #[arg(long, default_value_t = 256)]
    batch: usize,
    /// CrossQ: width of both hidden layers of its critics (unset: [agent.crossq]'s default, 1024;
    /// --hidden is its actor's).
    #[arg(long)]
    critic_hidden: Option<usize>,
    /// Timed updates (after 20 warm-up updates), 1 to 1 000 000.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    updates: u32,
    /// Threads for the update (the same results on any number, see `stagerl::base::par`), 1 to 64.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    threads: u32,
}

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl bench train --algo sac --hidden 64")]
pub struct TrainArgs {
    #[arg(long, value_parser = super::algo_parser(), default_value = "sac")]
    algo: stagerl::agent::Algo,
    #[arg(long, default_value_t = 64)]
    hidden: usize,
    /// Environment steps to time (after `learning_starts` = 1000 random steps, which are timed
    /// too), 1 to 100 000 000.
    #[arg(long, default_value_t = 20_000, value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    steps: u64,
    /// Threads for the update (the same results on any number, see `stagerl::base::par`), 1 to 64.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    threads: u32,
}

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl bench env --steps 1000000 --reward sar")]
pub struct EnvArgs {
    /// Steps to time.
    #[arg(long, default_value_t = 5_000_000, value_parser = clap::value_parser!(u64).range(1..=10_000_000_000))]
    steps: u64,
    /// Reward function.
    #[arg(long, value_parser = super::reward_parser(), default_value = "sar")]
    reward: RewardFunction,
    /// Seed of targets and actions.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// A config whose `[robot]`, `[task]` (obstacles and collision checks included) and
    /// `[reward]` sections to use (`--reward` overrides the function); unset: the defaults.
    #[arg(long)]
    config: Option<std::path::PathBuf>,
    /// The simulator (overrides `task.sim`): `kinematic` or `dynamic` (rapier3d).
    #[arg(long, value_parser = ["kinematic", "dynamic"])]
    sim: Option<String>,
    /// Time a vector env of this many environments (`VecEnv`, same-step autoreset; `--steps`
    /// counts every environment's steps) instead of one environment.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=65_536))]
    num_envs: u32,
    /// Threads the vector env's steps are split over (with `--num-envs` 16 or more).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    threads: u32,
}

pub fn run(b: Bench) -> Result<()> {
    match b {
        Bench::Env(a) => env(a),
        Bench::Update(a) => {
            let pool = stagerl::base::par::Pool::new(a.threads as usize)?;
            stagerl::base::par::install(Some(&pool), || update(a))
        }
        Bench::Train(a) => {
            let pool = stagerl::base::par::Pool::new(a.threads as usize)?;
            stagerl::base::par::install(Some(&pool), || train(a))
        }
        Bench::Plan(a) => plan(a),
        Bench::Obstacles(a) => crate::obstacles_bench::run(a),
        Bench::RrtConnect(a) => rrt_connect(a),
    }
}

/// The `q`-quantile of sorted `v` (nearest rank).
fn quantile(v: &[f64], q: f64) -> f64 {
    v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1]
}

fn rrt_connect(a: RrtArgs) -> Result<()> {
    use stagerl::plan::{problems, Planner};
    use stagerl::sim::rrt_connect::RrtConnect;
    let cfg = Config::default();
    let set = problems::obstacle_in_path(&cfg, a.problems as usize, a.problem_seed)?;
    let rrt = RrtConnect {
        seed: a.seed,
        budget_s: a.planner_budget_s,
        max_iterations: a.planner_iterations,
        ..RrtConnect::default()
    };
    let mut planner = Planner::rrt_connect(&cfg, None, rrt)?;
    let mut jacobian = Planner::jacobian(&cfg, None)?;
    let (mut solved, mut contacts, mut blocked, mut times) = (0u32, 0u32, 0u32, Vec::new());
    let mut clearance = f64::INFINITY;
    for p in &set {
        let straight = jacobian.plan_among(&p.target, None, Some(&p.obstacles))?;
        blocked += u32::from(straight.summary.collision);
        let plan = planner.plan_among(&p.target, None, Some(&p.obstacles))?;
        solved += u32::from(plan.summary.reached);
        contacts += u32::from(plan.summary.collision);
        if plan.summary.reached {
            clearance = clearance.min(plan.summary.min_clearance_m.unwrap_or(f64::INFINITY));
        }
        times.push(plan.summary.plan_time_s);
    }
    times.sort_by(f64::total_cmp);
    let (median, p95) = (quantile(&times, 0.5), quantile(&times, 0.95));
    let n = a.problems;
    outln!(
        "rrt-connect: {solved}/{n} solved, {contacts} with a contact, median plan time {:.2} ms, p95 {:.2} ms, max {:.2} ms \
         (one obstacle across the straight line, problem seed {}, planner seed {}, one thread; the Jacobian controller \
         touches the obstacle in {blocked}/{n}; least clearance of a solved path {clearance:.4} m)",
        median * 1e3,
        p95 * 1e3,
        times.last().copied().unwrap_or(0.0) * 1e3,
        a.problem_seed,
        a.seed
    )?;
    outln!(
        "{}",
        serde_json::json!({
            "problems": n, "solved": solved, "contacts": contacts, "median_plan_time_s": median,
            "p95_plan_time_s": p95, "jacobian_contacts": blocked
        })
    )?;
    Ok(())
}

fn env(a: EnvArgs) -> Result<()> {
    let mut cfg = match &a.config {
        Some(p) => Config::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => Config::default(),
    };
    cfg.reward.function = a.reward;
    if let Some(sim) = &a.sim {
        cfg.task.sim = sim.parse()?;
    }
    if a.num_envs > 1 {
        return vec_env(&a, &cfg);
    }
    if a.threads > 1 {
        return Err(stagerl::Error::config(
            "--threads",
            a.threads,
            "1 for one environment: threads split a vector env (--num-envs 16 or more)",
        )
        .into());
    }
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
        "env: {} steps ({} episodes) in {:.3} s, {:.0} steps/s, {:.1} ns/step (single thread, {}, {} simulation, \
         reward {}, {} collision shapes, {} obstacles, checksum {:.3}, simd {})",
        a.steps,
        episodes,
        secs,
        sps,
        1e9 / sps,
        cfg.robot.urdf,
        cfg.task.sim.name(),
        a.reward,
        env.chain().collision_shapes().len(),
        env.task().obstacles.len(),
        checksum,
        simd()
    )?;
    outln!("{}", serde_json::json!({ "steps_per_sec": sps, "simd": simd() }))?;
    Ok(())
}

/// `bench env --num-envs N`: steps/s of a [`stagerl::env::VecEnv`] of N environments on
/// `--threads` threads, over a table of random actions.
fn vec_env(a: &EnvArgs, cfg: &Config) -> Result<()> {
    let n = a.num_envs as usize;
    let mut venv = stagerl::env::VecEnv::from_config(n, cfg, a.seed).context("building the vector env")?;
    let dim = venv.act_dim();
    let mut rng = Rng::new(a.seed ^ 0xBE7C);
    let batches = 61;
    let table: Vec<f32> = (0..batches * n * dim).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
    let pool = stagerl::base::par::Pool::new(a.threads as usize)?;
    let steps = a.steps.div_ceil(n as u64);
    let mut run = |calls: u64| -> Result<f64> {
        let mut checksum = 0.0;
        stagerl::base::par::install(Some(&pool), || -> Result<()> {
            for k in 0..calls as usize {
                let b = k % batches;
                venv.step(&table[b * n * dim..(b + 1) * n * dim])?;
                checksum += venv.rewards().iter().sum::<f64>();
            }
            Ok(())
        })?;
        Ok(checksum)
    };
    run((steps / 10).max(10))?; // warm-up
    let start = Instant::now();
    let checksum = run(steps)?;
    let secs = start.elapsed().as_secs_f64();
    let sps = (steps * n as u64) as f64 / secs;
    outln!(
        "env: a vector env of {n} environments, {} calls ({} environment steps) in {:.3} s, {:.0} steps/s \
         ({} thread(s), {}, {} simulation, reward {}, {} collision shapes, checksum {:.3})",
        steps,
        steps * n as u64,
        secs,
        sps,
        a.threads,
        cfg.robot.urdf,
        cfg.task.sim.name(),
        a.reward,
        venv.envs()[0].chain().collision_shapes().len(),
        checksum
    )?;
    outln!("{}", serde_json::json!({ "steps_per_sec": sps }))?;
    Ok(())
}

fn update(a: UpdateArgs) -> Result<()> {
    use stagerl::agent::replay::Batch;
    use stagerl::agent::{build_off_policy, AgentConfig, Algo, CrossqConfig};
    let (od, ad) = (16, 6);
    let crossq =
        a.critic_hidden.map(|w| CrossqConfig { critic_hidden: vec![w, w], ..CrossqConfig::default() });
    if crossq.is_some() && a.algo != Algo::Crossq {
        return Err(stagerl::Error::config("--critic-hidden", a.algo, "only with --algo crossq").into());
    }
    let cfg = AgentConfig {
        algo: a.algo,
        hidden: vec![a.hidden, a.hidden],
        batch_size: a.batch,
        crossq,
        ..AgentConfig::default()
    };
    // The whole config's validation: its memory estimate refuses networks too large to allocate.
    Config { agent: cfg.clone(), ..Config::default() }.validate()?;
    let mut agent = build_off_policy(&cfg, od, ad, 0)?;
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
        "update: {} hidden {}x{} batch {}: median {:.3} ms, min {:.3} ms over {} updates (obs {od}, act {ad}, {}, simd {})",
        a.algo, a.hidden, a.hidden, a.batch, median, times[0], times.len(), threads_text(a.threads), simd()
    )?;
    outln!("{}", serde_json::json!({ "ms_per_update": median, "simd": simd() }))?;
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
        "train: {} hidden {}x{}: {} env steps, {} updates in {:.2} s, {:.0} env steps/s end to end (one update per step, {}, simd {})",
        a.algo, a.hidden, a.hidden, summary.env_steps, summary.updates, secs, sps, threads_text(a.threads), simd()
    )?;
    outln!("{}", serde_json::json!({ "steps_per_sec": sps, "simd": simd() }))?;
    Ok(())
}

/// "one thread" or "N threads".
fn threads_text(n: u32) -> String {
    if n == 1 {
        "one thread".into()
    } else {
        format!("{n} threads")
    }
}

/// The configuration of `bench plan`: the default task, with one random obstacle per plan when
/// `--obstacles-in-path` is given.
fn plan_config(a: &PlanArgs) -> Config {
    let mut cfg = Config::default();
    if a.obstacles_in_path.is_some() {
        cfg.task.random_obstacles =
            Some(stagerl::sim::scene::RandomObstacles { count: [1, 1], ..Default::default() });
    }
    cfg
}

fn plan(a: PlanArgs) -> Result<()> {
    use stagerl::plan::{PlanPolicy, Planner};
    let (mut planner, what) = match (&a.run, a.controller) {
        (_, Some(BenchController::Jacobian)) => {
            (Planner::jacobian(&plan_config(&a), None)?, "Jacobian controller".to_string())
        }
        (Some(dir), None) => {
            let run = stagerl::run::dir::RunDir::new(dir);
            let (ck, planner) = Planner::from_run(&run, None, None)?;
            (planner, format!("checkpoint {}", ck.display()))
        }
        (None, None) => {
            let mut cfg = plan_config(&a);
            cfg.agent.algo = a.algo;
            cfg.agent.hidden = vec![a.hidden, a.hidden];
            let run = cfg.resolve()?;
            let env = run.env(0).context("building the environment")?;
            let agent = run.learner(0).into_agent();
            (
                Planner::new(env, PlanPolicy::Agent(agent)),
                format!("untrained {} hidden {}x{}", a.algo, a.hidden, a.hidden),
            )
        }
    };
    if a.shield {
        planner.set_shield(true).context("--shield")?;
    }
    if let Some(p) = a.obstacles_in_path {
        planner.set_obstacles_in_path(p).context("--obstacles-in-path")?;
        let b = crate::plan_bench::scene_bench(&mut planner, a.plans)?;
        let shield = if a.shield { "shielded" } else { "unshielded" };
        outln!(
            "plan among obstacles (one per plan, in the way with probability {p}): {what}, {shield}: \
             reached {:.1} %, contact {:.1} %, {:.2} interventions and {:.2} stops per plan, \
             {:.1} steps per plan, {:.3} ms per plan, {:.3} ms per 50 steps (one thread, {} plans)",
            100.0 * b.reached_rate,
            100.0 * b.contact_rate,
            b.interventions_per_plan,
            b.stops_per_plan,
            b.steps_per_plan,
            b.ms_per_plan,
            b.ms_per_50_steps,
            b.plans
        )?;
        return outln!("{}", serde_json::to_string(&b)?);
    }
    let input = |n: u32, seed: u64| -> String {
        let env = planner.env();
        let mut rng = Rng::new(seed);
        let mut q = vec![0.0; env.act_dim()];
        let mut text = String::new();
        for _ in 0..n {
            let t = env.task().sample_target(env.chain(), &mut rng, &mut q);
            text.push_str(&format!("{{\"target\":[{},{},{}]}}\n", t.x, t.y, t.z));
        }
        text
    };
    let (warm, timed) = (input((a.plans / 10).max(1), 1), input(a.plans, 2));
    crate::plan_batch::batch(&mut planner, warm.as_bytes(), std::io::sink(), None)?;
    // The fastest of three timed passes (the machine's other load only slows a pass down);
    // the output is formatted in full and discarded.
    let (mut secs, mut steps) = (f64::INFINITY, 0);
    for _ in 0..3 {
        let start = Instant::now();
        steps = crate::plan_batch::batch(&mut planner, timed.as_bytes(), std::io::sink(), None)?;
        secs = secs.min(start.elapsed().as_secs_f64());
    }
    let pps = f64::from(a.plans) / secs;
    outln!(
        "plan: {} plans in {:.3} s, {:.0} plans/s, {:.1} steps per plan ({what}, batch mode with JSON in and out, one thread)",
        a.plans,
        secs,
        pps,
        steps as f64 / f64::from(a.plans)
    )?;
    outln!("{}", serde_json::json!({ "plans_per_sec": pps }))?;
    Ok(())
}

/// The instruction set the kernels run at (`STAGERL_SIMD` caps it), as the timings report it.
fn simd() -> &'static str {
    stagerl::base::simd::simd_level().name()
}
