//! The off-policy agents. Each algorithm reads top to bottom in its own file ([`ddpg`], [`td3`],
//! [`sac`]); what they share (the [`Agent`] verbs, checkpoint helpers, exploration noise) lives
//! here once. The replay buffer and the training loop are in [`crate::replay`] and
//! [`crate::train`].

mod config;
pub mod ddpg;
pub mod noise;
pub mod sac;
pub mod td3;

pub use config::{AgentConfig, Algo, NoiseKind, MAX_BATCH_VALUES, MAX_BUFFER_SIZE};

use crate::checkpoint::Checkpoint;
use crate::nn::{first_non_finite, Adam, Mlp};
use crate::replay::Batch;
use crate::{Error, Result};

/// What one gradient update measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Mean squared TD error of the critic(s).
    pub critic_loss: f64,
    /// Actor loss, when the actor was updated in this step.
    pub actor_loss: Option<f64>,
    /// SAC's entropy coefficient.
    pub alpha: Option<f64>,
    /// SAC's policy entropy estimate, -mean log pi(a|s).
    pub entropy: Option<f64>,
}

/// The verbs every agent offers.
pub trait Agent: Send {
    /// Which algorithm.
    fn algo(&self) -> Algo;
    /// Observation length.
    fn obs_dim(&self) -> usize;
    /// Action length.
    fn act_dim(&self) -> usize;
    /// Exploration action for one observation (training), in [-1, 1].
    fn act(&mut self, obs: &[f32], action: &mut [f32]);
    /// Deterministic action for one observation (evaluation, deployment), in [-1, 1].
    fn predict(&mut self, obs: &[f32], action: &mut [f32]);
    /// Called at the start of every training episode (resets temporally correlated noise).
    fn begin_episode(&mut self) {}
    /// One gradient update on a sampled batch.
    fn update(&mut self, batch: &Batch) -> UpdateStats;
    /// Write every network, target network, optimiser state and random state to `ck`.
    fn save(&self, ck: &mut Checkpoint);
    /// Restore what [`Agent::save`] wrote; shapes must match this agent's.
    fn load(&mut self, ck: &Checkpoint) -> Result<()>;
    /// The first non-finite parameter or gradient, described (network, tensor, index).
    fn first_non_finite(&self) -> Option<String>;
}

/// Build the agent the config asks for. `seed` fixes its initial weights and its noise.
pub fn build(cfg: &AgentConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Result<Box<dyn Agent>> {
    cfg.validate()?;
    Ok(match cfg.algo {
        Algo::Ddpg => Box::new(ddpg::Ddpg::new(cfg, obs_dim, act_dim, seed)),
        Algo::Td3 => Box::new(td3::Td3::new(cfg, obs_dim, act_dim, seed)),
        Algo::Sac => Box::new(sac::Sac::new(cfg, obs_dim, act_dim, seed)),
    })
}

/// Layer sizes `[input, hidden..., output]`.
pub(crate) fn sizes(input: usize, hidden: &[usize], output: usize) -> Vec<usize> {
    let mut s = Vec::with_capacity(hidden.len() + 2);
    s.push(input);
    s.extend_from_slice(hidden);
    s.push(output);
    s
}

/// Save a network's tensors as `{prefix}.layer{i}.weight|bias`.
pub(crate) fn save_mlp(ck: &mut Checkpoint, prefix: &str, net: &Mlp<f32>) {
    for t in net.tensors() {
        ck.put_tensor(&format!("{prefix}.{}", t.name), &t.shape, &net.params()[t.range()]);
    }
}

/// Load a network saved by [`save_mlp`]; every tensor's shape must match and every value be
/// finite (a damaged network would only show later, as a NaN action).
pub(crate) fn load_mlp(ck: &Checkpoint, prefix: &str, net: &mut Mlp<f32>) -> Result<()> {
    for t in net.tensors() {
        let name = format!("{prefix}.{}", t.name);
        let (shape, data) = ck.tensor(&name)?;
        if shape != t.shape.as_slice() {
            return Err(Error::InvalidInput(format!(
                "{}: tensor `{name}` has shape {shape:?}, this agent's has {:?} \
                 (a different network size or observation?)",
                ck.name(),
                t.shape
            )));
        }
        if let Some(i) = first_non_finite(data) {
            return Err(Error::InvalidInput(format!(
                "{}: tensor `{name}`[{i}] = {} is not finite: the network is damaged",
                ck.name(),
                data[i]
            )));
        }
        net.params_mut()[t.range()].copy_from_slice(data);
    }
    Ok(())
}

/// Save an optimiser's moments (`{prefix}.m`, `{prefix}.v`) and step count.
pub(crate) fn save_adam(ck: &mut Checkpoint, prefix: &str, opt: &Adam<f32>) {
    ck.put_tensor(&format!("{prefix}.m"), &[opt.m.len()], &opt.m);
    ck.put_tensor(&format!("{prefix}.v"), &[opt.v.len()], &opt.v);
    ck.put_json(&format!("{prefix}.step"), &opt.step);
}

/// Load what [`save_adam`] wrote.
pub(crate) fn load_adam(ck: &Checkpoint, prefix: &str, opt: &mut Adam<f32>) -> Result<()> {
    ck.read_tensor_into(&format!("{prefix}.m"), &mut opt.m)?;
    ck.read_tensor_into(&format!("{prefix}.v"), &mut opt.v)?;
    opt.step = ck.json(&format!("{prefix}.step"))?;
    Ok(())
}

/// Describe the first non-finite parameter or gradient among named networks.
pub(crate) fn find_non_finite(nets: &[(&str, &Mlp<f32>)]) -> Option<String> {
    for (name, net) in nets {
        for (what, values) in [("parameter", net.params()), ("gradient", net.grads())] {
            if let Some(i) = first_non_finite(values) {
                let tensor = net.tensors().into_iter().find(|t| t.range().contains(&i));
                let tname = tensor.map(|t| t.name).unwrap_or_default();
                return Some(format!("{name} {what} {tname}[{i}] = {}", values[i]));
            }
        }
    }
    None
}

/// Clip a gradient to a global L2 norm when `max_norm > 0`.
pub(crate) fn clip(grads: &mut [f32], max_norm: f64) {
    if max_norm > 0.0 {
        crate::nn::clip_grad_norm(grads, max_norm as f32);
    }
}

/// One regression step of a critic towards the targets `y` (`batch` rows): forward on `input`,
/// mean squared error, backward, Adam. `dq` is scratch of at least `batch` values. Returns the loss.
pub(crate) fn fit_critic(
    q: &mut Mlp<f32>,
    opt: &mut Adam<f32>,
    input: &[f32],
    y: &[f32],
    dq: &mut [f32],
    max_grad_norm: f64,
) -> f64 {
    let b = y.len();
    let pred = q.forward(input, b);
    let loss = crate::nn::mse_loss(pred, y, &mut dq[..b]);
    q.zero_grad();
    q.backward(&dq[..b]);
    step(q, opt, max_grad_norm);
    f64::from(loss)
}

/// Apply one Adam step to a network from its accumulated gradients (clipped first if asked).
pub(crate) fn step(net: &mut Mlp<f32>, opt: &mut Adam<f32>, max_grad_norm: f64) {
    clip(net.grads_mut(), max_grad_norm);
    let (p, g) = net.params_and_grads();
    opt.step(p, g);
}

#[cfg(test)]
mod tests;
