//! `stagerl bench obstacles`: every planner on the same fixed, seeded problem sets
//! ([`stagerl::plan::problems`]), one thread: success (reached with no contact anywhere along the
//! path, checked continuously), collision rate, path length, joint travel, plan time (median
//! and 95th percentile) and, for the shielded planners (`jacobian+shield`, `policy+shield`: the
//! safety shield of `--shield` filtering every command), the shield's interventions and stops per
//! plan.
//!
//! Every problem is known to be solvable: RRT-Connect with a generous budget (`--solvable-budget-s`,
//! its own seed) found a contact-free path to it, else the candidate was drawn again (counted in
//! the output). That path's last pose is the problem's joint-space goal (`goal_rad` in
//! `--problems-out`), which OMPL's RRTConnect is given (scripts/bench/ompl_rrt_connect.py).

use anyhow::{Context, Result};
use stagerl::config::Config;
use stagerl::plan::problems::{draw_problems, Problem, ProblemSet};
use stagerl::plan::{Plan, Planner};
use stagerl::sim::rrt_connect::{RrtConnect, DEFAULT_ITERATIONS};
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(
    after_help = "Example:\n  stagerl bench obstacles --problems 200 --run runs/sac-obstacles --problems-out problems.jsonl"
)]
pub struct ObstaclesArgs {
    /// Problems per set, 1 to 100 000.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    problems: u32,
    /// The problem sets (comma-separated; default: all).
    #[arg(long, value_delimiter = ',', value_parser = ["free", "in-the-way", "random-3", "random-6", "narrow-gap"])]
    sets: Vec<String>,
    /// The planners (comma-separated; default: all, the policy's two with --run).
    #[arg(long, value_delimiter = ',', value_parser = PLANNERS)]
    planners: Vec<String>,
    /// Seed of the problem sets.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The arm and task (a training config; default: the UR5 and the default task). Its own
    /// obstacles are not used.
    #[arg(long)]
    config: Option<PathBuf>,
    /// A trained run whose policy joins the table (`policy` and `policy+shield`); its arm is used.
    #[arg(long)]
    run: Option<PathBuf>,
    /// Write the problems as JSON lines (`set`, `id`, `robot`, `start_rad`, `target_m`,
    /// `obstacles`), the input of scripts/bench/ompl_rrt_connect.py.
    #[arg(long, value_name = "FILE")]
    problems_out: Option<PathBuf>,
    /// Write one JSON line per planner and problem (`planner`, `set`, `id`, `success`,
    /// `collision`, `reached`, `min_clearance_m`, `path_length_m`, `joint_travel_rad`,
    /// `plan_time_s`, and the shielded planners' `shield_*` counts).
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// RRT-Connect's wall-time budget per plan in the table, seconds.
    #[arg(long, default_value_t = stagerl::sim::rrt_connect::DEFAULT_BUDGET_S)]
    planner_budget_s: f64,
    /// RRT-Connect's wall-time budget when it decides whether a candidate problem is solvable,
    /// seconds (with 100 times the table's iterations).
    #[arg(long, default_value_t = 5.0)]
    solvable_budget_s: f64,
    /// Replace --problems-out and --out files that exist and hold something else.
    #[arg(long)]
    force: bool,
}

/// Mixed into `--seed` for the solvability judge's RRT-Connect (not the table's).
const JUDGE_SEED: u64 = 0x5017_AB1E;

/// The planners of the table, in its order.
const PLANNERS: [&str; 5] = ["jacobian", "jacobian+shield", "rrt-connect", "policy", "policy+shield"];

/// One planner's figures on one set.
struct Row {
    planner: &'static str,
    set: ProblemSet,
    plans: usize,
    success: usize,
    collision: usize,
    path_length_m: Vec<f64>,
    joint_travel_rad: Vec<f64>,
    plan_time_s: Vec<f64>,
    /// Shielded planners: commands the shield changed and stops, summed over the plans.
    shield: Option<(u64, u64)>,
}

pub fn run(a: ObstaclesArgs) -> Result<()> {
    let cfg = match (&a.run, &a.config) {
        (Some(run), _) => stagerl::run::dir::RunDir::new(run).load_config()?,
        (None, Some(path)) => Config::load(path)?,
        (None, None) => Config::default(),
    };
    let sets: Vec<ProblemSet> = if a.sets.is_empty() {
        ProblemSet::ALL.to_vec()
    } else {
        a.sets.iter().filter_map(|s| ProblemSet::from_name(s)).collect()
    };
    let rrt = |seed: u64, budget_s: f64, max_iterations: u32| RrtConnect {
        seed,
        budget_s,
        max_iterations,
        ..RrtConnect::default()
    };
    let mut judge = Planner::rrt_connect(
        &cfg,
        None,
        rrt(a.seed ^ JUDGE_SEED, a.solvable_budget_s, 100 * DEFAULT_ITERATIONS),
    )
    .context("--solvable-budget-s")?;
    let mut planners = planners(&cfg, &a, rrt(a.seed, a.planner_budget_s, DEFAULT_ITERATIONS))?;
    // Checked before the work; written whole at the end (atomically, never over another file
    // without --force).
    for path in [&a.problems_out, &a.out].into_iter().flatten() {
        stagerl::io::check_output_kind(path)?;
    }
    let mut problems_out = a.problems_out.as_ref().map(|_| Vec::<u8>::new());
    let mut out = a.out.as_ref().map(|_| Vec::<u8>::new());
    let (mut rows, mut refused) = (Vec::new(), Vec::new());
    for &set in &sets {
        // The goal of each problem's solving path, by the problem's index.
        let mut goals: Vec<Vec<f64>> = Vec::new();
        let mut solvable = |p: &Problem| -> bool {
            let Ok(plan) = judge.plan_among(&p.target_m, Some(&p.start_rad), Some(&p.obstacles)) else {
                return false;
            };
            let ok = plan.summary.reached && !plan.summary.collision;
            if ok {
                let dof = plan.dof;
                goals.truncate(p.id);
                goals.push(plan.q[plan.q.len() - dof..].to_vec());
            }
            ok
        };
        let (problems, n_refused) = draw_problems(&cfg, set, a.problems as usize, a.seed, &mut solvable)
            .with_context(|| format!("drawing the problem set `{}`", set.name()))?;
        refused.push((set, n_refused));
        if let Some(f) = problems_out.as_mut() {
            for (p, goal) in problems.iter().zip(&goals) {
                write_problem(f, &cfg, p, goal)?;
            }
        }
        for (name, planner) in &mut planners {
            let mut row = Row {
                planner: name,
                set,
                plans: 0,
                success: 0,
                collision: 0,
                path_length_m: Vec::new(),
                joint_travel_rad: Vec::new(),
                plan_time_s: Vec::new(),
                shield: None,
            };
            for p in &problems {
                let plan = planner
                    .plan_among(&p.target_m, Some(&p.start_rad), Some(&p.obstacles))
                    .with_context(|| format!("{name} on {} problem {}", set.name(), p.id))?;
                let success = record(&mut row, &plan);
                if let Some(f) = out.as_mut() {
                    writeln!(f, "{}", plan_line(name, set, p.id, success, &plan)?)?;
                }
            }
            rows.push(row);
        }
    }
    for (path, bytes) in [(&a.problems_out, problems_out), (&a.out, out)] {
        if let (Some(path), Some(bytes)) = (path, bytes) {
            stagerl::io::write_new(path, &bytes, a.force)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    print_table(&rows, &refused, &a)
}

/// The planners of the table: the Jacobian controller and RRT-Connect (`rrt`) on `cfg`'s arm and
/// task, the run's policy with `--run`, and the first and the policy again behind the shield.
/// `policy` is the policy alone, also for a run trained behind the shield (`[task.shield]`).
fn planners(cfg: &Config, a: &ObstaclesArgs, rrt: RrtConnect) -> Result<Vec<(&'static str, Planner)>> {
    let with_shield = |mut p: Planner, on: bool| -> Result<Planner> {
        p.set_shield(on).context(if on { "the shielded planners" } else { "the policy alone" })?;
        Ok(p)
    };
    let mut planners: Vec<(&'static str, Planner)> = vec![
        ("jacobian", Planner::jacobian(cfg, None)?),
        ("jacobian+shield", with_shield(Planner::jacobian(cfg, None)?, true)?),
        ("rrt-connect", Planner::rrt_connect(cfg, None, rrt).context("--planner-budget-s")?),
    ];
    if let Some(run) = &a.run {
        let policy = || Planner::from_run(&stagerl::run::dir::RunDir::new(run), None, None).map(|(_, p)| p);
        planners.push(("policy", with_shield(policy()?, false)?));
        planners.push(("policy+shield", with_shield(policy()?, true)?));
    } else if let Some(p) = a.planners.iter().find(|p| p.starts_with("policy")) {
        anyhow::bail!("--planners {p}: the policy's planners need --run (a trained run)");
    }
    if !a.planners.is_empty() {
        planners.retain(|(name, _)| a.planners.iter().any(|p| p == name));
    }
    Ok(planners)
}

/// One line of `--out`: the plan's verdict and figures, and the shield's counts when it ran.
fn plan_line(
    name: &str,
    set: ProblemSet,
    id: usize,
    success: bool,
    plan: &Plan,
) -> Result<serde_json::Value> {
    let s = &plan.summary;
    let mut line = serde_json::json!({
        "planner": name, "set": set.name(), "id": id, "success": success,
        "collision": s.collision, "reached": s.reached, "min_clearance_m": s.min_clearance_m,
        "path_length_m": s.path_length_m, "joint_travel_rad": s.joint_travel_rad,
        "plan_time_s": s.plan_time_s,
    });
    if let (Some(counts), Some(map)) = (s.shield, line.as_object_mut()) {
        if let serde_json::Value::Object(c) = serde_json::to_value(counts)? {
            map.extend(c);
        }
    }
    Ok(line)
}

/// Add a plan to its row; whether it succeeded (reached with no contact along the path).
fn record(row: &mut Row, plan: &Plan) -> bool {
    let s = &plan.summary;
    let success = s.reached && !s.collision;
    row.plans += 1;
    row.success += usize::from(success);
    row.collision += usize::from(s.collision);
    row.plan_time_s.push(s.plan_time_s);
    if let Some(c) = s.shield {
        let (changed, stops) = row.shield.unwrap_or((0, 0));
        row.shield = Some((changed + c.shield_interventions, stops + c.shield_stops));
    }
    if success {
        row.path_length_m.push(s.path_length_m);
        row.joint_travel_rad.push(s.joint_travel_rad);
    }
    success
}

fn write_problem(f: &mut impl Write, cfg: &Config, p: &Problem, goal: &[f64]) -> Result<()> {
    let line = serde_json::json!({
        "set": p.set.name(), "id": p.id, "robot": cfg.robot.urdf, "tip": cfg.robot.tip,
        "start_rad": p.start_rad, "goal_rad": goal, "target_m": p.target_m, "obstacles": p.obstacles,
    });
    writeln!(f, "{line}")?;
    Ok(())
}

/// The `q`-quantile of `v` (sorted in place), NaN when empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn print_table(rows: &[Row], refused: &[(ProblemSet, usize)], a: &ObstaclesArgs) -> Result<()> {
    let refused: Vec<String> = refused.iter().map(|(s, n)| format!("{} {n}", s.name())).collect();
    outln!(
        "obstacles: {} problems per set, seed {}, one thread; success = reached with no contact along the \
         path (checked continuously); path length and joint travel over successes; every problem solved \
         by RRT-Connect within {} s (candidates it could not solve, drawn again: {}); rrt-connect's \
         budget in the table {} s; shield: commands it changed and stops it made, per plan",
        a.problems,
        a.seed,
        a.solvable_budget_s,
        refused.join(", "),
        a.planner_budget_s
    )?;
    outln!(
        "| planner | set | success % | collision % | path length m | joint travel rad | plan time median ms \
         | p95 ms | shield changes/plan | shield stops/plan |"
    )?;
    outln!("|---|---|---|---|---|---|---|---|---|---|")?;
    for r in rows {
        let n = r.plans.max(1) as f64;
        let mut t = r.plan_time_s.clone();
        let per_plan = |k: u64| format!("{:.2}", k as f64 / n);
        let (changes, stops) = match r.shield {
            Some((c, s)) => (per_plan(c), per_plan(s)),
            None => ("-".into(), "-".into()),
        };
        // Over the successes: "-" when there is none.
        let over_successes = |v: &[f64]| match mean(v) {
            m if m.is_finite() => format!("{m:.3}"),
            _ => "-".into(),
        };
        outln!(
            "| {} | {} | {:.1} | {:.1} | {} | {} | {:.3} | {:.3} | {changes} | {stops} |",
            r.planner,
            r.set.name(),
            100.0 * r.success as f64 / n,
            100.0 * r.collision as f64 / n,
            over_successes(&r.path_length_m),
            over_successes(&r.joint_travel_rad),
            1e3 * quantile(&mut t, 0.5),
            1e3 * quantile(&mut t, 0.95),
        )?;
    }
    Ok(())
}
