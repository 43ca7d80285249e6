use anyhow::{Context, Result};
use stagerl::run::dir::RunDir;
use std::path::PathBuf;

#[derive(clap::Args)]
#[command(after_help = "Example:\n  stagerl export --run runs/sac-sar --out policy.onnx")]
pub struct Args {
    #[command(flatten)]
    run: super::RunArgs,
    /// The ONNX file to write (opset 13; input `observation` [batch, obs_dim] f32, output
    /// `joint_velocity` [batch, dof] f32, rad/s).
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing --out file that holds something else.
    #[arg(long)]
    force: bool,
}

pub fn run(args: Args) -> Result<()> {
    let run = RunDir::new(&args.run.run);
    let inputs: Vec<&std::path::Path> = args.run.checkpoint.as_deref().into_iter().collect();
    stagerl::run::dir::check_output_path(&args.out, "--out", &inputs)?;
    let (checkpoint, bytes) = stagerl::export::onnx_of_run(&run, args.run.checkpoint.as_deref())
        .with_context(|| format!("exporting the policy of the run in {}", args.run.run.display()))?;
    stagerl::run::dir::check_output_path(&args.out, "--out", &[&checkpoint])?;
    let written = stagerl::io::write_new(&args.out, &bytes, args.force)
        .with_context(|| format!("writing the ONNX model to {}", args.out.display()))?;
    outln!("{} ({} bytes, from {}): {written}", args.out.display(), bytes.len(), checkpoint.display())
}
