//! The random-target reaching task of the paper (section VI), as the design notes fix it.
//!
//! Every episode starts at the home pose with a new target drawn from the task's distribution.
//! An action is one value per joint, clipped to [-1, 1] and scaled by the joint's speed limit to
//! a joint-velocity command held for `dt`; the joint positions are integrated and clamped to their
//! limits, and the velocity the reward sees is the one actually applied, `(q_new - q_old) / dt`.
//! Reaching the target (`D_PT < beta`) ends the episode (terminated) and adds the success bonus;
//! otherwise it is truncated after `max_steps` steps.
//!
//! [`ReachEnv::step`] allocates nothing.

pub mod rollout;
pub mod task;
mod vec;

pub use rollout::{rollout, Driver, Flow, Observed, Outcome, Policy, Scratch, Transition};
pub use vec::VecEnv;

use nalgebra::Vector3;
use std::f64::consts::PI;
use std::sync::Arc;

use crate::collision::{ArmCollider, CollisionKind, Contact};
use crate::reward::{RewardConfig, RewardInput, RewardTerms};
use crate::rng::Rng;
use crate::robot::{Chain, Pose};
use crate::{Error, Result};
pub use task::{ObservationKind, ResolvedTask, TaskConfig};

/// The outcome of one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Step {
    /// Every reward term; `terms.total` is what the agent receives.
    pub terms: RewardTerms,
    /// The target was reached: a terminal state.
    pub terminated: bool,
    /// The step limit was hit without reaching the target: not terminal, bootstrap through it.
    pub truncated: bool,
    /// What the arm touched after the step, if anything ([`ReachEnv::contact`] has the links).
    /// Recorded only: a collision changes neither the reward nor the episode's end.
    pub collision: Option<CollisionKind>,
}

impl Step {
    /// What the agent receives: the configured reward plus the success bonus (`terms.total`).
    pub fn total(&self) -> f64 {
        self.terms.total
    }
    /// The episode is over (terminated or truncated).
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// Number of observation values for an arm with `dof` joints.
pub fn observation_dim(kind: ObservationKind, dof: usize) -> usize {
    match kind {
        ObservationKind::Standard => dof + 10,
    }
}

/// Write the observation entries that depend on the target (metres, base frame) for an
/// end-effector at `ee` (metres): for the standard observation of a `dof`-joint arm (`obs` of
/// `dof + 10` values), the target (at `dof + 3..dof + 6`), `obs_delta_scale x (target - ee)`
/// and its norm. The environment writes its own observations with it, and hindsight relabelling
/// ([`crate::her`]) writes those of a substituted goal, so both are the same bits.
pub fn write_target_entries(task: &ResolvedTask, obs: &mut [f32], ee: Vector3<f64>, target: Vector3<f64>) {
    match task.observation {
        ObservationKind::Standard => {
            let n = obs.len() - 10;
            let d = (target - ee) * task.obs_delta_scale;
            for k in 0..3 {
                obs[n + 3 + k] = target[k] as f32;
                obs[n + 6 + k] = d[k] as f32;
            }
            obs[n + 9] = d.norm() as f32;
        }
    }
}

/// Check joint positions for `chain`: one finite value per joint, each within its joint's limits.
pub fn check_joint_positions(chain: &Chain, q: &[f64]) -> Result<()> {
    let n = chain.dof();
    if q.len() != n {
        return Err(Error::InvalidInput(format!(
            "start pose has {} values, expected {n} (one per joint of the arm, radians)",
            q.len()
        )));
    }
    for (i, (j, &v)) in chain.joints().iter().zip(q).enumerate() {
        if !(v.is_finite() && v >= j.lower && v <= j.upper) {
            return Err(Error::InvalidInput(format!(
                "start pose: joint {i} `{}` = {v} is outside its limits [{}, {}]",
                j.name, j.lower, j.upper
            )));
        }
    }
    Ok(())
}

/// Everything that changes as a [`ReachEnv`] runs, for exact checkpoints: the random stream and,
/// mid-episode, the joint positions, the target and the step count. The end-effector pose and the
/// observation follow from these.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnvState {
    pub rng: Rng,
    pub q: Vec<f64>,
    pub joint_vel: Vec<f64>,
    pub target: [f64; 3],
    pub steps: u32,
    pub done: bool,
}

/// The reaching environment.
#[derive(Clone, Debug)]
pub struct ReachEnv {
    chain: Arc<Chain>,
    task: ResolvedTask,
    reward: RewardConfig,
    rng: Rng,
    q: Vec<f64>,
    joint_vel: Vec<f64>,
    scratch: Vec<f64>,
    ee: Pose,
    target: Vector3<f64>,
    steps: u32,
    done: bool,
    obs: Vec<f32>,
    /// The collision checker, when the arm has collision shapes.
    collider: Option<ArmCollider>,
    contact: Option<Contact>,
}

impl ReachEnv {
    /// An environment for `chain`, seeded; call [`ReachEnv::reset`] before stepping.
    pub fn new(chain: Arc<Chain>, task: ResolvedTask, reward: RewardConfig, seed: u64) -> Result<ReachEnv> {
        reward.validate()?;
        let n = chain.dof();
        if task.home_pose.len() != n || task.target_joint_range.len() != n {
            return Err(Error::InvalidInput(format!(
                "the task was resolved for {} joints, the arm has {n}",
                task.home_pose.len()
            )));
        }
        let obs_dim = observation_dim(task.observation, n);
        let q = task.home_pose.clone();
        let ee = chain.fk(&q);
        let collider = (!chain.collision_shapes().is_empty()).then(|| {
            let mut c = ArmCollider::new(&chain, task.collision);
            c.set_obstacles(&task.obstacles);
            c
        });
        let mut env = ReachEnv {
            collider,
            contact: None,
            chain,
            rng: Rng::new(seed),
            joint_vel: vec![0.0; n],
            scratch: vec![0.0; n],
            ee,
            target: ee.position,
            steps: 0,
            done: true,
            obs: vec![0.0; obs_dim],
            q,
            task,
            reward,
        };
        env.write_observation();
        Ok(env)
    }

    /// Start a new episode: home pose, new target from the environment's random stream.
    pub fn reset(&mut self) -> &[f32] {
        self.q.copy_from_slice(&self.task.home_pose);
        self.target = self.task.sample_target(&self.chain, &mut self.rng, &mut self.scratch);
        self.begin_episode()
    }

    /// Reseed the random stream, then [`ReachEnv::reset`].
    pub fn reset_with_seed(&mut self, seed: u64) -> &[f32] {
        self.rng = Rng::new(seed);
        self.reset()
    }

    /// Start a new episode at the home pose with a given target (metres, base frame).
    pub fn reset_to_target(&mut self, target: Vector3<f64>) -> Result<&[f32]> {
        if !target.iter().all(|x| x.is_finite()) {
            return Err(Error::InvalidInput(format!("target {target:?} is not finite")));
        }
        self.q.copy_from_slice(&self.task.home_pose);
        self.target = target;
        Ok(self.begin_episode())
    }

    /// Start a new episode at joint positions `start` (radians, metres for prismatic joints)
    /// with a given target (metres, base frame); the random stream is untouched.
    ///
    /// Errors: `start` without one value per joint (the expected count given), a value that is
    /// not finite or outside its joint's limits (the joint, the value and the limits named), a
    /// target that is not finite.
    pub fn reset_to(&mut self, start: &[f64], target: Vector3<f64>) -> Result<&[f32]> {
        check_joint_positions(&self.chain, start)?;
        if !target.iter().all(|x| x.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "target {:?} is not finite",
                [target.x, target.y, target.z]
            )));
        }
        self.q.copy_from_slice(start);
        self.target = target;
        Ok(self.begin_episode())
    }

    fn begin_episode(&mut self) -> &[f32] {
        self.joint_vel.fill(0.0);
        self.ee = self.chain.fk(&self.q);
        self.check_contact();
        self.steps = 0;
        self.done = false;
        self.write_observation();
        &self.obs
    }

    /// Apply one action (one value per joint, nominally in [-1, 1]; clipped).
    ///
    /// Errors: a wrong length, a NaN or infinite value, or a step after the episode ended.
    pub fn step(&mut self, action: &[f32]) -> Result<Step> {
        let n = self.q.len();
        if action.len() != n {
            return Err(Error::InvalidInput(format!(
                "action has {} values, the arm has {n} joints",
                action.len()
            )));
        }
        if let Some(i) = action.iter().position(|a| !a.is_finite()) {
            return Err(Error::InvalidInput(format!("action[{i}] = {} is not finite", action[i])));
        }
        if self.done {
            return Err(Error::InvalidInput("the episode is over: call reset() before step()".into()));
        }
        let dt = self.task.dt_s;
        let (lo, hi, vmax) =
            (self.chain.lower_limits(), self.chain.upper_limits(), self.chain.velocity_limits());
        let prev_ee = self.ee.position;
        for i in 0..n {
            let command = f64::from(action[i].clamp(-1.0, 1.0)) * vmax[i];
            let q_old = self.q[i];
            let q_new = (q_old + command * dt).clamp(lo[i], hi[i]);
            self.joint_vel[i] = (q_new - q_old) / dt;
            self.q[i] = q_new;
        }
        self.ee = self.chain.fk(&self.q);
        self.check_contact();
        self.steps += 1;
        let terms = RewardTerms::compute(
            &self.reward,
            dt,
            &RewardInput {
                ee_pos: self.ee.position,
                ee_quat: self.ee.quaternion_xyzw(),
                target: self.target,
                joint_vel: &self.joint_vel,
                prev_ee_pos: Some(prev_ee),
            },
        );
        let terminated = terms.reached;
        let truncated = !terminated && self.steps >= self.task.max_steps;
        self.done = terminated || truncated;
        self.write_observation();
        Ok(Step { terms, terminated, truncated, collision: self.contact.map(|c| c.kind()) })
    }

    /// Look for the arm's contacts at its current joint positions ([`ReachEnv::contact`]).
    fn check_contact(&mut self) {
        self.contact = self.collider.as_mut().and_then(|c| c.check(&self.chain, &self.q));
    }

    fn write_observation(&mut self) {
        match self.task.observation {
            ObservationKind::Standard => {
                let n = self.q.len();
                for (o, q) in self.obs.iter_mut().zip(&self.q) {
                    *o = (q / PI) as f32;
                }
                let p = self.ee.position;
                for k in 0..3 {
                    self.obs[n + k] = p[k] as f32;
                }
            }
        }
        write_target_entries(&self.task, &mut self.obs, self.ee.position, self.target);
    }

    /// What the arm touches at its current joint positions (checked at every reset and step),
    /// if anything; [`Contact::describe`] names the links.
    pub fn contact(&self) -> Option<Contact> {
        self.contact
    }

    /// The current observation.
    pub fn observation(&self) -> &[f32] {
        &self.obs
    }
    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.obs.len()
    }
    /// Action length (the number of joints).
    pub fn act_dim(&self) -> usize {
        self.q.len()
    }
    /// Joint positions, radians (metres for prismatic joints).
    pub fn joint_positions(&self) -> &[f64] {
        &self.q
    }
    /// Joint velocities applied in the last step, rad/s.
    pub fn joint_velocities(&self) -> &[f64] {
        &self.joint_vel
    }
    /// End-effector pose after the last step or reset.
    pub fn ee_pose(&self) -> &Pose {
        &self.ee
    }
    /// The episode's target, metres.
    pub fn target(&self) -> Vector3<f64> {
        self.target
    }
    /// D_PT now, metres.
    pub fn distance(&self) -> f64 {
        (self.target - self.ee.position).norm()
    }
    /// Steps taken in this episode.
    pub fn steps(&self) -> u32 {
        self.steps
    }
    /// The episode has ended.
    pub fn is_done(&self) -> bool {
        self.done
    }
    /// The arm.
    pub fn chain(&self) -> &Arc<Chain> {
        &self.chain
    }
    /// The resolved task.
    pub fn task(&self) -> &ResolvedTask {
        &self.task
    }
    /// The reward settings.
    pub fn reward_config(&self) -> &RewardConfig {
        &self.reward
    }
    /// The environment's whole state (for checkpoints).
    pub fn state(&self) -> EnvState {
        EnvState {
            rng: self.rng.clone(),
            q: self.q.clone(),
            joint_vel: self.joint_vel.clone(),
            target: [self.target.x, self.target.y, self.target.z],
            steps: self.steps,
            done: self.done,
        }
    }

    /// Restore a state from [`ReachEnv::state`]; errors if it does not fit this arm.
    pub fn restore(&mut self, s: &EnvState) -> Result<()> {
        let n = self.q.len();
        if s.q.len() != n || s.joint_vel.len() != n {
            return Err(Error::InvalidInput(format!(
                "environment state for {} joints, the arm has {n}",
                s.q.len()
            )));
        }
        let finite = s.q.iter().chain(&s.joint_vel).chain(&s.target).all(|x| x.is_finite());
        if !finite {
            return Err(Error::InvalidInput("environment state holds a non-finite value".into()));
        }
        self.rng = s.rng.clone();
        self.q.copy_from_slice(&s.q);
        self.joint_vel.copy_from_slice(&s.joint_vel);
        self.target = Vector3::from(s.target);
        self.steps = s.steps;
        self.done = s.done;
        self.ee = self.chain.fk(&self.q);
        self.check_contact();
        self.write_observation();
        Ok(())
    }

    /// The random generator's state (for checkpoints).
    pub fn rng(&self) -> &Rng {
        &self.rng
    }
    /// Replace the random generator's state (when resuming).
    pub fn set_rng(&mut self, rng: Rng) {
        self.rng = rng;
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::reward::RewardFunction;

    /// The default task on the UR5 with `reward`.
    pub(crate) fn ur5_env(reward: RewardConfig, seed: u64) -> ReachEnv {
        let chain = Arc::new(Chain::ur5());
        let task = TaskConfig::default().resolve(&chain).unwrap();
        ReachEnv::new(chain, task, reward, seed).unwrap()
    }

    fn env(seed: u64) -> ReachEnv {
        ur5_env(RewardConfig::default(), seed)
    }

    #[test]
    fn reset_starts_at_home_with_a_target_above_the_floor() {
        let mut e = env(1);
        let mut dists = Vec::new();
        for _ in 0..300 {
            e.reset();
            assert_eq!(e.joint_positions(), &task::UR5_HOME_POSE_RAD);
            assert!(e.target().z > 0.05);
            dists.push(e.distance());
        }
        let mean = dists.iter().sum::<f64>() / dists.len() as f64;
        // Design notes: the mean start distance is about 0.44 m, so both HAR stages occur.
        assert!((0.35..0.55).contains(&mean), "mean start distance {mean}");
        assert!(dists.iter().any(|&d| d > 0.5) && dists.iter().any(|&d| d < 0.5));
    }

    #[test]
    fn observation_layout() {
        let mut e = env(2);
        e.reset();
        let o = e.observation().to_vec();
        assert_eq!(o.len(), 16);
        let (p, t) = (e.ee_pose().position, e.target());
        for k in 0..6 {
            assert_eq!(o[k], (e.joint_positions()[k] / PI) as f32);
        }
        for k in 0..3 {
            assert_eq!(o[6 + k], p[k] as f32);
            assert_eq!(o[9 + k], t[k] as f32);
            assert_eq!(o[12 + k], ((t[k] - p[k]) * 10.0) as f32);
        }
        assert_eq!(o[15], (e.distance() * 10.0) as f32);
    }

    #[test]
    fn action_is_clipped_scaled_and_applied_velocity_is_reported() {
        let mut e = env(3);
        e.reset();
        let q0 = e.joint_positions().to_vec();
        let s = e.step(&[5.0, -5.0, 0.5, 0.0, 0.0, -0.25]).unwrap();
        let q1 = e.joint_positions();
        let dt = 0.05;
        let expect = [PI, -PI, 0.5 * PI, 0.0, 0.0, -0.25 * PI];
        for i in 0..6 {
            assert!((q1[i] - (q0[i] + expect[i] * dt)).abs() < 1e-12, "joint {i}");
            assert!((e.joint_velocities()[i] - expect[i]).abs() < 1e-9, "joint {i}");
        }
        // The movement term sees the applied velocity (eq. 9).
        let vv: f64 = expect.iter().map(|v| v * v).sum();
        assert!((s.terms.movement - dt * vv / 6.0).abs() < 1e-9);
    }

    #[test]
    fn joint_limits_clamp_and_the_reported_velocity_follows() {
        let mut e = env(4);
        e.reset();
        // The elbow starts at pi/2 with limit pi: 20 full-speed steps would go to 3.5 pi/2.
        for _ in 0..20 {
            if e.step(&[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).unwrap().done() {
                break;
            }
        }
        assert!(e.joint_positions()[2] <= PI);
        assert!((e.joint_positions()[2] - PI).abs() < 1e-12);
        // Once clamped, the applied velocity is zero.
        assert!(e.joint_velocities()[2].abs() < 1e-9);
    }

    #[test]
    fn truncates_at_max_steps_and_refuses_to_step_after() {
        let mut e = env(5);
        e.reset();
        let mut last = None;
        for k in 1..=50 {
            let s = e.step(&[0.0; 6]).unwrap();
            assert!(!s.terminated);
            assert_eq!(s.truncated, k == 50);
            last = Some(s);
        }
        assert!(last.unwrap().truncated);
        let err = e.step(&[0.0; 6]).unwrap_err().to_string();
        assert!(err.contains("reset"), "{err}");
    }

    #[test]
    fn bad_actions_are_errors_not_clamps() {
        let mut e = env(6);
        e.reset();
        assert!(e.step(&[0.0; 5]).unwrap_err().to_string().contains("6 joints"));
        let err = e.step(&[0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0]).unwrap_err().to_string();
        assert!(err.contains("action[1]"), "{err}");
        let err = e.step(&[0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0]).unwrap_err().to_string();
        assert!(err.contains("action[3]"), "{err}");
        // The failed calls did not advance the episode.
        assert_eq!(e.steps(), 0);
    }

    #[test]
    fn success_terminates_with_the_bonus() {
        let mut e = env(7);
        e.reset();
        // Put the target where one known action will take the end-effector.
        let mut probe = e.clone();
        probe.step(&[0.3, -0.2, 0.1, 0.0, 0.4, 0.0]).unwrap();
        let reached_at = probe.ee_pose().position + Vector3::new(0.004, 0.0, 0.0);
        e.reset_to_target(reached_at).unwrap();
        let s = e.step(&[0.3, -0.2, 0.1, 0.0, 0.4, 0.0]).unwrap();
        assert!(s.terminated && !s.truncated);
        assert!((s.terms.distance - 0.004).abs() < 1e-12);
        assert_eq!(s.terms.bonus, 20.0);
        assert_eq!(s.total(), s.terms.reward + 20.0);
        assert!(e.is_done());
    }

    #[test]
    fn same_seed_same_episodes() {
        let run = |seed| {
            let mut e = env(seed);
            let mut rng = Rng::new(99);
            let mut out = Vec::new();
            for _ in 0..5 {
                e.reset();
                out.push(e.target());
                loop {
                    let a: Vec<f32> = (0..6).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
                    let s = e.step(&a).unwrap();
                    out.push(Vector3::new(s.total(), s.terms.distance, 0.0));
                    if s.done() {
                        break;
                    }
                }
            }
            out
        };
        assert_eq!(run(11), run(11));
        assert_ne!(run(11), run(12));
    }

    #[test]
    fn state_restore_continues_identically() {
        let mut a = env(31);
        a.reset();
        a.step(&[0.2, -0.1, 0.3, 0.0, 0.5, -0.4]).unwrap();
        let saved = a.state();
        let mut b = env(999);
        b.restore(&saved).unwrap();
        assert_eq!(a.observation(), b.observation());
        for _ in 0..3 {
            let sa = a.step(&[0.1; 6]).unwrap();
            let sb = b.step(&[0.1; 6]).unwrap();
            assert_eq!(sa, sb);
        }
        a.reset();
        b.reset();
        assert_eq!(a.target(), b.target());
        let bad = EnvState { q: vec![0.0; 5], ..saved };
        assert!(b.restore(&bad).is_err());
    }

    #[test]
    fn reward_function_selects_the_reward() {
        for f in RewardFunction::ALL {
            let mut e = ur5_env(RewardConfig { function: f, ..RewardConfig::default() }, 8);
            e.reset();
            let s = e.step(&[0.1; 6]).unwrap();
            let t = s.terms;
            let expect = match f {
                RewardFunction::Basic => t.basic,
                RewardFunction::Posture => t.posture,
                RewardFunction::Stride => t.stride,
                RewardFunction::Har => t.har,
                RewardFunction::Sar => t.sar,
            };
            assert_eq!(t.reward, expect, "{f}");
        }
    }

    fn panda_env(
        obstacles: Vec<crate::collision::Obstacle>,
        checks: Option<crate::collision::Checks>,
    ) -> ReachEnv {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/robots/panda.urdf");
        let chain = Arc::new(Chain::from_urdf_file(std::path::Path::new(path), None).unwrap());
        let task = TaskConfig {
            home_pose_rad: Some(PANDA_HOME.to_vec()),
            target_joint_range_rad: Some(vec![0.8, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0]),
            obstacles,
            collision: checks,
            ..TaskConfig::default()
        };
        let task = task.resolve(&chain).unwrap();
        ReachEnv::new(chain, task, RewardConfig::default(), 3).unwrap()
    }

    const PANDA_HOME: [f64; 7] = {
        use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
        [0.0, -FRAC_PI_4, 0.0, -3.0 * FRAC_PI_4, 0.0, FRAC_PI_2, FRAC_PI_4]
    };

    /// Contacts are found at reset and after each step, named, and recorded in the step; they
    /// change nothing else: with the checks off, the same steps give the same bits.
    #[test]
    fn collisions_are_recorded_and_change_nothing_else() {
        use crate::collision::{Checks, CollisionKind, Contact, Obstacle};
        let mut env = panda_env(Vec::new(), None);
        env.reset();
        assert_eq!(env.contact(), None, "the home pose is clear");
        // A pose with the flange below the floor (shoulder forward, elbow open).
        let low = [0.0, 1.7, 0.0, -0.5, 0.0, 1.57, 0.0];
        let target = Vector3::new(0.5, 0.0, 0.3);
        env.reset_to(&low, target).unwrap();
        let c = env.contact().expect("a contact below the floor");
        assert_eq!(c.kind(), CollisionKind::Floor);
        assert!(c.describe(env.chain()).contains("with the floor"), "{}", c.describe(env.chain()));
        let step = env.step(&[0.0; 7]).unwrap();
        assert_eq!(step.collision, Some(CollisionKind::Floor));
        // An obstacle at the tool of the home pose.
        let tool = env.chain().fk(&PANDA_HOME).position;
        let ball = Obstacle::sphere(0.05, [tool.x, tool.y, tool.z]);
        let mut env = panda_env(vec![ball], None);
        env.reset();
        assert!(matches!(env.contact(), Some(Contact::Obstacle { obstacle: 0, .. })));
        // Recording changes nothing: the same random steps with all checks off.
        let mut on = panda_env(Vec::new(), None);
        let mut off = panda_env(Vec::new(), Some(Checks { floor: false, self_collision: false }));
        let (mut rng, mut seen) = (Rng::new(9), 0);
        for _ in 0..20 {
            assert_eq!(on.reset(), off.reset());
            while !on.is_done() {
                let a: Vec<f32> = (0..7).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
                let (x, y) = (on.step(&a).unwrap(), off.step(&a).unwrap());
                assert_eq!(x.terms, y.terms);
                assert_eq!((x.terminated, x.truncated), (y.terminated, y.truncated));
                assert_eq!(on.observation(), off.observation());
                assert_eq!(y.collision, None);
                seen += usize::from(x.collision.is_some());
            }
        }
        assert!(seen > 0, "random motion touched something at least once");
    }
}
