use anyhow::{bail, Context, Result};
use stagerl::plan::Planner;
use stagerl::run::dir::RunDir;
use stagerl::sim::rrt_connect::RrtConnect;
use stagerl::view::View;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  stagerl plan --run runs/sac-sar --target 0.4,0.2,0.5\n  stagerl plan --controller jacobian --target 0.4,0.2,0.5 --format csv\n  stagerl plan --planner rrt-connect --targets requests.jsonl --scene table.toml --seed 7"
)]
pub struct Args {
    /// The run directory whose policy plans (holds config.toml and checkpoints/).
    #[arg(long, required_unless_present_any = ["controller", "planner"])]
    run: Option<PathBuf>,
    /// Checkpoint to plan with (default: the run's best, else final, else latest).
    #[arg(long, conflicts_with = "controller")]
    checkpoint: Option<PathBuf>,
    /// Plan with a scripted controller instead of a trained policy (on the arm and task of
    /// --run if given, else the default UR5 task); the same as --planner jacobian.
    #[arg(long, value_enum, conflicts_with = "planner")]
    controller: Option<Controller>,
    /// Who plans: `policy` (the trained policy of --run; the default when --run is given),
    /// `jacobian` (the damped-least-squares controller) or `rrt-connect` (the sampling-based
    /// reference planner: collision-free, within the speed limits). The scripted planners use
    /// the arm and task of --run if given, else the default UR5 task.
    #[arg(long, value_enum)]
    planner: Option<PlannerKind>,
    /// RRT-Connect's random seed (recorded in each plan's "rrt_connect" object); every plan
    /// starts from it, so a request gives the same path wherever it stands in a batch.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// RRT-Connect's wall-time budget per plan, seconds (0 < s <= 3600); an unsolved plan says why.
    #[arg(long, default_value_t = stagerl::sim::rrt_connect::DEFAULT_BUDGET_S)]
    planner_budget_s: f64,
    /// RRT-Connect's most tree extensions per plan, 1 to 100 000 000.
    #[arg(long, default_value_t = stagerl::sim::rrt_connect::DEFAULT_ITERATIONS,
          value_parser = clap::value_parser!(u32).range(1..=100_000_000))]
    planner_iterations: u32,
    /// Target X,Y,Z, metres, base frame.
    #[arg(long, allow_hyphen_values = true, required_unless_present = "targets", conflicts_with = "targets")]
    target: Option<String>,
    /// Start pose Q1,...,QN, radians (default: the task's home pose).
    #[arg(long, allow_hyphen_values = true, conflicts_with = "targets")]
    start: Option<String>,
    /// Batch mode: JSON lines {"target":[x,y,z]}, with optional "start":[..] (radians) and
    /// "obstacles":[{"shape":"sphere","radius_m":r,"position_m":[x,y,z]}, ..] (added to
    /// --scene), from FILE, or from standard input with `-`; one JSON line out per input.
    #[arg(long)]
    targets: Option<PathBuf>,
    /// A fixed scene for every plan: a TOML file of `[[obstacles]]` tables in the schema of
    /// `[[task.obstacles]]`; a request line's own "obstacles" add to it.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Step limit of a plan (default: the task's max_steps), 1 to 1 000 000.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    max_steps: Option<u32>,
    /// Output of a single plan: `jsonl` (one line per state, then the summary; the default
    /// when standard output is not a terminal) or `csv` (one joint per column; the summary on
    /// standard error).
    #[arg(long, value_enum)]
    format: Option<Format>,
    /// Also write the plan (or, in batch mode, the first 500 plans) as an animated 3D view: a
    /// self-contained HTML file (see `stagerl view`).
    #[arg(long)]
    view: Option<PathBuf>,
    /// Replace an existing --view file that holds something else.
    #[arg(long, requires = "view")]
    force: bool,
    /// Filter every command through the safety shield (`[task.shield]`: no checked pair closer
    /// than its margin within a step; a plan's output adds the `shield_*` counts). A run trained
    /// with `[task.shield] enabled = true` plans behind it without this flag too.
    #[arg(long)]
    shield: bool,
    /// Plan without the safety shield with a run trained with `[task.shield] enabled = true`
    /// (the policy alone).
    #[arg(long, conflicts_with = "shield")]
    no_shield: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Controller {
    /// The damped-least-squares Jacobian controller.
    Jacobian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PlannerKind {
    /// The trained policy of --run.
    Policy,
    /// The damped-least-squares Jacobian controller.
    Jacobian,
    /// RRT-Connect in joint space, with shortcutting.
    RrtConnect,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Csv,
    Jsonl,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(view) = &args.view {
        let inputs: Vec<&std::path::Path> =
            args.checkpoint.as_deref().into_iter().chain(args.targets.as_deref()).collect();
        stagerl::run::dir::check_output_path(view, "--view", &inputs)?;
    }
    let mut planner = planner(&args)?;
    if let Some(path) = &args.scene {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading --scene {}", path.display()))?;
        let name = path.display().to_string();
        let scene = stagerl::env::request::parse_scene(&text, &name)?;
        planner.set_scene(scene, &format!("--scene {name}: obstacles"))?;
    }
    if args.shield || args.no_shield {
        planner.set_shield(args.shield).context(if args.shield { "--shield" } else { "--no-shield" })?;
    }
    let mut view = args.view.as_ref().map(|_| View::for_planner(&view_title(&args), &planner));
    if let Some(path) = &args.targets {
        if args.format == Some(Format::Csv) {
            bail!("--format csv is for a single plan; batch mode (--targets) writes JSON lines");
        }
        let out = crate::out::stdout()?;
        if path.as_os_str() == "-" {
            crate::plan_batch::batch(&mut planner, std::io::stdin().lock(), out, view.as_mut())?;
        } else {
            let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
            crate::plan_batch::batch(&mut planner, std::io::BufReader::new(file), out, view.as_mut())
                .with_context(|| format!("planning the targets of {}", path.display()))?;
        }
        return write_view(&args, view.as_ref());
    }
    let target = numbers("--target", args.target.as_deref().unwrap_or_default())?;
    let start = args.start.as_deref().map(|s| numbers("--start", s)).transpose()?;
    let plan = planner.plan(&target, start.as_deref())?;
    if let Some(v) = &mut view {
        v.push_planned(&planner, "plan", [target[0], target[1], target[2]], &plan)?;
    }
    if let Some(w) = &plan.warning {
        errln!("stagerl: warning: {w}")?;
    }
    let format =
        args.format.unwrap_or(if std::io::stdout().is_terminal() { Format::Csv } else { Format::Jsonl });
    let summary =
        serde_json::to_string(&SummaryLine { summary: &plan.summary }).context("writing the summary")?;
    let mut out = crate::out::stdout()?;
    match format {
        Format::Csv => out.write_all(plan.to_csv().as_bytes()).context("writing to standard output")?,
        Format::Jsonl => {
            for k in 0..plan.rows() {
                serde_json::to_writer(&mut out, &plan.row(k)).context("writing to standard output")?;
                out.write_all(b"\n").context("writing to standard output")?;
            }
            writeln!(out, "{summary}").context("writing to standard output")?;
        }
    }
    out.flush().context("writing to standard output")?;
    if format == Format::Csv {
        errln!("{summary}")?;
    }
    write_view(&args, view.as_ref())
}

/// The planner the flags choose (`--controller jacobian` is `--planner jacobian`).
fn kind(args: &Args) -> Option<PlannerKind> {
    match (args.planner, args.controller) {
        (Some(k), _) => Some(k),
        (None, Some(Controller::Jacobian)) => Some(PlannerKind::Jacobian),
        (None, None) => args.run.as_ref().map(|_| PlannerKind::Policy),
    }
}

fn view_title(args: &Args) -> String {
    match (&args.run, kind(args)) {
        (_, Some(PlannerKind::Jacobian)) => "Jacobian controller".into(),
        (_, Some(PlannerKind::RrtConnect)) => "RRT-Connect".into(),
        (Some(run), _) => format!("plans of {}", run.display()),
        (None, _) => String::new(),
    }
}

/// Write `view` to `--view`, if asked for; a line on standard error says what was written.
fn write_view(args: &Args, view: Option<&View>) -> Result<()> {
    let (Some(path), Some(view)) = (&args.view, view) else { return Ok(()) };
    let written = stagerl::io::write_new(path, view.to_html()?.as_bytes(), args.force)
        .with_context(|| format!("writing the view to {}", path.display()))?;
    errln!("stagerl: view of {} plan(s) in {}: {written}", view.trajectories.len(), path.display())
}

/// The last line of a plan's output: `{"summary":{...}}`, fields in the summary's order.
#[derive(serde::Serialize)]
struct SummaryLine<'a> {
    summary: &'a stagerl::plan::PlanSummary,
}

/// The planner the flags ask for.
fn planner(args: &Args) -> Result<Planner> {
    let run = args.run.as_deref().map(RunDir::new);
    let cfg = match &run {
        Some(r) => Some(r.load_config().with_context(|| format!("reading the run in {}", r.root.display()))?),
        None => None,
    };
    if args.checkpoint.is_some() && kind(args) != Some(PlannerKind::Policy) {
        bail!("--checkpoint is for --planner policy (a trained run's policy)");
    }
    match (kind(args), &run) {
        (Some(PlannerKind::Jacobian), _) => Ok(Planner::jacobian(&cfg.unwrap_or_default(), args.max_steps)?),
        (Some(PlannerKind::RrtConnect), _) => {
            let rrt = RrtConnect {
                seed: args.seed,
                budget_s: args.planner_budget_s,
                max_iterations: args.planner_iterations,
                ..RrtConnect::default()
            };
            Ok(Planner::rrt_connect(&cfg.unwrap_or_default(), args.max_steps, rrt)?)
        }
        (Some(PlannerKind::Policy) | None, Some(run)) => {
            let (_, planner) = Planner::from_run(run, args.checkpoint.as_deref(), args.max_steps)?;
            Ok(planner)
        }
        (_, None) => {
            bail!("give --run DIR (a trained run) for --planner policy, or --planner jacobian|rrt-connect")
        }
    }
}

/// Comma-separated numbers of flag `flag`.
fn numbers(flag: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',')
        .map(|x| {
            x.trim().parse::<f64>().with_context(|| {
                format!("{flag} {}: `{}` is not a number (comma-separated numbers expected)", text, x.trim())
            })
        })
        .collect()
}
