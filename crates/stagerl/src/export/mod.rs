//! Exporting a trained policy for use outside stagerl: [`onnx`], the actor with the action rule
//! and the speed-limit scaling inside the graph (and the observation's normalisation, if any).

pub mod onnx;

use std::path::{Path, PathBuf};

use crate::run::dir::RunDir;
use crate::run::policy::PolicySpec;
use crate::Result;

/// The ONNX model of a run directory's checkpoint (`checkpoint`, else the best available: best,
/// final, latest), the checkpoint's path first. The checkpoint is loaded as `stagerl eval` and
/// `stagerl plan` load it (checked against the run's config).
pub fn onnx_of_run(run: &RunDir, checkpoint: Option<&Path>) -> Result<(PathBuf, Vec<u8>)> {
    let cfg = run.load_config()?;
    let (path, env, agent) = crate::train::eval::load_run_agent(run, &cfg, checkpoint)?;
    let spec = PolicySpec::new(&cfg, &env, agent.as_ref());
    // The checkpoint as the run directory names it (`checkpoints/best.safetensors`), or by its
    // file name when it lies elsewhere: no absolute path of this machine goes into the model.
    let checkpoint = match path.strip_prefix(&run.root) {
        Ok(rel) => rel.display().to_string(),
        Err(_) => path.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
    };
    let meta = onnx::ModelInfo { config_hash: crate::train::config_hash(&cfg), checkpoint };
    let bytes = onnx::encode(&spec, agent.actor(), agent.obs_norm(), &meta)?;
    Ok((path, bytes))
}
