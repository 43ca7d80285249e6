use anyhow::{Context, Result};
use stagerl::report::metrics::ConvergenceCriterion;
use stagerl::report::{self, claims::Verdict, ReportOptions};
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  stagerl report runs/quick --out runs/quick/report\n  stagerl report docs/results/paper/runs.tar.xz --out /tmp/paper-report"
)]
pub struct Args {
    /// Directory holding run directories (at depth 1 or 2; a run has config.toml and episodes.csv),
    /// or a study's runs archive (`runs.tar.xz`, as under docs/results/).
    dir: PathBuf,
    /// Output directory (default: DIR/report; for an archive, `report` beside it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// E_start: moving-average window, episodes.
    #[arg(long, default_value_t = ConvergenceCriterion::default().window)]
    window: usize,
    /// E_start: fraction of the last episodes whose mean is the converged level.
    #[arg(long, default_value_t = ConvergenceCriterion::default().tail_fraction)]
    tail_fraction: f64,
    /// E_start: band half-width in standard deviations of the tail's episode rewards.
    #[arg(long, default_value_t = ConvergenceCriterion::default().band_k)]
    band_k: f64,
    /// E_start: smallest band half-width, reward units.
    #[arg(long, default_value_t = ConvergenceCriterion::default().band_floor)]
    band_floor: f64,
    /// Evaluation trajectories to draw for the best and the worst reward function (0: none; at
    /// most 1000).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(0..=i64::from(report::MAX_TRAJECTORIES)))]
    trajectories: u32,
    /// Also use runs with fewer episodes than configured (still training, or stopped early).
    #[arg(long)]
    include_incomplete: bool,
}

pub fn run(args: Args) -> Result<()> {
    let out = args.out.clone().unwrap_or_else(|| {
        if report::archive::is_archive(&args.dir) && !args.dir.is_dir() {
            args.dir.parent().unwrap_or(std::path::Path::new(".")).join("report")
        } else {
            args.dir.join("report")
        }
    });
    let opts = ReportOptions {
        out: out.clone(),
        criterion: ConvergenceCriterion {
            window: args.window,
            tail_fraction: args.tail_fraction,
            band_k: args.band_k,
            band_floor: args.band_floor,
        },
        trajectories: args.trajectories,
        include_incomplete: args.include_incomplete,
        command: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
    };
    let r = report::generate(&args.dir, &opts)
        .with_context(|| format!("reporting on the runs in {}", args.dir.display()))?;
    let runs: usize = r.groups.iter().map(|g| g.seeds).sum();
    let excluded: usize = r.groups.iter().map(|g| g.excluded.len()).sum();
    outln!(
        "{runs} run(s) in {} group(s) from {}{}{}",
        r.groups.len(),
        args.dir.display(),
        if excluded > 0 { format!(", {excluded} excluded (see the notes)") } else { String::new() },
        if r.skipped.is_empty() { String::new() } else { format!(", {} unreadable", r.skipped.len()) }
    )?;
    for g in &r.groups {
        outln!(
            "  {:<5} {:<8} {} seed(s), {} converged{}",
            g.algo.to_string(),
            g.reward.name(),
            g.seeds,
            g.converged,
            if g.primary { String::new() } else { format!("  [{}]", g.variant) }
        )?;
    }
    let count = |v: Verdict| r.claims.iter().filter(|c| c.verdict == v).count();
    outln!(
        "claims: {} supported, {} contradicted, {} inconclusive, {} not measurable",
        count(Verdict::Supported),
        count(Verdict::Contradicted),
        count(Verdict::Inconclusive),
        count(Verdict::NotMeasurable)
    )?;
    for w in &r.warnings {
        errln!("warning: {w}")?;
    }
    for s in &r.skipped {
        errln!("warning: {} not read: {}", s.name, s.reason)?;
    }
    outln!("wrote {}:", out.display())?;
    for f in &r.files {
        outln!("  {}", f.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default())?;
    }
    Ok(())
}
