//! The reaching task's section of the config (`[task]`): control period, episode length, home
//! pose, the target distribution and the observation layout; resolved against an arm, and the
//! target sampling that resolution makes safe.

use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;

use crate::collision::{Checks, Obstacle};
use crate::rng::Rng;
use crate::robot::{Chain, JointKind};
use crate::{Error, Result};

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
    /// `[[task.obstacles]]`: boxes (`shape = "cuboid"`, `half_extents_m`) and spheres
    /// (`shape = "sphere"`, `radius_m`) at `position_m` (base frame, metres), optionally turned by
    /// `rotation_xyzw`. The arm's contacts with them are recorded ([`crate::collision`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<Obstacle>,
    /// `[task.collision]`: which contacts are looked for (`floor`, `self_collision`); unset:
    /// both. Contacts are recorded; they change nothing in the episode (the paper's task).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub collision: Option<Checks>,
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
            obstacles: Vec::new(),
            collision: None,
        }
    }
}

/// Most `[[task.obstacles]]`.
pub const MAX_OBSTACLES: usize = 256;

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
    pub obstacles: Vec<Obstacle>,
    pub collision: Checks,
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
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(Error::config(
                "task.obstacles",
                format!("{} obstacles", self.obstacles.len()),
                format!("at most {MAX_OBSTACLES}"),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            o.validate(&format!("task.obstacles[{i}]"))?;
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
            obstacles: self.obstacles.clone(),
            collision: self.collision.unwrap_or_default(),
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

#[cfg(test)]
mod tests {
    use super::*;

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
