//! The TOML configuration: one schema for the arm, the task, the reward, the agent and the
//! training run, assembled here from the sections their modules own ([`RobotConfig`] beside the
//! robot, [`TaskConfig`] beside the environment, [`RewardConfig`] beside the rewards,
//! [`AgentConfig`] beside the agents, [`TrainConfig`] beside the training schedule), and its one
//! check and resolution against the arm ([`Config::resolve`], `resolved.rs`), which builds the
//! environments and the agent. Unknown fields are rejected; every
//! value is validated with an error that names the field, the value and what is allowed.
//!
//! Defaults are the paper's where it gives a value, and the choices of the design notes
//! (`docs/design.md`) elsewhere.

use serde::{Deserialize, Serialize};
use std::path::Path;

use crate::env::{ReachEnv, VecEnv};
use crate::{Error, Result};

use crate::agent::AgentConfig;
use crate::env::TaskConfig;
use crate::reward::RewardConfig;
use crate::robot::RobotConfig;

pub mod curriculum;
pub mod demonstrations;
mod resolved;
pub mod schema;
mod train;
pub use curriculum::{CurriculumConfig, CurriculumState};
pub use demonstrations::DemonstrationsConfig;
pub use resolved::Resolved;
pub use train::{TrainConfig, MAX_EVAL_TRIALS};

/// The whole configuration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub robot: RobotConfig,
    pub task: TaskConfig,
    pub reward: RewardConfig,
    pub agent: AgentConfig,
    pub train: TrainConfig,
}

/// The largest config file read, bytes (a config is a few kB).
pub const MAX_CONFIG_BYTES: u64 = 16 << 20;

/// The most memory a run may be estimated to need ([`Config::estimated_memory`]): 16 GiB.
pub const MAX_RUN_MEMORY_BYTES: f64 = 16.0 * (1u64 << 30) as f64;

/// Joints assumed by [`Config::validate`]'s memory estimate (the URDF is not loaded there): the
/// UR5's. The networks' hidden layers dominate the estimate wherever it comes near the limit.
const ESTIMATE_DOF: usize = 6;

/// A training run's estimated memory, bytes, by what holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemoryEstimate {
    /// Network parameters: actor, two critics and their targets (5 networks) x 4 copies (values,
    /// gradients, two Adam moments), f32.
    pub networks: f64,
    /// Activations and their gradients: batch x every layer's width x 5 networks x 2, f32.
    pub activations: f64,
    /// What the collector preallocates, f32: the off-policy agents' replay buffer (buffer_size x
    /// (2 observations + action + reward + terminal)), PPO's rollout (num_steps x num_envs x
    /// (observation + action + log-probability + value + reward + done)).
    pub replay: f64,
    /// One record per evaluation trial (64 bytes each).
    pub evaluation: f64,
}

impl MemoryEstimate {
    /// Everything, bytes.
    pub fn total(&self) -> f64 {
        self.networks + self.activations + self.replay + self.evaluation
    }
}

impl Config {
    /// The memory a run of this config needs for an arm of `dof` joints, estimated before anything
    /// is allocated (in f64: absurd sizes do not overflow).
    /// The per-link observation's slots (one per collision shape of the arm, unknown before it
    /// is loaded) are estimated as three per joint (the UR5 has 14 shapes for 6 joints).
    pub fn estimated_memory(&self, dof: usize) -> MemoryEstimate {
        let (encoding, mut slots) = (self.task.obstacle_observation, self.task.obstacle_slots());
        if encoding == crate::env::ObstacleObservation::PerLink && slots > 0 {
            slots = 3 * dof;
        }
        let obs = crate::env::ObservationLayout::with_encoding(self.task.observation, dof, encoding, slots)
            .dim() as f64;
        let act = dof as f64;
        let f32_bytes = 4.0;
        // CrossQ's critics have their own widths (and a joint pass of twice the batch).
        let crossq = self.agent.algo == crate::agent::Algo::Crossq;
        let hidden = if crossq { self.agent.crossq().critic_hidden } else { self.agent.hidden.clone() };
        let widths: Vec<f64> = hidden.iter().map(|&h| h as f64).collect();
        // Layer sizes of one network, input obs + act (the critics'; the actor's is smaller).
        let mut params = 0.0;
        let mut fan_in = obs + act;
        for &w in widths.iter().chain([2.0 * act].iter()) {
            params += fan_in * w + w;
            fan_in = w;
        }
        let nets = 5.0;
        let layer_values = widths.iter().sum::<f64>() + obs + 2.0 * act;
        MemoryEstimate {
            networks: params * nets * 4.0 * f32_bytes,
            activations: self.update_batch()
                * if crossq { 2.0 } else { 1.0 }
                * layer_values
                * nets
                * 2.0
                * f32_bytes,
            replay: if self.agent.algo.is_off_policy() {
                self.agent.buffer_size as f64 * (2.0 * obs + act + 2.0) * f32_bytes
            } else {
                let p = self.agent.ppo();
                (p.num_steps * p.num_envs) as f64 * (obs + act + 4.0) * f32_bytes
            },
            evaluation: f64::from(self.train.eval_trials) * 64.0,
        }
    }

    /// The rows of one update's activation matrices: the off-policy agents' `batch_size`, PPO's
    /// minibatch (`num_envs x num_steps / num_minibatches`, rounded up), as f64.
    fn update_batch(&self) -> f64 {
        if self.agent.algo.is_off_policy() {
            self.agent.batch_size as f64
        } else {
            let p = self.agent.ppo();
            let rollout = p.num_envs as f64 * p.num_steps as f64;
            (rollout / p.num_minibatches.max(1) as f64).ceil()
        }
    }

    /// An error if [`Config::estimated_memory`] for `dof` joints exceeds
    /// [`MAX_RUN_MEMORY_BYTES`], naming the field that contributes most.
    pub fn check_memory(&self, dof: usize) -> Result<()> {
        let m = self.estimated_memory(dof);
        if m.total() <= MAX_RUN_MEMORY_BYTES {
            return Ok(());
        }
        let gib = |b: f64| b / (1u64 << 30) as f64;
        let parts = [
            (m.networks, "agent.hidden", format!("{:?}", self.agent.hidden)),
            match self.agent.algo.is_off_policy() {
                true => (m.activations, "agent.batch_size", self.agent.batch_size.to_string()),
                false => (
                    m.activations,
                    "agent.ppo.num_minibatches",
                    format!(
                        "{} (minibatches of {} transitions)",
                        self.agent.ppo().num_minibatches,
                        self.update_batch()
                    ),
                ),
            },
            match self.agent.algo.is_off_policy() {
                true => (m.replay, "agent.buffer_size", self.agent.buffer_size.to_string()),
                false => (m.replay, "agent.ppo.num_steps", self.agent.ppo().num_steps.to_string()),
            },
            (m.evaluation, "train.eval_trials", self.train.eval_trials.to_string()),
        ];
        let (_, field, value) = parts.iter().max_by(|a, b| a.0.total_cmp(&b.0)).expect("four parts");
        Err(Error::config(
            *field,
            value,
            format!(
                "the run would need about {:.1} GiB (networks {:.1}, activations {:.1}, replay buffer \
                 or rollout {:.1}, evaluation {:.1} GiB), more than the {:.0} GiB allowed; use smaller \
                 values",
                gib(m.total()),
                gib(m.networks),
                gib(m.activations),
                gib(m.replay),
                gib(m.evaluation),
                gib(MAX_RUN_MEMORY_BYTES)
            ),
        ))
    }
}

impl Config {
    /// Parse a TOML document; `origin` names it in error messages. Every value is checked; a
    /// section of another algorithm than `agent.algo` is allowed here (a command-line `--algo`
    /// may pick the run's algorithm later; a preset holds one for each algorithm of its sweep)
    /// and refused by [`Config::validate`], which every run calls.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Config> {
        let cfg: Config = toml::from_str(text).map_err(|e| {
            let raw: Option<toml::Table> = toml::from_str(text).ok();
            let agent = raw.as_ref().and_then(|t| t.get("agent")).and_then(toml::Value::as_table);
            let missing = raw.as_ref().map(schema::missing_required).unwrap_or_default();
            let message = agent.and_then(AgentConfig::misplaced_key).unwrap_or_else(|| match missing.len() {
                0 => e.to_string(),
                _ => format!("missing required settings (all of them): {}", missing.join(", ")),
            });
            Error::ConfigParse {
                path: origin.to_path_buf(),
                message: crate::base::text::bound_message(&message),
            }
        })?;
        cfg.validate_values()?;
        Ok(cfg)
    }

    /// Read, parse and check a TOML file (see [`Config::from_toml_str`]): a regular file of at
    /// most [`MAX_CONFIG_BYTES`] (a FIFO or a device is refused unread).
    pub fn load(path: &Path) -> Result<Config> {
        let bytes = crate::io::read_regular(path, MAX_CONFIG_BYTES, "config")?;
        let text = String::from_utf8(bytes).map_err(|e| {
            Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()))
        })?;
        Config::from_toml_str(&text, path)
    }

    /// The configuration as TOML, every field written out (the resolved config of a run); of
    /// the agent's algorithm sections only the run's own.
    pub fn to_toml_string(&self) -> String {
        let resolved = Config { agent: self.agent.resolved(), ..self.clone() };
        toml::to_string_pretty(&resolved).expect("the config is always representable in TOML")
    }

    /// The checks of a run's config: every value, and no agent section of another algorithm
    /// than the run's.
    pub fn validate(&self) -> Result<()> {
        self.validate_values()?;
        self.agent.validate()?;
        self.check_curriculum()?;
        self.check_demonstrations()
    }

    /// The run-level check of `[train.demonstrations]`: an off-policy agent (the demonstrations
    /// go into its replay buffer).
    fn check_demonstrations(&self) -> Result<()> {
        let bc = self.agent.sac.map_or(0.0, |s| s.bc_weight);
        if bc > 0.0 && self.train.demonstrations.is_none() {
            return Err(Error::config(
                "agent.sac.bc_weight",
                bc,
                "0 (left out) without [train.demonstrations]: it clones the demonstrations' actions",
            ));
        }
        if self.train.demonstrations.is_some() && !self.agent.algo.is_off_policy() {
            return Err(Error::config(
                "train.demonstrations",
                "a demonstrations section",
                format!(
                    "none with agent.algo = \"{}\": demonstrations are stored in the replay buffer \
                     of an off-policy agent (use ddpg, td3, sac or crossq)",
                    self.agent.algo
                ),
            ));
        }
        Ok(())
    }

    /// The run-level checks of `[train.curriculum]`: an off-policy agent, and no
    /// `train.obstacles_in_path` beside it (its stages set that probability).
    fn check_curriculum(&self) -> Result<()> {
        if self.train.curriculum.is_none() {
            return Ok(());
        }
        if !self.agent.algo.is_off_policy() {
            return Err(Error::config(
                "train.curriculum",
                "a curriculum section",
                format!(
                    "none with agent.algo = \"{}\": the curriculum follows the episodes of the \
                     off-policy collector's one environment (use ddpg, td3, sac or crossq)",
                    self.agent.algo
                ),
            ));
        }
        if self.train.obstacles_in_path != 0.0 {
            return Err(Error::config(
                "train.obstacles_in_path",
                self.train.obstacles_in_path,
                "0 (left out) with [train.curriculum], whose obstacles_in_path sets it per stage",
            ));
        }
        Ok(())
    }

    /// Chain-independent checks of every value of every section.
    fn validate_values(&self) -> Result<()> {
        if self.robot.urdf.trim().is_empty() {
            return Err(Error::config("robot.urdf", "\"\"", "\"ur5\" or a path to a URDF file"));
        }
        self.task.validate()?;
        self.reward.validate()?;
        crate::env::check_collision_settings(self.task.on_collision, &self.reward)?;
        self.agent.validate_values()?;
        self.train.validate()?;
        crate::env::check_obstacles_in_path(
            self.train.obstacles_in_path,
            self.task.random_obstacles.is_some(),
        )?;
        if let Some(c) = &self.train.curriculum {
            c.check_task(self.task.random_obstacles.as_ref().map(|r| r.count))?;
        }
        if let Some(d) = &self.train.demonstrations {
            d.validate(self.task.random_obstacles.is_some())?;
        }
        self.check_memory(ESTIMATE_DOF)
    }
}

impl ReachEnv {
    /// Build the arm, resolve the task and create the environment from a whole config
    /// ([`Config::resolve`], then [`Resolved::env`]).
    pub fn from_config(cfg: &Config, seed: u64) -> Result<ReachEnv> {
        cfg.resolve()?.env(seed)
    }
}

impl VecEnv {
    /// `n` environments from a whole config ([`Config::resolve`], then [`Resolved::vec_env`]).
    pub fn from_config(n: usize, cfg: &Config, seed: u64) -> Result<VecEnv> {
        cfg.resolve()?.vec_env(n, seed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Config> {
        Config::from_toml_str(text, Path::new("test.toml"))
    }

    #[test]
    fn defaults_are_the_papers() {
        let c = Config::default();
        assert_eq!(c.task.dt_s, 0.05);
        assert_eq!(c.task.max_steps, 50);
        assert_eq!(c.reward.beta_m, 0.01);
        assert_eq!(c.reward.success_bonus, 20.0);
        assert_eq!(c.reward.har_boundary_m, 0.5);
        assert_eq!((c.reward.sar_sigma1, c.reward.sar_sigma2), (1.0, 1.0));
        c.validate().unwrap();
    }

    #[test]
    fn empty_file_is_the_default_and_round_trips() {
        let c = parse("").unwrap();
        assert_eq!(c, Config::default());
        let full = Config {
            task: TaskConfig {
                home_pose_rad: Some(crate::env::UR5_HOME_POSE_RAD.to_vec()),
                ..TaskConfig::default()
            },
            ..Config::default()
        };
        let text = full.to_toml_string();
        assert_eq!(parse(&text).unwrap(), full);
    }

    #[test]
    fn partial_sections_override_only_what_they_name() {
        let c = parse("[reward]\nfunction = \"har\"\nbeta_m = 0.02\n[task]\nmax_steps = 80\n").unwrap();
        assert_eq!(c.reward.function, crate::reward::RewardFunction::Har);
        assert_eq!(c.reward.beta_m, 0.02);
        assert_eq!(c.reward.har_boundary_m, 0.5);
        assert_eq!(c.task.max_steps, 80);
        assert_eq!(c.task.dt_s, 0.05);
    }

    #[test]
    fn parse_errors_name_the_problem() {
        let cases = [
            ("[reward]\nbeta = 0.02\n", "unknown field `beta`"),
            ("[rewards]\n", "unknown field `rewards`"),
            ("[task]\ndt_s = \"fast\"\n", "dt_s"),
            ("[task]\nmax_steps = -3\n", "max_steps"),
            ("[reward]\nfunction = \"sparse\"\n", "sparse"),
            ("[task]\ndt_s = 0.0\n", "task.dt_s"),
            ("[task]\ndt_s = -0.05\n", "task.dt_s"),
            ("[task]\nmax_steps = 0\n", "task.max_steps"),
            ("[reward]\nbeta_m = 0\n", "reward.beta_m"),
            ("[reward]\nsar_sigma1 = -1\n", "reward.sar_sigma1"),
            ("[robot]\nurdf = \"\"\n", "robot.urdf"),
            ("[task]\ntarget_min_z_m = nan\n", "task.target_min_z_m"),
        ];
        for (text, needle) in cases {
            let e = parse(text).expect_err(text).to_string();
            assert!(e.contains(needle), "error for {text:?} was {e:?}, expected it to mention {needle:?}");
        }
    }

    #[test]
    fn the_printed_default_holds_only_its_algorithms_section_and_round_trips() {
        // `stagerl config` prints this; `train --config` must read it back unchanged.
        let text = Config::default().to_toml_string();
        assert!(text.contains("[agent.sac]") && text.contains("init_alpha = 1.0"), "{text}");
        assert!(!text.contains("[agent.ddpg]") && !text.contains("[agent.td3]"), "{text}");
        let back = parse(&text).unwrap();
        back.validate().unwrap();
        assert_eq!(back, Config::default());
        assert_eq!(back.to_toml_string(), text);
        for algo in crate::agent::Algo::ALL {
            let c = Config { agent: AgentConfig::new(algo), ..Config::default() };
            let text = c.to_toml_string();
            assert!(text.contains(&format!("[agent.{algo}]")), "{text}");
            assert_eq!(parse(&text).unwrap(), c, "{algo}");
        }
    }

    #[test]
    fn the_memory_estimate_counts_what_the_collector_allocates() {
        // PPO keeps no replay buffer: a buffer_size it does not use is not refused; its rollout is
        // what it preallocates.
        let big = "buffer_size = 100000000\nhidden = [4096, 4096]\n";
        let ppo = parse(&format!("[agent]\nalgo = \"ppo\"\n{big}")).unwrap();
        let sac = parse(&format!("[agent]\nalgo = \"sac\"\n{big}")).unwrap_err().to_string();
        assert!(sac.contains("agent.buffer_size") && sac.contains("replay buffer or rollout"), "{sac}");
        let m = ppo.estimated_memory(6);
        let obs = crate::env::ObservationLayout::new(ppo.task.observation, 6, 0).dim() as f64;
        assert_eq!(m.replay, (256.0 * 8.0) * (obs + 6.0 + 4.0) * 4.0, "num_steps x num_envs rows");
        let e = parse("[agent]\nalgo = \"ppo\"\n[agent.ppo]\nnum_envs = 64\nnum_steps = 4000000\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("agent.ppo.num_steps"), "{e}");
    }

    #[test]
    fn load_reports_missing_file_with_its_path() {
        let e = Config::load(Path::new("/nonexistent/stagerl.toml")).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/stagerl.toml"), "{e}");
    }
}
