//! The TOML configuration: one schema for the arm, the task, the reward, the agent and the
//! training run. Unknown fields are rejected; every value is validated with an error
//! that names the field, the value and what is allowed.
//!
//! Defaults are the paper's where it gives a value, and the design notes' choices elsewhere.

use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;
use std::path::Path;

use crate::agent::AgentConfig;
use crate::reward::RewardConfig;
use crate::rng::Rng;
use crate::robot::{Chain, JointKind};
use crate::train::TrainConfig;
use crate::{Error, Result};

/// The whole configuration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub robot: RobotConfig,
    pub task: TaskConfig,
    pub reward: RewardConfig,
    pub agent: AgentConfig,
    pub train: TrainConfig,
}

/// Which arm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    /// `"ur5"` for the bundled UR5, or a path to a URDF file.
    pub urdf: String,
    /// Tip link of the chain; unset takes the URDF's only leaf link.
    pub tip: Option<String>,
}

impl Default for RobotConfig {
    fn default() -> Self {
        RobotConfig { urdf: "ur5".into(), tip: None }
    }
}

impl RobotConfig {
    /// Load the configured arm.
    pub fn load(&self) -> Result<Chain> {
        Chain::load(&self.urdf, self.tip.as_deref())
    }
}

/// What the policy observes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationKind {
    /// N + 10 values (16 for six joints), f32: q / pi (N), end-effector position (3, m),
    /// target (3, m), k (target - end-effector) (3, m), k D_PT (1, m), with
    /// k = `task.obs_delta_scale`.
    Standard,
}

/// The reaching task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// Control period: each joint-velocity command is held this long, seconds (paper: 0.05).
    pub dt_s: f64,
    /// Steps before an episode is truncated (paper: 50).
    pub max_steps: u32,
    /// Pose every episode starts from, radians (metres for prismatic joints). Unset: the UR5 home
    /// pose [0, -pi/2, pi/2, -pi/2, -pi/2, 0], which needs a six-joint arm.
    pub home_pose_rad: Option<Vec<f64>>,
    /// Target = FK(home + u * range), u uniform in [-1, 1]^N, radians per joint. Unset:
    /// [1.2, 0.8, 0.8, 0, 0, 0], which needs a six-joint arm.
    pub target_joint_range_rad: Option<Vec<f64>>,
    /// Targets are drawn again until their height is above this, metres (default 0.05).
    pub target_min_z_m: f64,
    /// Observation layout.
    pub observation: ObservationKind,
    /// Factor on the observation's `target - end-effector` and `D_PT` entries. Near the goal
    /// these are about 0.01 m, a tiny input for a network that must turn them into precise
    /// joint velocities; a factor of 10 puts the last centimetre on the scale of the other inputs.
    /// At most [`MAX_OBS_DELTA_SCALE`]: the scaled entries are stored as f32.
    pub obs_delta_scale: f64,
}

impl Default for TaskConfig {
    fn default() -> Self {
        TaskConfig {
            dt_s: 0.05,
            max_steps: 50,
            home_pose_rad: None,
            target_joint_range_rad: None,
            target_min_z_m: 0.05,
            observation: ObservationKind::Standard,
            obs_delta_scale: 10.0,
        }
    }
}

/// The UR5 home pose of the design notes, radians.
pub const UR5_HOME_POSE_RAD: [f64; 6] = [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0];
/// The default target joint range of the design notes, radians.
pub const DEFAULT_TARGET_JOINT_RANGE_RAD: [f64; 6] = [1.2, 0.8, 0.8, 0.0, 0.0, 0.0];

/// Largest `task.obs_delta_scale`: the scaled `target - end-effector` entries are f32, and a
/// larger factor turns distances of metres into infinite observations.
pub const MAX_OBS_DELTA_SCALE: f64 = 1e6;

/// A task whose per-joint vectors are resolved against an arm and checked.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedTask {
    pub dt_s: f64,
    pub max_steps: u32,
    pub home_pose: Vec<f64>,
    pub target_joint_range: Vec<f64>,
    pub target_min_z_m: f64,
    pub observation: ObservationKind,
    pub obs_delta_scale: f64,
    /// Fraction of target draws accepted by the height test, estimated from 2000 seeded draws.
    pub target_acceptance: f64,
}

fn check_finite(field: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::config(field, v, "a finite number"))
    }
}

impl TaskConfig {
    /// Chain-independent checks.
    pub fn validate(&self) -> Result<()> {
        if !(self.dt_s.is_finite() && self.dt_s > 0.0) {
            return Err(Error::config("task.dt_s", self.dt_s, "a finite number of seconds > 0"));
        }
        if self.max_steps == 0 {
            return Err(Error::config("task.max_steps", self.max_steps, "an integer >= 1"));
        }
        check_finite("task.target_min_z_m", self.target_min_z_m)?;
        if !(self.obs_delta_scale > 0.0 && self.obs_delta_scale <= MAX_OBS_DELTA_SCALE) {
            return Err(Error::config(
                "task.obs_delta_scale",
                self.obs_delta_scale,
                format!("a number in (0, {MAX_OBS_DELTA_SCALE:e}]"),
            ));
        }
        Ok(())
    }

    /// Resolve the per-joint vectors for `chain` and check them against its limits; also check
    /// that the target distribution can be sampled.
    pub fn resolve(&self, chain: &Chain) -> Result<ResolvedTask> {
        self.validate()?;
        let n = chain.dof();
        let per_joint = |field: &str, given: &Option<Vec<f64>>, default: &[f64; 6]| -> Result<Vec<f64>> {
            match given {
                Some(v) if v.len() != n => Err(Error::config(
                    field,
                    format!("{v:?}"),
                    format!("one value per joint: the arm has {n} joints"),
                )),
                Some(v) => Ok(v.clone()),
                None if n == 6 => Ok(default.to_vec()),
                None => Err(Error::config(
                    field,
                    "(unset)",
                    format!(
                        "set it: the default {default:?} is for a six-joint arm, this one has {n} joints"
                    ),
                )),
            }
        };
        let home = per_joint("task.home_pose_rad", &self.home_pose_rad, &UR5_HOME_POSE_RAD)?;
        let range = per_joint(
            "task.target_joint_range_rad",
            &self.target_joint_range_rad,
            &DEFAULT_TARGET_JOINT_RANGE_RAD,
        )?;
        for (i, joint) in chain.joints().iter().enumerate() {
            let (lo, hi) = (chain.lower_limits()[i], chain.upper_limits()[i]);
            if !home[i].is_finite() || home[i] < lo || home[i] > hi {
                return Err(Error::config(
                    format!("task.home_pose_rad[{i}]"),
                    home[i],
                    format!("within the limits of joint `{}`: [{lo}, {hi}]", joint.name),
                ));
            }
            if !(range[i].is_finite() && range[i] >= 0.0) {
                return Err(Error::config(
                    format!("task.target_joint_range_rad[{i}]"),
                    range[i],
                    "a finite number >= 0",
                ));
            }
            if joint.kind == JointKind::Prismatic && range[i] > hi - lo {
                return Err(Error::config(
                    format!("task.target_joint_range_rad[{i}]"),
                    range[i],
                    format!("at most the travel of prismatic joint `{}`: {}", joint.name, hi - lo),
                ));
            }
        }
        let mut resolved = ResolvedTask {
            dt_s: self.dt_s,
            max_steps: self.max_steps,
            home_pose: home,
            target_joint_range: range,
            target_min_z_m: self.target_min_z_m,
            observation: self.observation,
            obs_delta_scale: self.obs_delta_scale,
            target_acceptance: 0.0,
        };
        // Estimate how often a draw passes the height test; refuse a distribution the arm
        // cannot (or almost never) reach.
        let draws = 2000;
        let mut rng = Rng::new(0x7A26E7);
        let mut q = vec![0.0; n];
        let (mut accepted, mut best_z) = (0usize, f64::NEG_INFINITY);
        for _ in 0..draws {
            let p = resolved.draw_target_candidate(chain, &mut rng, &mut q);
            best_z = best_z.max(p.z);
            accepted += usize::from(p.z > self.target_min_z_m);
        }
        resolved.target_acceptance = accepted as f64 / draws as f64;
        if resolved.target_acceptance < 0.001 {
            return Err(Error::config(
                "task.target_min_z_m",
                self.target_min_z_m,
                format!(
                    "a height the arm reaches from task.home_pose_rad within task.target_joint_range_rad: \
                     {accepted} of {draws} draws passed, the highest was z = {best_z:.4} m"
                ),
            ));
        }
        Ok(resolved)
    }
}

impl ResolvedTask {
    /// One candidate target: FK(home + u * range) with u uniform in [-1, 1]^N, clamped to the
    /// joint limits. `q` is scratch of length N.
    #[inline]
    pub fn draw_target_candidate(
        &self,
        chain: &Chain,
        rng: &mut Rng,
        q: &mut [f64],
    ) -> nalgebra::Vector3<f64> {
        let (lo, hi) = (chain.lower_limits(), chain.upper_limits());
        for i in 0..q.len() {
            let u = rng.uniform_range(-1.0, 1.0);
            q[i] = (self.home_pose[i] + u * self.target_joint_range[i]).clamp(lo[i], hi[i]);
        }
        chain.fk(q).position
    }

    /// A target from the task's distribution (draws again until above `target_min_z_m`).
    pub fn sample_target(&self, chain: &Chain, rng: &mut Rng, q: &mut [f64]) -> nalgebra::Vector3<f64> {
        // Validation guarantees an acceptance rate of at least 1e-3, so 1e6 draws fail with
        // probability below e^-1000; the highest candidate is the fallback all the same.
        let mut best = self.draw_target_candidate(chain, rng, q);
        for _ in 0..1_000_000 {
            if best.z > self.target_min_z_m {
                break;
            }
            let p = self.draw_target_candidate(chain, rng, q);
            if p.z > best.z {
                best = p;
            }
        }
        best
    }
}

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
    /// The preallocated replay buffer: buffer_size x (2 observations + action + reward +
    /// terminal), f32.
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
    pub fn estimated_memory(&self, dof: usize) -> MemoryEstimate {
        let obs = crate::env::observation_dim(self.task.observation, dof) as f64;
        let act = dof as f64;
        let f32_bytes = 4.0;
        let widths: Vec<f64> = self.agent.hidden.iter().map(|&h| h as f64).collect();
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
            activations: self.agent.batch_size as f64 * layer_values * nets * 2.0 * f32_bytes,
            replay: self.agent.buffer_size as f64 * (2.0 * obs + act + 2.0) * f32_bytes,
            evaluation: f64::from(self.train.eval_trials) * 64.0,
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
            (m.activations, "agent.batch_size", self.agent.batch_size.to_string()),
            (m.replay, "agent.buffer_size", self.agent.buffer_size.to_string()),
            (m.evaluation, "train.eval_trials", self.train.eval_trials.to_string()),
        ];
        let (_, field, value) = parts.iter().max_by(|a, b| a.0.total_cmp(&b.0)).expect("four parts");
        Err(Error::config(
            *field,
            value,
            format!(
                "the run would need about {:.1} GiB (networks {:.1}, activations {:.1}, replay buffer \
                 {:.1}, evaluation {:.1} GiB), more than the {:.0} GiB allowed; use smaller values",
                gib(m.total()),
                gib(m.networks),
                gib(m.activations),
                gib(m.replay),
                gib(m.evaluation),
                gib(MAX_RUN_MEMORY_BYTES)
            ),
        ))
    }

    /// Parse a TOML document; `origin` names it in error messages.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Config> {
        let cfg: Config = toml::from_str(text).map_err(|e| Error::ConfigParse {
            path: origin.to_path_buf(),
            message: crate::text::bound_message(&e.to_string()),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Read, parse and validate a TOML file.
    pub fn load(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Config::from_toml_str(&text, path)
    }

    /// The configuration as TOML, every field written out (the resolved config of a run).
    pub fn to_toml_string(&self) -> String {
        toml::to_string_pretty(self).expect("the config is always representable in TOML")
    }

    /// Chain-independent checks of every section.
    pub fn validate(&self) -> Result<()> {
        if self.robot.urdf.trim().is_empty() {
            return Err(Error::config("robot.urdf", "\"\"", "\"ur5\" or a path to a URDF file"));
        }
        self.task.validate()?;
        self.reward.validate()?;
        self.agent.validate()?;
        self.train.validate()?;
        self.check_memory(ESTIMATE_DOF)
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
            task: TaskConfig { home_pose_rad: Some(UR5_HOME_POSE_RAD.to_vec()), ..TaskConfig::default() },
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
    fn load_reports_missing_file_with_its_path() {
        let e = Config::load(Path::new("/nonexistent/stagerl.toml")).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/stagerl.toml"), "{e}");
    }

    #[test]
    fn resolve_against_the_ur5() {
        let chain = Chain::ur5();
        let t = TaskConfig::default().resolve(&chain).unwrap();
        assert_eq!(t.home_pose, UR5_HOME_POSE_RAD.to_vec());
        assert!(t.target_acceptance > 0.5, "{}", t.target_acceptance);

        let wrong_len = TaskConfig { home_pose_rad: Some(vec![0.0; 5]), ..TaskConfig::default() };
        let e = wrong_len.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.home_pose_rad") && e.contains("6 joints"), "{e}");

        let outside =
            TaskConfig { home_pose_rad: Some(vec![0.0, 0.0, 4.0, 0.0, 0.0, 0.0]), ..TaskConfig::default() };
        let e = outside.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.home_pose_rad[2]") && e.contains("elbow_joint"), "{e}");

        let negative = TaskConfig {
            target_joint_range_rad: Some(vec![1.0, -0.1, 0.0, 0.0, 0.0, 0.0]),
            ..TaskConfig::default()
        };
        let e = negative.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.target_joint_range_rad[1]"), "{e}");

        // The UR5 reaches less than 1 m up from its base: a 5 m floor is unreachable.
        let unreachable = TaskConfig { target_min_z_m: 5.0, ..TaskConfig::default() };
        let e = unreachable.resolve(&chain).unwrap_err().to_string();
        assert!(e.contains("task.target_min_z_m") && e.contains("0 of 2000"), "{e}");
    }
}
