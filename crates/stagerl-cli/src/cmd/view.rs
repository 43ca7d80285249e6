use anyhow::{Context, Result};
use stagerl::run::dir::RunDir;
use stagerl::view::{self, ViewSource};
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl view --run runs/sac-sar --targets 5 --out view.html")]
pub struct Args {
    #[command(flatten)]
    run: super::RunArgs,
    /// Plan to the first N targets of the evaluation seed --seed, from the home pose (1 to
    /// 500; default 5).
    #[arg(long, conflicts_with = "plans", value_parser = clap::value_parser!(u32).range(1..=view::MAX_TRAJECTORIES as i64))]
    targets: Option<u32>,
    /// Seed of the --targets (default: the run's train.eval_seed, the targets of its
    /// evaluations).
    #[arg(long, conflicts_with = "plans")]
    seed: Option<u64>,
    /// Plan the requests of FILE instead: JSON lines {"target":[x,y,z]}, with optional
    /// "start":[..] (radians) and "obstacles":[..] (the schema of [[task.obstacles]]), as
    /// `stagerl plan --targets` reads them; each line's scene is drawn.
    #[arg(long)]
    plans: Option<PathBuf>,
    /// The HTML file to write (self-contained: opens without network access).
    #[arg(long, default_value = "view.html")]
    out: PathBuf,
    /// Replace an existing --out file that holds something else.
    #[arg(long)]
    force: bool,
}

pub fn run(args: Args) -> Result<()> {
    let run = RunDir::new(&args.run.run);
    let inputs: Vec<&std::path::Path> =
        args.run.checkpoint.as_deref().into_iter().chain(args.plans.as_deref()).collect();
    stagerl::run::dir::check_output_path(&args.out, "--out", &inputs)?;
    let source = match &args.plans {
        Some(p) => ViewSource::Requests { text: read_plans(p)?, origin: p.display().to_string() },
        None => {
            let seed = match args.seed {
                Some(s) => s,
                None => {
                    run.load_config()
                        .with_context(|| format!("reading the run in {}", args.run.run.display()))?
                        .train
                        .eval_seed
                }
            };
            ViewSource::Targets { count: args.targets.unwrap_or(5), seed }
        }
    };
    let v = view::view_of_run(&run, args.run.checkpoint.as_deref(), &source)
        .with_context(|| format!("viewing the policy of the run in {}", args.run.run.display()))?;
    let written = stagerl::io::write_new(&args.out, v.to_html()?.as_bytes(), args.force)
        .with_context(|| format!("writing the view to {}", args.out.display()))?;
    let reached = v.trajectories.iter().filter(|t| t.reached).count();
    outln!("{}: {} trajectories ({reached} reached), {written}", args.out.display(), v.trajectories.len())
}

/// The plans file, at most [`view::MAX_PLANS_FILE_BYTES`].
fn read_plans(path: &std::path::Path) -> Result<String> {
    use std::io::Read;
    let context = || format!("reading the plans file {}", path.display());
    let file = std::fs::File::open(path).with_context(context)?;
    let mut text = String::new();
    file.take(view::MAX_PLANS_FILE_BYTES + 1).read_to_string(&mut text).with_context(context)?;
    if text.len() as u64 > view::MAX_PLANS_FILE_BYTES {
        anyhow::bail!(
            "the plans file {} is larger than {} bytes; a view shows at most {} plans",
            path.display(),
            view::MAX_PLANS_FILE_BYTES,
            view::MAX_TRAJECTORIES
        );
    }
    Ok(text)
}
