//! The paper's reward functions: position (eqs. 1-2), direction (eqs. 3-6), posture (eq. 7),
//! movement (eqs. 8-9), stride (eq. 10), hard stage incentive HAR (eqs. 11-12), soft stage
//! incentive SAR (eqs. 13-15) and the sparse basic reward (eq. 18), plus the +20 success bonus of
//! section VI.
//!
//! Our extension beside the paper's terms, off by default (`[reward.clearance]`,
//! [`ClearanceConfig`]): with `d` the arm's clearance from the obstacles (the smallest signed
//! distance between a collision shape of the arm and an obstacle, metres, negative inside;
//! [`crate::sim::collision::distance`]), weight `w` and margin `m`:
//! 19. `c = max(d, -m) / m`, in [-1, inf);
//! 20. `R_clearance = w (1 - c)^2` when `d < m`, else 0: 0 at the margin, `w` at contact,
//!     growing with the depth of an overlap up to `4 w` at a depth of `m`;
//! 21. the agent receives `R + bonus - R_clearance` (`R` any of the five functions). It needs
//!     the arm's geometry, so only the environment computes it ([`crate::env::Step::outcome`]);
//!     `stagerl reward` and `stagerl.rewards.compute`, which see the end effector only, refuse
//!     `[reward.clearance]`.
//!
//! A second one, for training with the safety shield on (`reward.shield_penalty`, weight
//! `w_s >= 0`; [`crate::sim::shield`]): with `x` the command the policy asked for (rad/s, within
//! the joint limits) and `c'` the one the shield let through,
//! 22. `R_shield = w_s |x - c'|` (the Euclidean norm over the joints, rad/s; 0 when the shield
//!     kept the command), so that a policy trained behind the shield learns to need it less;
//! 23. the agent receives `R + bonus - R_clearance - R_shield`. Like the clearance term it is
//!     the environment's ([`crate::env::Step::outcome`]), and hindsight relabelling charges a
//!     step's term again as it was.
//!
//! [`RewardTerms::compute`] evaluates every term at once, so a caller can see why a step got its
//! reward; [`RewardTerms::reward`] is the value of the configured [`RewardFunction`] and
//! [`RewardTerms::total`] adds the bonus.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::fmt;
use std::str::FromStr;

use crate::{Error, Result};

pub mod batch;

/// Which reward the agent is trained on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum RewardFunction {
    /// Sparse: 1 when the task is done, else 0 (eq. 18).
    Basic,
    /// Position minus direction (eq. 7).
    Posture,
    /// Position minus movement (eq. 10).
    Stride,
    /// Hard stage incentive: posture far from the target, stride near it (eqs. 11-12).
    Har,
    /// Soft stage incentive: distance-weighted blend of stride and posture (eqs. 13-15).
    Sar,
}

impl RewardFunction {
    /// All five, in the paper's Table 1 order.
    pub const ALL: [RewardFunction; 5] = [
        RewardFunction::Basic,
        RewardFunction::Posture,
        RewardFunction::Stride,
        RewardFunction::Har,
        RewardFunction::Sar,
    ];

    /// The lowercase name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            RewardFunction::Basic => "basic",
            RewardFunction::Posture => "posture",
            RewardFunction::Stride => "stride",
            RewardFunction::Har => "har",
            RewardFunction::Sar => "sar",
        }
    }
}

impl fmt::Display for RewardFunction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for RewardFunction {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        RewardFunction::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| Error::config("reward.function", s, "one of basic, posture, stride, har, sar"))
    }
}

/// Where the "actual direction" of eq. 4 comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum DirectionSource {
    /// The paper's eq. 4: the rotation axis of the end-effector's orientation quaternion,
    /// `V_PP' = (x, y, z) / sin(acos(w))`, compared with `V_PT = T - P` (eq. 3).
    Quaternion,
    /// Our alternative: the end-effector's displacement over the step, `V_PP' = P - P_prev`,
    /// compared with the direction the step should have taken, `V_PT = T - P_prev`.
    Displacement,
}

/// Reward settings; every constant of the paper is here with the paper's value as default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RewardConfig {
    /// The reward the agent is trained on.
    pub function: RewardFunction,
    /// Success radius beta of eq. 1, metres (paper: 0.01). Reached when `D_PT < beta`.
    pub beta_m: f64,
    /// Added to the step's reward when the target is reached (paper, section VI: +20).
    pub success_bonus: f64,
    /// HAR stage boundary (eq. 11), metres (paper: 0.5): posture when `D_PT > boundary`, else stride.
    pub har_boundary_m: f64,
    /// SAR exponent sigma1 of eq. 13 (paper: 1).
    pub sar_sigma1: f64,
    /// SAR exponent sigma2 of eq. 14 (paper: 1).
    pub sar_sigma2: f64,
    /// SAR distance scale, metres: eqs. 13-14 use `clamp(D_PT / scale, 0, 1)`. The paper clamps
    /// `D_PT` itself to [0, 1], which is the default scale of 1 m.
    pub sar_scale_m: f64,
    /// Source of the actual direction in eq. 4 (paper: the quaternion).
    pub direction: DirectionSource,
    /// Apply eq. 6's fold (`phi` if `phi < pi/2`, else `pi - phi`). The paper does; turning it off
    /// makes the direction reward `phi / 2 pi` in [0, 1/2], which tells moving away from moving
    /// towards when used with [`DirectionSource::Displacement`].
    pub direction_fold: bool,
    /// Subtracted from the step's reward when a contact ends the episode
    /// (`task.on_collision = "terminate"`), a magnitude >= 0. Our extension: the paper has no
    /// collision term. Unset: 0 (and left out of a written config).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub collision_penalty: Option<f64>,
    /// `[reward.clearance]`: a penalty as the arm comes closer to an obstacle than a margin,
    /// our extension ([`ClearanceConfig`], eqs. 19-21 of this module). Unset: off, the paper's
    /// rewards.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance: Option<ClearanceConfig>,
    /// Weight of the shield's penalty, reward per rad/s of the change the safety shield made to
    /// a step's command (eq. 22 of this module; our extension, >= 0). Only with `[task.shield]`
    /// enabled. Unset: 0 (and left out of a written config).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shield_penalty: Option<f64>,
}

/// `[reward.clearance]`: a penalty taken off every step's reward as the arm comes closer to an
/// obstacle than `margin_m` (our extension, off by default: unset, the paper's rewards).
/// `R_clearance = weight (1 - c)^2` with `c = max(d, -margin_m) / margin_m` when the arm's
/// clearance from the obstacles `d < margin_m`, else 0 (eqs. 19-21); values in [0, 4 weight].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ClearanceConfig {
    /// Weight w of the clearance penalty (>= 0, finite): its value at contact (d = 0).
    pub weight: f64,
    /// Margin m, metres (> 0, finite): no penalty while every collision shape of the arm is at
    /// least this far from every obstacle.
    pub margin_m: f64,
}

impl Default for ClearanceConfig {
    fn default() -> Self {
        ClearanceConfig { weight: 1.0, margin_m: 0.1 }
    }
}

impl ClearanceConfig {
    /// The error of a tool that computes rewards from the end effector's pose alone (`tool`:
    /// `stagerl reward`, `stagerl.rewards.compute`) for a config with `[reward.clearance]`:
    /// the term needs the whole arm and the obstacles, which only the environment has.
    pub fn refused_by(&self, tool: &str) -> Error {
        Error::config(
            "reward.clearance",
            format!("{{ weight = {}, margin_m = {} }}", self.weight, self.margin_m),
            format!(
                "unset for {tool}: it computes the rewards from the end effector's pose alone, and \
                 the clearance term needs the whole arm's distance to the obstacles (the environment \
                 charges it: stagerl train, eval, plan, the Python ReachEnv)"
            ),
        )
    }

    /// Eqs. 19-20 for the arm's clearance `d` (metres; `f64::INFINITY` without obstacles).
    #[inline]
    pub fn penalty(&self, d: f64) -> f64 {
        if d >= self.margin_m {
            return 0.0;
        }
        let c = d.max(-self.margin_m) / self.margin_m;
        self.weight * (1.0 - c) * (1.0 - c)
    }

    /// Check both values; the error names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(Error::config("reward.clearance.weight", self.weight, "a finite number >= 0"));
        }
        if !(self.margin_m.is_finite() && self.margin_m > 0.0) {
            return Err(Error::config(
                "reward.clearance.margin_m",
                self.margin_m,
                "a distance in metres, finite and > 0",
            ));
        }
        Ok(())
    }
}

impl Default for RewardConfig {
    fn default() -> Self {
        RewardConfig {
            function: RewardFunction::Sar,
            beta_m: 0.01,
            success_bonus: 20.0,
            har_boundary_m: 0.5,
            sar_sigma1: 1.0,
            sar_sigma2: 1.0,
            sar_scale_m: 1.0,
            direction: DirectionSource::Quaternion,
            direction_fold: true,
            collision_penalty: None,
            clearance: None,
            shield_penalty: None,
        }
    }
}

impl RewardConfig {
    /// Check every value; the error names the field, the value and what is allowed.
    pub fn validate(&self) -> Result<()> {
        use crate::base::validate::{finite, non_negative, positive};
        positive("reward.beta_m", self.beta_m)?;
        finite("reward.success_bonus", self.success_bonus)?;
        non_negative("reward.har_boundary_m", self.har_boundary_m)?;
        non_negative("reward.sar_sigma1", self.sar_sigma1)?;
        non_negative("reward.sar_sigma2", self.sar_sigma2)?;
        positive("reward.sar_scale_m", self.sar_scale_m)?;
        if let Some(p) = self.collision_penalty {
            non_negative("reward.collision_penalty", p)?;
        }
        if let Some(c) = &self.clearance {
            c.validate()?;
        }
        if let Some(w) = self.shield_penalty {
            non_negative("reward.shield_penalty", w)?;
        }
        Ok(())
    }

    /// The error of a tool that computes rewards from the end effector's pose alone (`tool`:
    /// `stagerl reward`, `stagerl.rewards.compute`) for a config with a term only the
    /// environment can charge: `[reward.clearance]` (the arm's distance to the obstacles) or
    /// `reward.shield_penalty` (what the safety shield did). `Ok` without either.
    pub fn pose_only(&self, tool: &str) -> Result<()> {
        if let Some(c) = &self.clearance {
            return Err(c.refused_by(tool));
        }
        if let Some(w) = self.shield_penalty {
            return Err(Error::config(
                "reward.shield_penalty",
                w,
                format!(
                    "unset for {tool}: it computes the rewards from the end effector's pose alone, \
                     and the shield's penalty needs what the safety shield did to each command (the \
                     environment charges it: stagerl train, eval, plan, the Python ReachEnv)"
                ),
            ));
        }
        Ok(())
    }
}

/// What a reward is computed from (all in the base frame).
#[derive(Clone, Copy, Debug)]
pub struct RewardInput<'a> {
    /// End-effector position P, metres.
    pub ee_pos: Vector3<f64>,
    /// End-effector orientation P' as `[x, y, z, w]`, unit norm.
    pub ee_quat: [f64; 4],
    /// Target position T, metres.
    pub target: Vector3<f64>,
    /// Joint velocities V of eq. 8 (rad/s, or m/s for prismatic joints); N = its length.
    pub joint_vel: &'a [f64],
    /// End-effector position before the step; needed by [`DirectionSource::Displacement`].
    pub prev_ee_pos: Option<Vector3<f64>>,
}

impl RewardInput<'_> {
    /// Reject input outside the reward's domain: non-finite values, an empty velocity vector, a
    /// quaternion whose norm is off 1 by more than 1e-6. Ok exactly when
    /// [`RewardInput::is_valid`]; the error names the first value at fault.
    #[inline]
    pub fn validate(&self) -> Result<()> {
        if self.is_valid() {
            Ok(())
        } else {
            Err(self.invalid())
        }
    }

    /// [`RewardInput::validate`]'s test without an error to build (for batches: a row that fails
    /// it can then be explained by `validate`).
    #[inline]
    pub fn is_valid(&self) -> bool {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        finite(self.ee_pos.as_slice())
            && finite(&self.ee_quat)
            && finite(self.target.as_slice())
            && finite(self.joint_vel)
            && self.prev_ee_pos.is_none_or(|p| finite(p.as_slice()))
            && !self.joint_vel.is_empty()
            && (quat_norm(&self.ee_quat) - 1.0).abs() <= 1e-6
    }

    /// The error for input that is not [`RewardInput::is_valid`]: the first value at fault.
    #[cold]
    #[inline(never)]
    fn invalid(&self) -> Error {
        let first_bad = |name: &str, v: &[f64]| {
            v.iter()
                .position(|x| !x.is_finite())
                .map(|i| Error::InvalidInput(format!("{name}[{i}] = {} is not finite", v[i])))
        };
        let prev = self.prev_ee_pos.as_ref().map_or(&[][..], |p| p.as_slice());
        first_bad("ee_pos", self.ee_pos.as_slice())
            .or_else(|| first_bad("ee_quat", &self.ee_quat))
            .or_else(|| first_bad("target", self.target.as_slice()))
            .or_else(|| first_bad("joint_vel", self.joint_vel))
            .or_else(|| first_bad("prev_ee_pos", prev))
            .unwrap_or_else(|| {
                if self.joint_vel.is_empty() {
                    Error::InvalidInput("joint_vel is empty: need one value per joint".into())
                } else {
                    Error::InvalidInput(format!(
                        "ee_quat has norm {}, expected a unit quaternion (|norm - 1| <= 1e-6)",
                        quat_norm(&self.ee_quat)
                    ))
                }
            })
    }
}

/// The Euclidean norm of a quaternion's four values (in order, as `validate` has always summed).
#[inline]
fn quat_norm(q: &[f64; 4]) -> f64 {
    q.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Every term of the paper's rewards for one step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RewardTerms {
    /// D_PT, Euclidean distance from end-effector to target, metres.
    pub distance: f64,
    /// J_reach of eq. 1: `D_PT < beta`.
    pub reached: bool,
    /// R_position = J_reach - D_PT (eq. 2).
    pub position: f64,
    /// phi of eq. 5, radians in [0, pi].
    pub phi: f64,
    /// R_direction = fold(phi) / 2 pi (eq. 6), in [0, 1/4].
    pub direction: f64,
    /// R_posture = R_position - R_direction (eq. 7).
    pub posture: f64,
    /// R_move = dt (V . V) / N (eq. 9).
    pub movement: f64,
    /// R_stride = R_position - R_move (eq. 10).
    pub stride: f64,
    /// gamma_posture of eq. 11 (1 in the fast approach area `D_PT > boundary`, else 0).
    pub gamma_posture: f64,
    /// R_HAR (eq. 12).
    pub har: f64,
    /// alpha1 = 1 - clamp(D_PT)^sigma1 (eq. 13).
    pub alpha1: f64,
    /// alpha2 = clamp(D_PT)^sigma2 (eq. 14).
    pub alpha2: f64,
    /// R_SAR = alpha1 R_stride + alpha2 R_posture (eq. 15).
    pub sar: f64,
    /// R_basic (eq. 18): 1 when reached, else 0.
    pub basic: f64,
    /// The configured function's value.
    pub reward: f64,
    /// The success bonus when reached, else 0.
    pub bonus: f64,
    /// `reward + bonus`: what the agent receives. (The environment takes
    /// `reward.collision_penalty` off it when a contact ends the episode, and `clearance`.)
    pub total: f64,
    /// R_clearance (eqs. 19-20), taken off `total` by the environment; 0 unless
    /// `[reward.clearance]` is set.
    #[serde(default)]
    pub clearance: f64,
    /// R_shield (eq. 22), taken off `total` by the environment; 0 unless
    /// `reward.shield_penalty` is set and the shield changed the step's command.
    #[serde(default)]
    pub shield: f64,
}

impl RewardTerms {
    /// The terms `stagerl reward` writes and the demo tabulates, named and in that order
    /// (`movement` as `move`, `reached` as 0 or 1).
    #[inline]
    pub fn reported(&self) -> [(&'static str, f64); 12] {
        let t = self;
        [
            ("distance", t.distance),
            ("reached", f64::from(u8::from(t.reached))),
            ("position", t.position),
            ("direction", t.direction),
            ("posture", t.posture),
            ("move", t.movement),
            ("stride", t.stride),
            ("alpha1", t.alpha1),
            ("alpha2", t.alpha2),
            ("reward", t.reward),
            ("bonus", t.bonus),
            ("total", t.total),
        ]
    }
}

/// [`RewardTerms`] serialised as its [`RewardTerms::reported`] terms: an object with those keys
/// in that order, `reached` a boolean.
#[derive(Clone, Copy, Debug)]
pub struct Reported(pub RewardTerms);

impl Serialize for Reported {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let terms = self.0.reported();
        let mut m = s.serialize_map(Some(terms.len()))?;
        for (key, value) in terms {
            if key == "reached" {
                m.serialize_entry(key, &self.0.reached)?;
            } else {
                m.serialize_entry(key, &value)?;
            }
        }
        m.end()
    }
}

/// phi of eq. 5: the angle between `expected` and `actual`, in [0, pi]. 0 when either vector is
/// degenerate (|V_PT| < 1e-12 or |V_PP'| < 1e-9), as the design notes (`docs/design.md`) fix.
#[inline]
pub fn angle_between(expected: &Vector3<f64>, actual: &Vector3<f64>) -> f64 {
    angle_from_cosine(cosine_between(expected, actual))
}

/// What [`cosine_between`] returns for a degenerate pair: outside acos's domain, so that no
/// cosine can take its place (a NaN cosine stays NaN).
pub(crate) const DEGENERATE: f64 = 2.0;

/// cos phi of eq. 5 clamped to [-1, 1] (NaN where the input overflows), or [`DEGENERATE`]: the
/// half of [`angle_between`] before its `acos` (split so that batches can run the cheap halves
/// as vector loops).
#[inline(always)]
pub(crate) fn cosine_between(expected: &Vector3<f64>, actual: &Vector3<f64>) -> f64 {
    let ne = expected.norm();
    let na = actual.norm();
    if ne < 1e-12 || na < 1e-9 {
        return DEGENERATE;
    }
    (expected.dot(actual) / (ne * na)).clamp(-1.0, 1.0)
}

/// phi from [`cosine_between`]'s value: 0 for [`DEGENERATE`], else its `acos`.
#[inline(always)]
pub(crate) fn angle_from_cosine(cosine: f64) -> f64 {
    if cosine > 1.0 {
        0.0
    } else {
        cosine.acos()
    }
}

/// cos phi of eqs. 3-5 for `input` (see [`cosine_between`]), `to_target` being `T - P`: the
/// quaternion's axis against `T - P`, or the step's displacement against `T - P_prev`
/// ([`DEGENERATE`] without `prev_ee_pos`).
#[inline(always)]
pub(crate) fn direction_cosine(cfg: &RewardConfig, input: &RewardInput<'_>, to_target: &Vector3<f64>) -> f64 {
    match cfg.direction {
        DirectionSource::Quaternion => {
            let [x, y, z, _w] = input.ee_quat;
            cosine_between(to_target, &Vector3::new(x, y, z))
        }
        DirectionSource::Displacement => match input.prev_ee_pos {
            Some(prev) => cosine_between(&(input.target - prev), &(input.ee_pos - prev)),
            None => DEGENERATE,
        },
    }
}

/// Eq. 6: R_direction = fold(phi) / 2 pi, where fold(phi) = phi when phi < pi/2, else pi - phi.
#[inline]
pub fn direction_reward(phi: f64, fold: bool) -> f64 {
    let folded = if !fold || phi < FRAC_PI_2 { phi } else { PI - phi };
    folded / TAU
}

/// Eq. 9: R_move = dt (V . V) / N, with dt in seconds and N = `joint_vel.len()`.
#[inline]
pub fn movement_reward(joint_vel: &[f64], dt_s: f64) -> f64 {
    let vv: f64 = joint_vel.iter().map(|v| v * v).sum();
    dt_s * vv / joint_vel.len() as f64
}

/// Eqs. 13-14: `(alpha1, alpha2)` with `c = clamp(D_PT / scale, 0, 1)`.
#[inline]
pub fn sar_weights(distance: f64, cfg: &RewardConfig) -> (f64, f64) {
    let c = (distance / cfg.sar_scale_m).clamp(0.0, 1.0);
    (1.0 - pow(c, cfg.sar_sigma1), pow(c, cfg.sar_sigma2))
}

/// `c^s` for `c` in [0, 1], exact and cheap for the common exponents 1 and 2.
#[inline]
fn pow(c: f64, s: f64) -> f64 {
    if s == 1.0 {
        c
    } else if s == 2.0 {
        c * c
    } else {
        c.powf(s)
    }
}

impl RewardTerms {
    /// Evaluate every term for one step. `dt_s` is the control period of eq. 9 (seconds).
    ///
    /// The input is trusted (see [`RewardInput::validate`] for outside input). With
    /// [`DirectionSource::Displacement`] and no `prev_ee_pos`, phi is 0.
    ///
    /// Eq. 4's `temp = sin(acos(w))` is a positive scale of `(x, y, z)`, so it does not change
    /// phi; it only matters where it vanishes, which is tested as `|(x, y, z)| < 1e-9` (equal
    /// to `sin(acos(w))` for a unit quaternion, and free of its cancellation near w = 1).
    #[inline(always)]
    pub fn compute(cfg: &RewardConfig, dt_s: f64, input: &RewardInput<'_>) -> RewardTerms {
        let to_target = input.target - input.ee_pos;
        let distance = to_target.norm(); // eq. 1's D_PT
        let phi = angle_from_cosine(direction_cosine(cfg, input, &to_target));
        let movement = movement_reward(input.joint_vel, dt_s);
        RewardTerms::from_parts(cfg, distance, phi, movement)
    }

    /// Every term from D_PT (`distance`, metres), phi (radians) and R_move: the rest of
    /// [`RewardTerms::compute`], eqs. 1-18 in order.
    #[inline(always)]
    pub(crate) fn from_parts(cfg: &RewardConfig, distance: f64, phi: f64, movement: f64) -> RewardTerms {
        // Eqs. 1-2.
        let reached = distance < cfg.beta_m;
        let position = f64::from(u8::from(reached)) - distance;

        // Eqs. 3-6 (phi from `direction_cosine`).
        let direction = direction_reward(phi, cfg.direction_fold);
        let posture = position - direction; // eq. 7

        // Eqs. 8-10 (R_move from `movement_reward`).
        let stride = position - movement;

        // Eqs. 11-12.
        let gamma_posture = if distance > cfg.har_boundary_m { 1.0 } else { 0.0 };
        let har = gamma_posture * posture + (1.0 - gamma_posture) * stride;

        // Eqs. 13-15.
        let (alpha1, alpha2) = sar_weights(distance, cfg);
        let sar = alpha1 * stride + alpha2 * posture;

        // Eq. 18.
        let basic = f64::from(u8::from(reached));

        let reward = match cfg.function {
            RewardFunction::Basic => basic,
            RewardFunction::Posture => posture,
            RewardFunction::Stride => stride,
            RewardFunction::Har => har,
            RewardFunction::Sar => sar,
        };
        let bonus = if reached { cfg.success_bonus } else { 0.0 };
        RewardTerms {
            distance,
            reached,
            position,
            phi,
            direction,
            posture,
            movement,
            stride,
            gamma_posture,
            har,
            alpha1,
            alpha2,
            sar,
            basic,
            reward,
            bonus,
            total: reward + bonus,
            clearance: 0.0,
            shield: 0.0,
        }
    }

    /// The terms [`RewardTerms::try_compute`] checks for finiteness, named as in its error.
    #[inline(always)]
    fn checked(&self) -> [(&'static str, f64); 13] {
        let t = self;
        [
            ("distance", t.distance),
            ("position", t.position),
            ("phi", t.phi),
            ("direction", t.direction),
            ("posture", t.posture),
            ("move", t.movement),
            ("stride", t.stride),
            ("har", t.har),
            ("alpha1", t.alpha1),
            ("alpha2", t.alpha2),
            ("sar", t.sar),
            ("reward", t.reward),
            ("total", t.total),
        ]
    }

    /// Whether every term [`RewardTerms::try_compute`] checks is finite: for valid input, `Ok`
    /// from `try_compute` exactly when this holds of [`RewardTerms::compute`]'s result.
    #[inline]
    pub fn all_finite(&self) -> bool {
        self.checked().iter().all(|(_, v)| v.is_finite())
    }

    /// [`RewardTerms::compute`] for input from outside: the input is validated, and a term that
    /// overflows to a non-finite value for finite input (an `ee_pos` of 1e200 m squares past
    /// f64's range) is an error naming the term, not a silent infinity or NaN.
    #[inline]
    pub fn try_compute(cfg: &RewardConfig, dt_s: f64, input: &RewardInput<'_>) -> Result<RewardTerms> {
        input.validate()?;
        let t = RewardTerms::compute(cfg, dt_s, input);
        if t.all_finite() {
            Ok(t)
        } else {
            Err(t.overflow(input))
        }
    }

    /// The error for terms that are not [`RewardTerms::all_finite`]: the first such term.
    #[cold]
    #[inline(never)]
    fn overflow(&self, input: &RewardInput<'_>) -> Error {
        let terms = self.checked();
        let (name, v) = terms.iter().find(|(_, v)| !v.is_finite()).copied().unwrap_or(("total", self.total));
        Error::InvalidInput(format!(
            "the reward term `{name}` = {v} is not finite: the finite input overflows f64 \
             (distance to the target {:e} m, squared joint speed {:e}); use physical scales",
            (input.target - input.ee_pos).norm(),
            input.joint_vel.iter().map(|v| v * v).sum::<f64>()
        ))
    }
}

#[cfg(test)]
mod tests;
