//! Running observation normalisation, as Gymnasium's `NormalizeObservation` wrapper (which
//! CleanRL's `ppo_continuous_action` applies) and Stable-Baselines3's `VecNormalize`:
//!
//! `x' = clip((x - mu) / sqrt(sigma^2 + 1e-8), -c, c)`, per observation entry,
//!
//! where `mu` and `sigma^2` are the running mean and (population) variance of every observation
//! the policy has acted on in training, merged batch by batch with Chan et al.'s parallel
//! update (count starts at 1e-4, mean at 0, variance at 1, as Gymnasium's `RunningMeanStd`):
//! for a batch of `m` rows with mean `mu_b` and variance `s_b`, `delta = mu_b - mu`,
//! `N' = N + m`, `mu' = mu + delta m / N'`, `sigma'^2 = (sigma^2 N + s_b m + delta^2 N m / N') / N'`.
//!
//! The statistics are kept in f64; the formula runs in f32 on `mu` and
//! `sqrt(sigma^2 + 1e-8)` rounded to f32 once ([`ObsNorm::mean`], [`ObsNorm::std`]), so that an
//! exported graph (Sub, Div, Clip on those two tensors) gives the same bits as training,
//! evaluation and planning. Evaluation and planning never update the statistics.
//!
//! PPO (`agent.ppo.norm_obs`) updates them on each batch of observations its policy acts on and
//! keeps the normalised observations in its rollout. The off-policy agents (DDPG, TD3, SAC with
//! `agent.norm_obs`, HER included; [`OffPolicyNorm`]) do as Stable-Baselines3's `VecNormalize`
//! with an off-policy algorithm:
//! - the statistics are updated from each observation as it is collected (every observation the
//!   training episodes act on, the uniform warm-up steps included), never from replay samples;
//! - the replay buffer stores raw observations; each update normalises its sampled batch (`s`
//!   and `s'`) with the statistics of that moment, so that a hindsight-relabelled goal is
//!   normalised as an observed one;
//! - the actor and the critics (and their targets) read normalised observations only;
//! - acting, evaluation, export and planning normalise with the statistics as they are (saved in
//!   the checkpoint: frozen at evaluation).

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// `agent.ppo.norm_obs = { clip = 10.0 }`: normalise observations with running statistics;
/// unset: off.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ObsNormConfig {
    /// The normalised values are clipped to `[-clip, clip]` (Gymnasium and CleanRL: 10).
    pub clip: f64,
}

impl Default for ObsNormConfig {
    fn default() -> Self {
        ObsNormConfig { clip: 10.0 }
    }
}

impl ObsNormConfig {
    /// Check `clip`; the error names the field.
    pub fn validate(&self, field: &str) -> Result<()> {
        if !(self.clip.is_finite() && self.clip > 0.0 && self.clip <= 1e6) {
            return Err(Error::config(format!("{field}.clip"), self.clip, "a number in (0, 1e6]"));
        }
        Ok(())
    }
}

/// The running statistics (what a checkpoint keeps to resume them exactly).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningStats {
    /// Observations merged so far, plus the initial 1e-4.
    pub count: f64,
    pub mean: Vec<f64>,
    /// Population variance.
    pub var: Vec<f64>,
}

/// Checkpoint name of the f32 means the formula uses.
pub const MEAN_TENSOR: &str = "obs_norm.mean";
/// Checkpoint name of the f32 standard deviations the formula uses.
pub const STD_TENSOR: &str = "obs_norm.std";

/// Added to the variance under the square root.
const VAR_EPS: f64 = 1e-8;

/// A running normaliser of observations of `dim` values (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ObsNorm {
    pub stats: RunningStats,
    /// `mu` in f32, as the formula uses it.
    pub mean: Vec<f32>,
    /// `sqrt(sigma^2 + 1e-8)` in f32, as the formula uses it.
    pub std: Vec<f32>,
    pub clip: f32,
    // Scratch: a batch's mean and variance.
    batch_mean: Vec<f64>,
    batch_var: Vec<f64>,
}

impl ObsNorm {
    pub fn new(dim: usize, cfg: &ObsNormConfig) -> ObsNorm {
        let mut n = ObsNorm {
            stats: RunningStats { count: 1e-4, mean: vec![0.0; dim], var: vec![1.0; dim] },
            mean: vec![0.0; dim],
            std: vec![0.0; dim],
            clip: cfg.clip as f32,
            batch_mean: vec![0.0; dim],
            batch_var: vec![0.0; dim],
        };
        n.derive();
        n
    }

    /// Merge the `rows` observations of `obs` (row-major) into the statistics.
    pub fn update(&mut self, obs: &[f32], rows: usize) {
        let d = self.mean.len();
        if rows == 0 || d == 0 {
            return;
        }
        let m = rows as f64;
        self.batch_mean.fill(0.0);
        self.batch_var.fill(0.0);
        for row in obs[..rows * d].chunks_exact(d) {
            for (s, &x) in self.batch_mean.iter_mut().zip(row) {
                *s += f64::from(x);
            }
        }
        self.batch_mean.iter_mut().for_each(|s| *s /= m);
        for row in obs[..rows * d].chunks_exact(d) {
            for ((s, &x), &mu) in self.batch_var.iter_mut().zip(row).zip(&self.batch_mean) {
                *s += (f64::from(x) - mu).powi(2);
            }
        }
        self.batch_var.iter_mut().for_each(|s| *s /= m);
        let st = &mut self.stats;
        let total = st.count + m;
        for j in 0..d {
            let delta = self.batch_mean[j] - st.mean[j];
            st.mean[j] += delta * m / total;
            let m2 = st.var[j] * st.count + self.batch_var[j] * m + delta * delta * st.count * m / total;
            st.var[j] = m2 / total;
        }
        st.count = total;
        self.derive();
    }

    /// Normalise `obs` (any number of rows) into `out`.
    pub fn apply(&self, obs: &[f32], out: &mut [f32]) {
        let d = self.mean.len();
        for (o, x) in out.chunks_exact_mut(d).zip(obs.chunks_exact(d)) {
            for j in 0..d {
                o[j] = ((x[j] - self.mean[j]) / self.std[j]).clamp(-self.clip, self.clip);
            }
        }
    }

    /// Restore the statistics (from a checkpoint); an error if they do not fit.
    pub fn restore(&mut self, stats: RunningStats) -> Result<()> {
        let d = self.mean.len();
        let ok = stats.mean.len() == d
            && stats.var.len() == d
            && stats.count.is_finite()
            && stats.count > 0.0
            && stats.mean.iter().all(|x| x.is_finite())
            && stats.var.iter().all(|x| x.is_finite() && *x >= 0.0);
        if !ok {
            return Err(Error::InvalidInput(format!(
                "observation normalisation statistics do not fit: {} means and {} variances \
                 (count {}) for observations of {d} values; all must be finite, variances >= 0",
                stats.mean.len(),
                stats.var.len(),
                stats.count
            )));
        }
        self.stats = stats;
        self.derive();
        Ok(())
    }

    /// The f32 mean and standard deviation the formula uses.
    fn derive(&mut self) {
        for j in 0..self.mean.len() {
            self.mean[j] = self.stats.mean[j] as f32;
            self.std[j] = (self.stats.var[j] + VAR_EPS).sqrt() as f32;
        }
    }
}

/// The observation normalisation of an off-policy agent (see the module docs): the running
/// normaliser and its scratch, preallocated to the batch size (no allocation per update).
#[derive(Clone, Debug)]
pub struct OffPolicyNorm {
    pub norm: ObsNorm,
    obs: Vec<f32>,
    next_obs: Vec<f32>,
    one: Vec<f32>,
}

impl OffPolicyNorm {
    /// For observations of `dim` values and batches of up to `batch` rows.
    pub fn new(dim: usize, cfg: &ObsNormConfig, batch: usize) -> OffPolicyNorm {
        OffPolicyNorm {
            norm: ObsNorm::new(dim, cfg),
            obs: vec![0.0; batch * dim],
            next_obs: vec![0.0; batch * dim],
            one: vec![0.0; dim],
        }
    }

    /// Merge one collected observation into the statistics.
    pub fn observe(&mut self, obs: &[f32]) {
        self.norm.update(obs, 1);
    }

    /// One observation, normalised (acting, evaluation).
    pub fn one(&mut self, obs: &[f32]) -> &[f32] {
        self.norm.apply(obs, &mut self.one);
        &self.one
    }

    /// A batch's observations and next observations (`rows` rows each), normalised.
    pub fn batch(&mut self, obs: &[f32], next_obs: &[f32], rows: usize) -> (&[f32], &[f32]) {
        let n = rows * self.norm.mean.len();
        self.norm.apply(&obs[..n], &mut self.obs[..n]);
        self.norm.apply(&next_obs[..n], &mut self.next_obs[..n]);
        (&self.obs[..n], &self.next_obs[..n])
    }
}

/// An off-policy agent's observations: `raw` itself, or normalised by `norm` (the batch's `s`
/// and `s'`, `rows` rows).
pub fn batch_inputs<'a>(
    norm: &'a mut Option<OffPolicyNorm>,
    obs: &'a [f32],
    next_obs: &'a [f32],
    rows: usize,
) -> (&'a [f32], &'a [f32]) {
    match norm {
        Some(n) => n.batch(obs, next_obs, rows),
        None => (obs, next_obs),
    }
}

/// One observation for an off-policy agent's actor: `obs` itself, or normalised by `norm`.
pub fn one_input<'a>(norm: &'a mut Option<OffPolicyNorm>, obs: &'a [f32]) -> &'a [f32] {
    match norm {
        Some(n) => n.one(obs),
        None => obs,
    }
}

/// Saved as its [`RunningStats`] (JSON; f64 values round-trip exactly).
impl crate::agent::parts::State for ObsNorm {
    fn save_json(&self, ck: &mut crate::io::checkpoint::Checkpoint, name: &str) {
        ck.put_json(name, &self.stats);
    }
    fn load_json(&mut self, ck: &crate::io::checkpoint::Checkpoint, name: &str) -> Result<()> {
        self.restore(ck.json(name)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Merged batch by batch, the statistics equal the whole data's mean and variance (with the
    /// initial pseudo-count's pull, which is tiny).
    #[test]
    fn batches_merge_to_the_whole_datas_moments() {
        let mut n = ObsNorm::new(2, &ObsNormConfig::default());
        let mut rng = crate::base::rng::Rng::new(3);
        let data: Vec<f32> =
            (0..2 * 300).map(|i| (rng.normal() * 2.0 + (i % 2) as f64 * 5.0) as f32).collect();
        for chunk in data.chunks(2 * 30) {
            n.update(chunk, chunk.len() / 2);
        }
        for j in 0..2 {
            let xs: Vec<f64> = data.iter().skip(j).step_by(2).map(|&x| f64::from(x)).collect();
            let mean = xs.iter().sum::<f64>() / 300.0;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 300.0;
            assert!((n.stats.mean[j] - mean).abs() < 1e-5, "mean {j}: {} vs {mean}", n.stats.mean[j]);
            assert!(
                (n.stats.var[j] - var).abs() < 1e-3 * var.max(1.0),
                "var {j}: {} vs {var}",
                n.stats.var[j]
            );
        }
        assert!((n.stats.count - 300.0).abs() < 1e-3);
    }

    /// `apply` is the documented f32 formula, clip included.
    #[test]
    fn apply_is_the_formula_and_clips() {
        let mut n = ObsNorm::new(3, &ObsNormConfig { clip: 2.0 });
        n.update(&[0.0, 10.0, -1.0, 2.0, 10.0, 1.0], 2);
        let x = [1.0f32, 10.0, 100.0];
        let mut out = [0.0f32; 3];
        n.apply(&x, &mut out);
        for j in 0..3 {
            let s = (n.stats.var[j] + 1e-8).sqrt() as f32;
            let want = ((x[j] - n.stats.mean[j] as f32) / s).clamp(-2.0, 2.0);
            assert_eq!(out[j].to_bits(), want.to_bits(), "entry {j}");
        }
        // A constant entry (variance ~0) stays finite; a far value is clipped.
        assert!(out[1].is_finite());
        assert_eq!(out[2], 2.0);
    }

    #[test]
    fn bad_statistics_and_settings_are_errors_naming_what() {
        let mut n = ObsNorm::new(2, &ObsNormConfig::default());
        let bad = RunningStats { count: 1.0, mean: vec![0.0], var: vec![1.0, 1.0] };
        assert!(n.restore(bad).unwrap_err().to_string().contains("1 means"));
        let nan = RunningStats { count: 1.0, mean: vec![0.0, f64::NAN], var: vec![1.0, 1.0] };
        assert!(n.restore(nan).is_err());
        let e = ObsNormConfig { clip: 0.0 }.validate("agent.ppo.norm_obs").unwrap_err().to_string();
        assert!(e.contains("agent.ppo.norm_obs.clip") && e.contains("(0, 1e6]"), "{e}");
    }
}
