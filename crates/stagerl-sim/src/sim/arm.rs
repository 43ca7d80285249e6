//! The simulated arm an environment steps, behind one interface that it calls once a step: the
//! kinematic simulation or the dynamic one ([`super::physics`]), and the scene's collision checks
//! ([`super::collision`]).
//!
//! A step of `dt` seconds from joint positions `q` with an action `a` (one value per joint):
//! 1. the command `c_i = clip(a_i, -1, 1) * vmax_i` (rad/s, m/s for prismatic joints);
//!    with the shield on (`[task.shield]`, kinematic only), `c` is then filtered by
//!    [`super::shield::Shield::filter`];
//! 2. kinematic: `q_i' = clip(q_i + c_i dt, lo_i, hi_i)`; dynamic: `c` drives the joints' velocity
//!    motors for `dt`, and `q'` is where the simulated arm got to, clamped to the limits (a joint
//!    a hair past its limit in f32 continues from the clamped pose);
//! 3. the joint velocity that counts is the one achieved, `(q' - q) / dt`;
//! 4. the collision checks look for contacts at `q'` (floor, self, obstacles).

use super::collision::{ArmCollider, Checks, Contact};
use super::physics::DynamicArm;
use super::scene::Obstacle;
use super::shield::{Shield, ShieldConfig};
use crate::robot::Chain;
use crate::{Error, Result};

/// An arm in its scene, kinematic or dynamic.
#[derive(Clone, Debug)]
pub struct Arm {
    /// The rigid-body simulation, boxed: it is large. `None`: kinematic.
    physics: Option<Box<DynamicArm>>,
    /// The collision checker, when the arm has collision shapes.
    collider: Option<ArmCollider>,
    /// What the arm touches at its current joint positions.
    contact: Option<Contact>,
    /// The joints' commands, then the simulated positions (scratch, one per joint).
    scratch: Vec<f64>,
    /// The safety shield, when on (kinematic arms with collision shapes only).
    shield: Option<Box<Shield>>,
}

impl Arm {
    /// The arm of `chain` among `obstacles`, with the collision checks `checks` (when the chain
    /// has collision shapes); `dynamic` for the rigid-body simulation with control period `dt_s`.
    ///
    /// Errors: those of [`DynamicArm::new`] for a dynamic arm.
    pub fn new(
        chain: &Chain,
        dynamic: bool,
        dt_s: f64,
        obstacles: &[Obstacle],
        checks: Checks,
    ) -> Result<Arm> {
        let collider = (!chain.collision_shapes().is_empty()).then(|| {
            let mut c = ArmCollider::new(chain, checks);
            c.set_obstacles(obstacles);
            c
        });
        let physics = match dynamic {
            false => None,
            true => {
                Some(Box::new(DynamicArm::new(chain.urdf_source(), chain, dt_s, obstacles, checks.floor)?))
            }
        };
        Ok(Arm { physics, collider, contact: None, scratch: vec![0.0; chain.dof()], shield: None })
    }

    /// Put the scene's obstacles in place of the ones before.
    pub fn set_obstacles(&mut self, obstacles: &[Obstacle]) {
        if let Some(c) = &mut self.collider {
            c.set_obstacles(obstacles);
        }
        if let Some(p) = &mut self.physics {
            p.set_obstacles(obstacles);
        }
    }

    /// The collision checker, if the arm has collision shapes (obstacle placement tests
    /// candidates with it).
    pub fn collider_mut(&mut self) -> Option<&mut ArmCollider> {
        self.collider.as_mut()
    }

    /// The collision checker, if the arm has collision shapes.
    pub fn collider(&self) -> Option<&ArmCollider> {
        self.collider.as_ref()
    }

    /// Put the arm at joint positions `q` (checked against the limits by the caller) with joint
    /// velocities `v` (dynamic: the simulation's state; kinematic: unused), and look for its
    /// contacts.
    pub fn set_state(&mut self, chain: &Chain, q: &[f64], v: &[f64]) -> Result<()> {
        if let Some(p) = &mut self.physics {
            p.set_state(q, v)?;
        }
        self.check_contact(chain, q);
        Ok(())
    }

    /// One step of `dt_s` seconds: `q` and `joint_vel` (the achieved velocities) are updated in
    /// place (see the module docs), then the contacts looked for. `step` (1-based, this one)
    /// names the step in an error.
    ///
    /// Errors: [`Error::NumericalFault`] when the dynamic simulation gives a joint a position
    /// that is not finite (`q` is then left as it was).
    #[inline]
    pub fn step(
        &mut self,
        chain: &Chain,
        action: &[f32],
        dt_s: f64,
        step: u32,
        q: &mut [f64],
        joint_vel: &mut [f64],
    ) -> Result<()> {
        let n = q.len();
        let (lo, hi, vmax) = (chain.lower_limits(), chain.upper_limits(), chain.velocity_limits());
        match &mut self.physics {
            None if self.shield.is_some() => self.step_shielded(chain, action, dt_s, q, joint_vel),
            None => {
                for i in 0..n {
                    let command = f64::from(action[i].clamp(-1.0, 1.0)) * vmax[i];
                    let q_old = q[i];
                    let q_new = (q_old + command * dt_s).clamp(lo[i], hi[i]);
                    joint_vel[i] = (q_new - q_old) / dt_s;
                    q[i] = q_new;
                }
            }
            Some(p) => {
                // The command goes to the joints' motors; the velocity that counts is the one
                // the simulated arm achieved over the step.
                for i in 0..n {
                    self.scratch[i] = f64::from(action[i].clamp(-1.0, 1.0)) * vmax[i];
                }
                p.step(&self.scratch);
                p.joint_positions(&mut self.scratch);
                if let Some(i) = self.scratch.iter().position(|x| !x.is_finite()) {
                    return Err(Error::NumericalFault(format!(
                        "the dynamic simulation gave joint {i} the position {} at step {step} of the \
                         episode; the episode is over",
                        self.scratch[i]
                    )));
                }
                let mut clamped = false;
                for i in 0..n {
                    let (q_old, q_new) = (q[i], self.scratch[i].clamp(lo[i], hi[i]));
                    clamped |= q_new != self.scratch[i];
                    joint_vel[i] = (q_new - q_old) / dt_s;
                    q[i] = q_new;
                }
                if clamped {
                    // A joint a hair past its limit (f32): the simulation continues from the
                    // clamped pose, as a restored state would.
                    p.joint_velocities(&mut self.scratch);
                    p.set_state(q, &self.scratch).expect("clamped joint positions are a valid state");
                }
            }
        }
        self.check_contact(chain, q);
        Ok(())
    }

    /// The kinematic step with the shield: the commands filtered, then integrated as without.
    fn step_shielded(
        &mut self,
        chain: &Chain,
        action: &[f32],
        dt_s: f64,
        q: &mut [f64],
        joint_vel: &mut [f64],
    ) {
        let (lo, hi, vmax) = (chain.lower_limits(), chain.upper_limits(), chain.velocity_limits());
        for (i, c) in self.scratch.iter_mut().enumerate() {
            *c = f64::from(action[i].clamp(-1.0, 1.0)) * vmax[i];
        }
        if let (Some(shield), Some(collider)) = (&mut self.shield, &mut self.collider) {
            shield.filter(chain, collider, q, &mut self.scratch, dt_s);
        }
        for i in 0..q.len() {
            let q_old = q[i];
            let q_new = (q_old + self.scratch[i] * dt_s).clamp(lo[i], hi[i]);
            joint_vel[i] = (q_new - q_old) / dt_s;
            q[i] = q_new;
        }
    }

    /// Turn the safety shield on with `config` (off: `None`).
    ///
    /// Errors: a dynamic arm (the shield needs the kinematic simulation's exact motion), an arm
    /// without collision shapes (nothing to keep apart), values out of range.
    pub fn set_shield(&mut self, chain: &Chain, config: Option<ShieldConfig>) -> Result<()> {
        let Some(config) = config.filter(|c| c.enabled) else {
            self.shield = None;
            return Ok(());
        };
        config.validate()?;
        if self.physics.is_some() {
            return Err(Error::config(
                "task.shield.enabled",
                true,
                "false with task.sim = \"dynamic\": the shield verifies the motion a command makes, \
                 which only the kinematic simulation carries out exactly",
            ));
        }
        let Some(collider) = self.collider.as_mut() else {
            return Err(Error::config(
                "task.shield.enabled",
                true,
                format!(
                    "false for this arm: no link of `{}` to `{}` has a collision shape, so there is \
                     nothing to keep apart",
                    chain.base_link(),
                    chain.tip_link()
                ),
            ));
        };
        self.shield = Some(Box::new(Shield::new(chain, collider, config)));
        Ok(())
    }

    /// The safety shield, when on.
    pub fn shield(&self) -> Option<&Shield> {
        self.shield.as_deref()
    }

    /// The safety shield, when on (to reset its counts).
    pub fn shield_mut(&mut self) -> Option<&mut Shield> {
        self.shield.as_deref_mut()
    }

    /// Look for the arm's contacts at joint positions `q`.
    #[inline]
    fn check_contact(&mut self, chain: &Chain, q: &[f64]) {
        self.contact = self.collider.as_mut().and_then(|c| c.check(chain, q));
    }

    /// What the arm touches at its current joint positions, if anything.
    pub fn contact(&self) -> Option<Contact> {
        self.contact
    }

    /// The dynamic simulation's joint velocities (rad/s), which with the joint positions are its
    /// state; empty for the kinematic arm.
    pub fn sim_velocities(&self) -> Vec<f64> {
        self.physics.as_ref().map_or_else(Vec::new, |p| {
            let mut v = vec![0.0; self.scratch.len()];
            p.joint_velocities(&mut v);
            v
        })
    }
}
