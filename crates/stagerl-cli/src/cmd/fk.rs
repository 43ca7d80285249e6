use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use stagerl::robot::Chain;

#[derive(clap::Args)]
pub struct Args {
    /// `ur5` for the bundled arm, or a path to a URDF file.
    #[arg(long, default_value = "ur5")]
    robot: String,
    /// Tip link (default: the URDF's only leaf link).
    #[arg(long)]
    tip: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Input {
    joints: Vec<f64>,
}

#[derive(Serialize)]
struct Output {
    position: [f64; 3],
    quaternion: [f64; 4],
}

pub fn run(args: Args) -> Result<()> {
    let chain = Chain::load(&args.robot, args.tip.as_deref())
        .with_context(|| format!("loading robot `{}`", args.robot))?;
    let stdin = std::io::stdin().lock();
    let stdout = std::io::BufWriter::new(std::io::stdout().lock());
    crate::jsonl::process(stdin, stdout, |input: Input| {
        let pose = chain.try_fk(&input.joints)?;
        Ok(Output { position: pose.position.into(), quaternion: pose.quaternion_xyzw() })
    })
}
