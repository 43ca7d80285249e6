//! A scripted resolved-rate controller: the reference a learned reaching policy is measured
//! against, and the demonstration policy of `stagerl demo`.
//!
//! Damped least squares on the position rows of the geometric Jacobian:
//! `dq = J^T (J J^T + lambda^2 I)^-1 (gain * (T - P))`, as joint velocities `dq / dt`, scaled down
//! uniformly when a joint would exceed its speed limit (so the direction of motion is kept), and
//! returned as an action in [-1, 1] (velocity over speed limit).

use nalgebra::{Matrix3, Vector3};

use crate::env::ReachEnv;
use crate::robot::Chain;
use crate::Result;

/// Damped-least-squares Jacobian controller. Holds its scratch so that [`act`](Self::act) does
/// not allocate.
#[derive(Clone, Debug)]
pub struct JacobianController {
    /// Fraction of the remaining error to remove per step (1 = all of it if speed allows).
    pub gain: f64,
    /// Damping lambda, metres; keeps the step bounded near singularities.
    pub damping_m: f64,
    jac: Vec<f64>,
}

impl JacobianController {
    /// A controller for `chain` with gain 1 and damping 0.01 m.
    pub fn new(chain: &Chain) -> Self {
        JacobianController { gain: 1.0, damping_m: 0.01, jac: vec![0.0; 6 * chain.dof()] }
    }

    /// This controller as a rollout policy on an environment of its arm (for
    /// [`crate::env::rollout()`]).
    pub fn policy(&mut self) -> impl FnMut(&ReachEnv, &mut [f32]) -> Result<()> + '_ {
        move |env, action| {
            self.act(env.chain(), env.joint_positions(), &env.target(), env.task().dt_s, action);
            Ok(())
        }
    }

    /// Write the action for joint positions `q` (rad) towards `target` (m) into `action`.
    pub fn act(&mut self, chain: &Chain, q: &[f64], target: &Vector3<f64>, dt_s: f64, action: &mut [f32]) {
        let n = chain.dof();
        let pose = chain.jacobian(q, &mut self.jac);
        let e = (target - pose.position) * self.gain;
        // J is 6 x n row-major; the position block is rows 0..3.
        let jp = |r: usize, c: usize| self.jac[r * n + c];
        let mut jjt = Matrix3::<f64>::zeros();
        for r in 0..3 {
            for s in 0..3 {
                jjt[(r, s)] = (0..n).map(|c| jp(r, c) * jp(s, c)).sum();
            }
        }
        jjt += Matrix3::identity() * self.damping_m * self.damping_m;
        let y = jjt.try_inverse().map(|m| m * e).unwrap_or_else(Vector3::zeros);
        let vmax = chain.velocity_limits();
        let mut scale: f64 = 1.0;
        for c in 0..n {
            let dq = (0..3).map(|r| jp(r, c) * y[r]).sum::<f64>();
            let ratio = (dq / dt_s) / vmax[c];
            action[c] = ratio as f32;
            scale = scale.max(ratio.abs());
        }
        for a in action.iter_mut() {
            *a = (f64::from(*a) / scale) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::env::ReachEnv;

    #[test]
    fn reaches_every_target_in_a_few_steps() {
        let mut env = ReachEnv::from_config(&Config::default(), 21).unwrap();
        let chain = env.chain().clone();
        let mut ctl = JacobianController::new(&chain);
        let mut action = vec![0.0f32; 6];
        let (mut successes, mut steps, mut ret) = (0, 0u32, 0.0);
        let trials = 200;
        for _ in 0..trials {
            env.reset();
            loop {
                ctl.act(&chain, env.joint_positions(), &env.target(), 0.05, &mut action);
                assert!(action.iter().all(|a| a.abs() <= 1.0 + 1e-6));
                let s = env.step(&action).unwrap();
                ret += s.total();
                if s.done() {
                    successes += u32::from(s.reached());
                    steps += env.steps();
                    break;
                }
            }
        }
        let mean_steps = f64::from(steps) / f64::from(trials);
        // Design notes: a scripted IK controller succeeds 100 % in about 5.5 steps.
        assert_eq!(successes, trials, "success {successes}/{trials}");
        assert!((3.0..8.0).contains(&mean_steps), "mean steps {mean_steps}");
        assert!(ret / f64::from(trials) > 15.0, "mean return {}", ret / f64::from(trials));
    }
}
