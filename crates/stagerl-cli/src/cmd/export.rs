use anyhow::{Context, Result};
use stagerl::rundir::RunDir;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The run directory whose policy is exported (holds config.toml and checkpoints/).
    #[arg(long)]
    run: PathBuf,
    /// Checkpoint to export (default: the run's best, else final, else latest).
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// The ONNX file to write (opset 13; input `observation` [batch, obs_dim] f32, output
    /// `joint_velocity` [batch, dof] f32, rad/s).
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing --out file that holds something else.
    #[arg(long)]
    force: bool,
}

pub fn run(args: Args) -> Result<()> {
    let run = RunDir::new(&args.run);
    let (checkpoint, bytes) = stagerl::export::onnx_of_run(&run, args.checkpoint.as_deref())
        .with_context(|| format!("exporting the policy of the run in {}", args.run.display()))?;
    let written = stagerl::io::write_new(&args.out, &bytes, args.force)
        .with_context(|| format!("writing the ONNX model to {}", args.out.display()))?;
    outln!("{} ({} bytes, from {}): {written}", args.out.display(), bytes.len(), checkpoint.display())
}
