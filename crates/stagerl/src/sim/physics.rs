//! Dynamic simulation of a serial arm: rapier3d (f32, single thread) with the arm as a
//! reduced-coordinate multibody loaded from its URDF by `rapier3d-urdf`.
//!
//! The arm's root link is fixed; gravity is -9.81 m/s^2 along the base frame's z. Each actuated
//! joint of the [`Chain`] carries a velocity motor whose force or torque is capped at the joint's
//! effort limit ([`crate::robot::JointInfo::effort`]), and the multibody enforces the URDF's
//! position limits. Obstacles ([`Obstacle`]) and, optionally, the floor (the half-space z <= 0)
//! are static colliders; the arm's colliders are its URDF's `<collision>` primitives (cylinders
//! as cylinders; meshes are not simulated). Links that share a joint do not collide with each
//! other; other links do.
//!
//! Settings (those that held a UR5 still and tracked its commands, see the design notes):
//! one physics step per control step ([`DynamicArm::new`]'s `dt_s`), [`SOLVER_ITERATIONS`] solver
//! iteration with [`INTERNAL_PGS_ITERATIONS`] internal PGS iterations, motor damping
//! [`MOTOR_DAMPING`], sleeping off, continuous collision detection off (see `params`). Pairs of
//! colliders far apart are kept out of the narrow phase (`FarPairs`, which changes no result).
//!
//! Determinism: a step is a function of the joint positions, the joint velocities and the
//! command alone, bit for bit (single thread, no `parallel` feature). Rapier carries state from
//! step to step besides the arm's own (contact warm-start impulses, the order of contact pairs,
//! the broad phase's tree), and that state matters when there are contacts. So by default
//! ([`DynamicArm::set_exact_resume`]) a step that ends up with an active contact is taken again
//! on a fresh world (a copy of the world as first built, kept for that: the same bits as building
//! it again) at the state the step started from, and a step after one with contact starts on a
//! fresh world directly; a step without
//! contact is independent of that history (contact recycling is off, and
//! the multibody's internal joint constraints start from zero impulses every step).
//! [`DynamicArm::set_state`] also starts a fresh world. Storing `q`, `qdot` and calling
//! [`DynamicArm::set_state`] therefore resumes a run exactly, in another process too.
//!
//! Units: metres, radians, seconds, kilograms; N m (revolute) or N (prismatic) efforts.

use std::path::Path;

use rapier3d::prelude::*;
use rapier3d_urdf::{urdf_rs, UrdfLoaderOptions, UrdfMultibodyOptions, UrdfRobot};

use crate::robot::{Chain, JointKind};
use crate::sim::scene::{Obstacle, ObstacleShape};
use crate::{Error, Result};

/// Solver iterations per physics step (rapier's `num_solver_iterations`; its default of 4 with
/// one internal iteration let a UR5 sag about 1 rad in 5 s).
pub const SOLVER_ITERATIONS: usize = 1;
/// Internal projected-Gauss-Seidel iterations per solver iteration (rapier's
/// `num_internal_pgs_iterations`): the joint motors are solved one at a time and need these to
/// settle against each other.
pub const INTERNAL_PGS_ITERATIONS: usize = 30;
/// Velocity-motor damping (rapier's acceleration-based motor model, 1/s): stiff tracking of the
/// commanded velocity, the effort limit permitting.
pub const MOTOR_DAMPING: f32 = 1e5;
/// Gravity, m/s^2, along -z of the base frame.
pub const GRAVITY_M_S2: f32 = 9.81;

/// One chain joint in the multibody.
#[derive(Clone, Copy, Debug)]
struct Dof {
    /// The multibody link the joint moves.
    link: usize,
    /// Its index in the multibody's generalized coordinates.
    index: usize,
    /// Its free axis: `AngX` (revolute) or `LinX` (prismatic), in the loader's joint frame.
    axis: JointAxis,
}

/// Everything needed to build the world afresh: the loaded arm and the static colliders.
#[derive(Clone)]
struct Template {
    robot: UrdfRobot,
    statics: Vec<Collider>,
    params: IntegrationParameters,
}

impl Template {
    /// A new world with the arm at its URDF zero pose and zero velocity, its dof layout settled;
    /// its multibody, and the arm's bodies in the loader's link order.
    fn build(&self) -> (PhysicsWorld, MultibodyIndex, Vec<RigidBodyHandle>) {
        let mut w = PhysicsWorld::new();
        // A tree of some twenty leaves gains nothing from rapier's incremental re-optimization
        // (2 % of a step's instructions); it finds the same pairs (the order could differ).
        w.broad_phase = BroadPhaseBvh::with_optimization_strategy(BvhOptimizationStrategy::None);
        w.gravity = Vector::new(0.0, 0.0, -GRAVITY_M_S2);
        w.integration_parameters = self.params;
        let handles = self.robot.clone().insert_using_multibody_joints(
            &mut w.bodies,
            &mut w.colliders,
            &mut w.multibody_joints,
            UrdfMultibodyOptions::empty(),
        );
        for c in &self.statics {
            w.colliders.insert(c.clone());
        }
        // Every link of the arm is in one multibody (checked in `DynamicArm::new`).
        let root = handles.links[0].body;
        let index = w.multibody_joints.rigid_body_link(root).map(|l| l.multibody);
        let index = index.expect("the arm's links form a multibody");
        let mb = w.multibody_joints.get_multibody_mut(index).expect("the multibody exists");
        // Recognise the fixed root now (otherwise the first step does it, changing the dofs).
        mb.forward_kinematics(&w.bodies, true);
        mb.update_rigid_bodies(&mut w.bodies, true);
        (w, index, handles.links.iter().map(|l| l.body).collect())
    }
}

/// The world as [`Template::build`] returns it (before any step and before the state is
/// written in), kept in parts that can be cloned (`PhysicsWorld` itself cannot): a world made
/// from a copy, with new pipelines, is the one a build would give, bit for bit, at a fraction
/// of the cost (no URDF robot to clone and insert).
#[derive(Clone)]
struct Snapshot {
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    multibody: MultibodyIndex,
}

impl Snapshot {
    /// A copy of `w`, a world fresh from [`Template::build`] with the arm's multibody `multibody`.
    fn of(w: &PhysicsWorld, multibody: MultibodyIndex) -> Snapshot {
        Snapshot {
            islands: w.islands.clone(),
            broad_phase: w.broad_phase.clone(),
            narrow_phase: w.narrow_phase.clone(),
            bodies: w.bodies.clone(),
            colliders: w.colliders.clone(),
            impulse_joints: w.impulse_joints.clone(),
            multibody_joints: w.multibody_joints.clone(),
            soft_bodies: w.soft_bodies.clone(),
            multibody,
        }
    }

    /// A new world from the copy: the same as [`Template::build`]'s (new pipelines and CCD
    /// workspace, as there), with `params`.
    fn world(&self, params: IntegrationParameters) -> PhysicsWorld {
        PhysicsWorld {
            gravity: Vector::new(0.0, 0.0, -GRAVITY_M_S2),
            integration_parameters: params,
            physics_pipeline: PhysicsPipeline::new(),
            collision_pipeline: CollisionPipeline::new(),
            islands: self.islands.clone(),
            broad_phase: self.broad_phase.clone(),
            narrow_phase: self.narrow_phase.clone(),
            bodies: self.bodies.clone(),
            colliders: self.colliders.clone(),
            impulse_joints: self.impulse_joints.clone(),
            multibody_joints: self.multibody_joints.clone(),
            soft_bodies: self.soft_bodies.clone(),
            ccd_solver: CCDSolver::new(),
        }
    }
}

/// A serial arm under velocity control in a rigid-body simulation (see the module docs).
///
/// Physics settings: [`SOLVER_ITERATIONS`], [`INTERNAL_PGS_ITERATIONS`], [`MOTOR_DAMPING`],
/// [`GRAVITY_M_S2`], one physics step of `dt_s` per [`DynamicArm::step`].
pub struct DynamicArm {
    template: Template,
    /// The template's world as built, which fresh worlds are copies of.
    snapshot: Snapshot,
    world: PhysicsWorld,
    /// The bounding shapes of the world's colliders (the same handles in every copy).
    far_pairs: FarPairs,
    multibody: MultibodyIndex,
    dofs: Vec<Dof>,
    /// Joint positions (rad or m) and velocities (rad/s or m/s), chain order: the state.
    q: Vec<f32>,
    qdot: Vec<f32>,
    /// Workspace: one value per generalized coordinate.
    disp: Vec<f32>,
    /// The state before the step being taken (to redo it on a fresh world).
    q_before: Vec<f32>,
    qdot_before: Vec<f32>,
    exact_resume: bool,
    /// Build a new world for every step (what exact resume is equivalent to; for tests).
    rebuild_every_step: bool,
    /// Step with the far-pair filter (always, but in a test of what it changes).
    filter_far_pairs: bool,
    /// The world needs the state written into it before the next step.
    dirty: bool,
    /// The world was built afresh and has not stepped since.
    fresh: bool,
    contact: bool,
    /// The floor is one of the static colliders.
    floor: bool,
    /// The static colliders changed since the world was built ([`DynamicArm::set_obstacles`]).
    stale: bool,
}

impl Clone for DynamicArm {
    /// The same arm in the same state, on a world built afresh (which the next step starts
    /// from: the same bits as the original's next step, see the module docs).
    fn clone(&self) -> DynamicArm {
        DynamicArm {
            template: self.template.clone(),
            snapshot: self.snapshot.clone(),
            world: self.snapshot.world(self.template.params),
            far_pairs: self.far_pairs.clone(),
            multibody: self.snapshot.multibody,
            dofs: self.dofs.clone(),
            q: self.q.clone(),
            qdot: self.qdot.clone(),
            disp: self.disp.clone(),
            q_before: self.q_before.clone(),
            qdot_before: self.qdot_before.clone(),
            exact_resume: self.exact_resume,
            rebuild_every_step: self.rebuild_every_step,
            filter_far_pairs: self.filter_far_pairs,
            dirty: true,
            fresh: false,
            contact: self.contact,
            floor: self.floor,
            stale: self.stale,
        }
    }
}

impl std::fmt::Debug for DynamicArm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DynamicArm")
            .field("q", &self.q)
            .field("qdot", &self.qdot)
            .field("contact", &self.contact)
            .field("floor", &self.floor)
            .field("static_colliders", &self.template.statics.len())
            .finish_non_exhaustive()
    }
}

impl DynamicArm {
    /// Build from the URDF text and the [`Chain`] compiled from that same text: the chain's
    /// actuated joints map, by name, to the multibody's joints. `dt_s` (s, finite, > 0) is the
    /// control period, one physics step per control step. `obstacles` become static colliders
    /// (validated as `obstacles[i]`); `floor` adds the half-space z <= 0 of the base frame (the
    /// root link is fixed, so resting on it does not push the arm). The arm starts at zero joint
    /// positions and velocities ([`DynamicArm::set_state`] to change them).
    ///
    /// Errors: [`Error::Urdf`] for a document that does not compile to `chain`'s joints (see
    /// [`Chain::from_urdf_str`]), a link moved by an actuated joint of the chain without
    /// `<inertial>` (or with zero mass), a link on the chain with a non-finite or negative mass
    /// or inertia; [`Error::Config`] for a bad `dt_s` or obstacle.
    pub fn new(
        urdf_xml: &str,
        chain: &Chain,
        dt_s: f64,
        obstacles: &[Obstacle],
        floor: bool,
    ) -> Result<DynamicArm> {
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 10.0) {
            return Err(Error::config("dt_s", dt_s, "a control period in (0, 10] seconds"));
        }
        for (i, o) in obstacles.iter().enumerate() {
            o.validate(&format!("obstacles[{i}]"))?;
        }
        // The same chain from this text (also bounds the document's size and nesting).
        let again = Chain::from_urdf_str(urdf_xml, Some(chain.tip_link()))?;
        if again.joints() != chain.joints() || again.base_link() != chain.base_link() {
            return Err(Error::Urdf(format!(
                "the URDF text does not give the chain `{}` -> `{}` it was passed with (joints {:?})",
                chain.base_link(),
                chain.tip_link(),
                chain.joints().iter().map(|j| j.name.as_str()).collect::<Vec<_>>()
            )));
        }
        let options = UrdfLoaderOptions {
            make_roots_fixed: true,
            // A sleeping arm would not wake up for a new motor command.
            rigid_body_blueprint: RigidBodyBuilder::dynamic().can_sleep(false),
            // The loader's default (massless colliders: the URDF's `<inertial>` gives the mass),
            // with the far-pair filter (see `FarPairs`).
            collider_blueprint: ColliderBuilder::default()
                .density(0.0)
                .active_hooks(ActiveHooks::FILTER_CONTACT_PAIRS),
            ..UrdfLoaderOptions::default()
        };
        let (mut robot, urdf) = UrdfRobot::from_str(urdf_xml, options, Path::new("."))
            .map_err(|e| Error::Urdf(format!("the rapier URDF loader failed: {e}")))?;
        check_inertials(&urdf, chain)?;
        let joint_ids = loader_joints(&robot, &urdf, chain)?;
        for (k, &ji) in joint_ids.iter().enumerate() {
            let info = &chain.joints()[k];
            let axis = axis_of(info.kind);
            let effort = info.effort.min(f32::MAX as f64) as f32;
            let joint = &mut robot.joints[ji].joint;
            joint.set_motor_velocity(axis, 0.0, MOTOR_DAMPING).set_motor_max_force(axis, effort);
        }
        let template = Template { robot, statics: static_colliders(obstacles, floor), params: params(dt_s) };
        let (world, multibody, bodies) = template.build();
        let dofs = dof_map(&world, multibody, &bodies, &template.robot, &joint_ids)?;
        let n = chain.dof();
        let ndofs = world.multibody_joints.get_multibody(multibody).map_or(0, |m| m.ndofs());
        Ok(DynamicArm {
            snapshot: Snapshot::of(&world, multibody),
            far_pairs: FarPairs::of(&world.colliders),
            template,
            world,
            multibody,
            dofs,
            q: vec![0.0; n],
            qdot: vec![0.0; n],
            disp: vec![0.0; ndofs],
            q_before: vec![0.0; n],
            qdot_before: vec![0.0; n],
            exact_resume: true,
            rebuild_every_step: false,
            filter_far_pairs: true,
            dirty: true,
            fresh: false,
            contact: false,
            floor,
            stale: false,
        })
    }

    /// Replace the obstacles (validated ones, see [`Obstacle::validate`]): the next step starts
    /// on a world built afresh with them (and the floor if the arm was built with it).
    pub fn set_obstacles(&mut self, obstacles: &[Obstacle]) {
        self.template.statics = static_colliders(obstacles, self.floor);
        // Built once, by the next step (which writes the state in anyway).
        self.stale = true;
        self.dirty = true;
    }

    /// Number of actuated joints (the chain's).
    pub fn dof(&self) -> usize {
        self.dofs.len()
    }

    /// Whether steps are a function of `q`, `qdot` and the command alone (default `true`): a step
    /// with an active contact is then taken again on a freshly built world (see the module
    /// docs), so that [`DynamicArm::set_state`] with a stored state continues a run bit for bit.
    /// `false` keeps rapier's world between steps (contact warm-starting and pair order carry
    /// over): cheaper in contact, still deterministic for the same sequence of calls, but a
    /// restored state no longer reproduces the run's bits once there is contact.
    pub fn set_exact_resume(&mut self, exact: bool) {
        self.exact_resume = exact;
        self.dirty = true;
    }

    /// Put the arm at joint positions `q` (rad or m) with joint velocities `qdot` (rad/s or m/s),
    /// chain order, and clear any solver state from earlier steps. Values are stored as f32 (the
    /// simulation's precision): [`DynamicArm::joint_positions`] after it returns them rounded.
    /// Errors ([`Error::InvalidInput`]): a wrong length or a non-finite value.
    pub fn set_state(&mut self, q: &[f64], qdot: &[f64]) -> Result<()> {
        for (what, v) in [("q", q), ("qdot", qdot)] {
            if v.len() != self.dof() {
                return Err(Error::InvalidInput(format!(
                    "{what} has {} values; the arm has {} joints",
                    v.len(),
                    self.dof()
                )));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite() || x.abs() > f32::MAX as f64) {
                return Err(Error::InvalidInput(format!("{what}[{i}] = {} is not a finite f32", v[i])));
            }
        }
        for k in 0..self.dof() {
            self.q[k] = q[k] as f32;
            self.qdot[k] = qdot[k] as f32;
        }
        self.contact = false;
        self.dirty = true;
        Ok(())
    }

    /// Hold each joint's velocity command `vel_cmd` (rad/s or m/s, chain order; a non-finite
    /// value reads as 0) for one control period through its velocity motor, capped at the
    /// joint's effort limit, under gravity. `vel_cmd.len()` must be [`DynamicArm::dof`] (checked
    /// in debug builds; extra values are ignored, missing ones read as 0).
    pub fn step(&mut self, vel_cmd: &[f64]) {
        debug_assert_eq!(vel_cmd.len(), self.dof(), "step: vel_cmd.len() must equal dof");
        let exact = self.exact_resume || self.rebuild_every_step;
        // In exact mode a world with contacts is not reused: the step would likely be redone.
        if self.dirty || self.rebuild_every_step || (exact && self.contact && !self.fresh) {
            if exact || self.stale {
                self.rebuild();
            }
            self.write_state();
            self.dirty = false;
        }
        if !exact || self.fresh {
            self.fresh = false;
            return self.step_world(vel_cmd);
        }
        self.q_before.copy_from_slice(&self.q);
        self.qdot_before.copy_from_slice(&self.qdot);
        self.step_world(vel_cmd);
        if self.contact {
            // Contacts make the step depend on the world's history (pair order, warm starts):
            // redo it on a world built afresh at the state it started from.
            self.q.copy_from_slice(&self.q_before);
            self.qdot.copy_from_slice(&self.qdot_before);
            self.rebuild();
            self.write_state();
            self.fresh = false;
            self.step_world(vel_cmd);
        }
    }

    /// One physics step of the world as it is, motors set to `vel_cmd`.
    fn step_world(&mut self, vel_cmd: &[f64]) {
        let mb = self.world.multibody_joints.get_multibody_mut(self.multibody).expect("the arm's multibody");
        for (k, d) in self.dofs.iter().enumerate() {
            let v = vel_cmd.get(k).copied().filter(|v| v.is_finite()).unwrap_or(0.0) as f32;
            let link = mb.link_mut(d.link).expect("the joint's link");
            link.joint.data.set_motor_velocity(d.axis, v, MOTOR_DAMPING);
        }
        let hooks: &dyn PhysicsHooks = if self.filter_far_pairs { &self.far_pairs } else { &() };
        self.world.step_with_events(hooks, &());
        self.read_state();
        self.contact = self.world.narrow_phase.contact_pairs().any(|p| p.has_any_active_contact());
    }

    /// Replace the world by a new one: a copy of the snapshot, or (new obstacles, or the
    /// `rebuild_every_step` reference) built from the template. The state is written separately.
    fn rebuild(&mut self) {
        if self.stale || self.rebuild_every_step {
            let (world, multibody, _) = self.template.build();
            if self.stale {
                self.snapshot = Snapshot::of(&world, multibody);
            }
            self.far_pairs = FarPairs::of(&world.colliders);
            self.world = world;
            self.multibody = multibody;
        } else {
            self.world = self.snapshot.world(self.template.params);
            self.multibody = self.snapshot.multibody;
        }
        self.fresh = true;
        self.stale = false;
    }

    /// The joint positions after the last step (or as set), rad or m, chain order, into `out`
    /// (`out.len()` must be [`DynamicArm::dof`]).
    pub fn joint_positions(&self, out: &mut [f64]) {
        for (o, &v) in out.iter_mut().zip(&self.q) {
            *o = v as f64;
        }
    }

    /// The joint velocities after the last step (or as set), rad/s or m/s, chain order, into `out`
    /// (`out.len()` must be [`DynamicArm::dof`]).
    pub fn joint_velocities(&self, out: &mut [f64]) {
        for (o, &v) in out.iter_mut().zip(&self.qdot) {
            *o = v as f64;
        }
    }

    /// Whether the last step ended with an active contact (the arm with the floor, an obstacle or
    /// itself), for diagnostics.
    pub fn in_contact(&self) -> bool {
        self.contact
    }

    /// Write `q`, `qdot` into the multibody exactly (coordinates zeroed, then set) and place the
    /// bodies accordingly.
    fn write_state(&mut self) {
        let w = &mut self.world;
        let mb = w.multibody_joints.get_multibody_mut(self.multibody).expect("the arm's multibody");
        self.disp.fill(0.0);
        for d in &self.dofs {
            self.disp[d.index] = -coord(mb, d);
        }
        mb.apply_displacements(&self.disp);
        for (k, d) in self.dofs.iter().enumerate() {
            self.disp[d.index] = self.q[k];
        }
        mb.apply_displacements(&self.disp);
        let mut v = mb.generalized_velocity_mut();
        v.fill(0.0);
        for (k, d) in self.dofs.iter().enumerate() {
            v[d.index] = self.qdot[k];
        }
        mb.forward_kinematics(&w.bodies, false);
        mb.update_rigid_bodies(&mut w.bodies, true);
    }

    /// Read `q`, `qdot` back from the multibody.
    fn read_state(&mut self) {
        let mb = self.world.multibody_joints.get_multibody(self.multibody).expect("the arm's multibody");
        let v = mb.generalized_velocity();
        for (k, d) in self.dofs.iter().enumerate() {
            self.q[k] = coord(mb, d);
            self.qdot[k] = v[d.index];
        }
    }
}

/// Pairs farther apart than this (m, between bounding shapes) are not handed to rapier's narrow
/// phase: ten times its prediction distance (0.002 m), beyond which it makes no contact.
const FAR_M: f64 = 0.02;

/// A collider's bounding shape in its own frame.
#[derive(Clone, Copy, Debug)]
enum Bound {
    /// The points within `radius` (m) of the segment `a`-`b`: exact for a capsule, the smallest
    /// capsule around a cylinder (parry's lie along y), a sphere around a box.
    Capsule { a: Vector, b: Vector, radius: f32 },
    /// The half-space `normal . p <= 0`.
    HalfSpace { normal: Vector },
}

/// A bounding shape placed in the world (f64, m).
#[derive(Clone, Copy, Debug)]
enum Placed {
    Capsule { a: [f64; 3], b: [f64; 3], radius: f64 },
    HalfSpace { normal: [f64; 3], offset: f64 },
}

/// Rapier's contact-pair filter (a [`PhysicsHooks`]): a pair of colliders whose bounding shapes
/// are more than [`FAR_M`] apart cannot make a contact within the narrow phase's prediction
/// distance, so the narrow phase, whose general convex test (GJK on the arm's cylinders) was
/// the largest part of a step after the solver, skips it. The bounds contain the shapes, so a
/// pair that could touch is never dropped; a dropped pair would have given no contact, and the
/// solver sees the same constraints (the step's bits are unchanged: tested). Colliders of other
/// shapes are never filtered.
#[derive(Clone, Debug, Default)]
struct FarPairs {
    /// By collider handle index.
    bounds: Vec<Option<Bound>>,
}

impl FarPairs {
    fn of(colliders: &ColliderSet) -> FarPairs {
        let mut bounds = Vec::new();
        for (h, co) in colliders.iter() {
            let i = h.into_raw_parts().0 as usize;
            if bounds.len() <= i {
                bounds.resize(i + 1, None);
            }
            let shape = co.shape();
            bounds[i] = if let Some(c) = shape.as_cylinder() {
                let h = Vector::new(0.0, c.half_height, 0.0);
                Some(Bound::Capsule { a: -h, b: h, radius: c.radius })
            } else if let Some(c) = shape.as_capsule() {
                Some(Bound::Capsule { a: c.segment.a, b: c.segment.b, radius: c.radius })
            } else if let Some(b) = shape.as_ball() {
                Some(Bound::Capsule { a: Vector::ZERO, b: Vector::ZERO, radius: b.radius })
            } else if let Some(b) = shape.as_cuboid() {
                Some(Bound::Capsule { a: Vector::ZERO, b: Vector::ZERO, radius: b.half_extents.length() })
            } else {
                shape.as_halfspace().map(|hs| Bound::HalfSpace { normal: hs.normal })
            };
        }
        FarPairs { bounds }
    }

    /// The bounding shape of collider `h` where it is now.
    fn placed(&self, colliders: &ColliderSet, h: ColliderHandle) -> Option<Placed> {
        let bound = (*self.bounds.get(h.into_raw_parts().0 as usize)?)?;
        let pose = colliders.get(h)?.position();
        let f = |v: Vector| [v.x as f64, v.y as f64, v.z as f64];
        Some(match bound {
            Bound::Capsule { a, b, radius } => Placed::Capsule {
                a: f(pose.transform_point(a)),
                b: f(pose.transform_point(b)),
                radius: radius as f64,
            },
            Bound::HalfSpace { normal } => {
                let n = f(pose.rotation * normal);
                let t = f(pose.translation);
                Placed::HalfSpace { normal: n, offset: n[0] * t[0] + n[1] * t[1] + n[2] * t[2] }
            }
        })
    }
}

/// The gap (m) between two placed bounds, or `None` if it is not computed (two half-spaces).
fn gap_m(x: Placed, y: Placed) -> Option<f64> {
    let below = |normal: [f64; 3], offset: f64, a: [f64; 3], b: [f64; 3], r: f64| {
        let h = |p: [f64; 3]| normal[0] * p[0] + normal[1] * p[1] + normal[2] * p[2] - offset;
        h(a).min(h(b)) - r
    };
    match (x, y) {
        (Placed::Capsule { a, b, radius }, Placed::Capsule { a: c, b: d, radius: s }) => {
            Some(crate::sim::collision::segment_segment_distance2(a, b, c, d).sqrt() - radius - s)
        }
        (Placed::Capsule { a, b, radius }, Placed::HalfSpace { normal, offset })
        | (Placed::HalfSpace { normal, offset }, Placed::Capsule { a, b, radius }) => {
            Some(below(normal, offset, a, b, radius))
        }
        (Placed::HalfSpace { .. }, Placed::HalfSpace { .. }) => None,
    }
}

impl PhysicsHooks for FarPairs {
    fn filter_contact_pair(&self, context: &PairFilterContext) -> Option<SolverFlags> {
        let placed = |h| self.placed(context.colliders, h);
        let gap = match (placed(context.collider1), placed(context.collider2)) {
            (Some(x), Some(y)) => gap_m(x, y),
            _ => None,
        };
        // Dropped only when surely far (a NaN gap keeps the pair); kept with what rapier uses
        // without a filter.
        let far = gap.is_some_and(|g| g > FAR_M);
        (!far).then(SolverFlags::default)
    }
}

/// A joint's generalized coordinate (rad or m).
fn coord(mb: &Multibody, d: &Dof) -> f32 {
    mb.link(d.link).map_or(0.0, |l| l.joint().coords()[d.axis as usize])
}

fn axis_of(kind: JointKind) -> JointAxis {
    match kind {
        JointKind::Revolute => JointAxis::AngX,
        JointKind::Prismatic => JointAxis::LinX,
    }
}

/// The integration parameters: one step of `dt_s`, the solver settings above, no sleeping
/// (bodies are made unable to sleep), no contact warm-starting from the previous step, no
/// continuous collision detection.
fn params(dt_s: f64) -> IntegrationParameters {
    IntegrationParameters {
        dt: dt_s as f32,
        num_solver_iterations: SOLVER_ITERATIONS,
        num_internal_pgs_iterations: INTERNAL_PGS_ITERATIONS,
        // A pair that barely moved keeps its contact points otherwise: history.
        contact_recycling: false,
        // Rapier's automatic CCD sweeps every fast body against the fixed colliders (the
        // floor: every moving link, most steps) and clamps the poses of the bodies it stops;
        // a multibody's links are placed from its joint coordinates, which the clamp leaves
        // alone, so it only cost time (about a sixth of a step) and could only leak a clamped
        // pose into the next step's contacts. Contacts come from the narrow phase, with its
        // prediction distance, as before.
        max_ccd_substeps: 0,
        ..IntegrationParameters::default()
    }
}

/// The floor (if asked) and the obstacles as parentless (static) colliders.
fn static_colliders(obstacles: &[Obstacle], floor: bool) -> Vec<Collider> {
    let mut out = Vec::new();
    if floor {
        out.push(
            ColliderBuilder::halfspace(nalgebra::Unit::new_unchecked(Vector::Z))
                .active_hooks(ActiveHooks::FILTER_CONTACT_PAIRS)
                .build(),
        );
    }
    for o in obstacles {
        let p = o.position_m;
        let [x, y, z, w] = o.rotation_xyzw.unwrap_or([0.0, 0.0, 0.0, 1.0]);
        let rot = Rotation::from_xyzw(x as f32, y as f32, z as f32, w as f32).normalize();
        let pose = Pose::from_parts(Vector::new(p[0] as f32, p[1] as f32, p[2] as f32), rot);
        let builder = match o.shape {
            ObstacleShape::Cuboid => {
                let h = o.half_extents_m.unwrap_or([0.0; 3]);
                ColliderBuilder::cuboid(h[0] as f32, h[1] as f32, h[2] as f32)
            }
            ObstacleShape::Sphere => ColliderBuilder::ball(o.radius_m.unwrap_or(0.0) as f32),
        };
        out.push(builder.position(pose).active_hooks(ActiveHooks::FILTER_CONTACT_PAIRS).build());
    }
    out
}

/// An error for a link moved by an actuated chain joint without a positive mass, or a link on
/// the chain with non-finite or negative inertial values.
fn check_inertials(urdf: &urdf_rs::Robot, chain: &Chain) -> Result<()> {
    for j in urdf.joints.iter().filter(|j| chain.joints().iter().any(|c| c.name == j.name)) {
        let name = &j.child.link;
        let Some(link) = urdf.links.iter().find(|l| &l.name == name) else { continue };
        let i = &link.inertial;
        let m = i.mass.value;
        let tensor =
            [i.inertia.ixx, i.inertia.iyy, i.inertia.izz, i.inertia.ixy, i.inertia.ixz, i.inertia.iyz];
        if m == 0.0 && tensor.iter().all(|&v| v == 0.0) {
            return Err(Error::Urdf(format!(
                "link `{name}` (moved by joint `{}`) has no <inertial>; the dynamic simulation \
                 needs its mass and inertia",
                j.name
            )));
        }
        let finite =
            tensor.iter().chain(i.origin.xyz.0.iter()).chain(i.origin.rpy.0.iter()).all(|v| v.is_finite());
        if !(m.is_finite() && m > 0.0 && finite && tensor[..3].iter().all(|&v| v >= 0.0)) {
            return Err(Error::Urdf(format!(
                "link `{name}` has <mass value=\"{m}\"> and inertia {tensor:?}; the dynamic \
                 simulation needs a finite mass > 0 and a finite inertia with ixx, iyy, izz >= 0"
            )));
        }
    }
    Ok(())
}

/// For each chain joint, the index of the loader's joint that carries it.
fn loader_joints(robot: &UrdfRobot, urdf: &urdf_rs::Robot, chain: &Chain) -> Result<Vec<usize>> {
    chain
        .joints()
        .iter()
        .map(|c| {
            robot
                .joints
                .iter()
                .position(|j| urdf.joints[j.source_urdf_joint_index()].name == c.name)
                .ok_or_else(|| {
                    Error::Urdf(format!(
                        "joint `{}` of the chain is not a joint of the loaded multibody",
                        c.name
                    ))
                })
        })
        .collect()
}

/// Where each chain joint sits in the built multibody.
fn dof_map(
    world: &PhysicsWorld,
    multibody: MultibodyIndex,
    handles: &[RigidBodyHandle],
    robot: &UrdfRobot,
    joint_ids: &[usize],
) -> Result<Vec<Dof>> {
    let mb = world.multibody_joints.get_multibody(multibody).expect("the arm's multibody");
    joint_ids
        .iter()
        .map(|&ji| {
            let lj = &robot.joints[ji];
            let link = handles
                .get(lj.link2)
                .and_then(|&h| world.multibody_joints.rigid_body_link(h))
                .filter(|l| l.multibody == multibody)
                .ok_or_else(|| Error::Urdf("a joint of the chain is outside the arm's multibody".into()))?;
            let ml = mb.link(link.id).expect("the link exists");
            let axis = if lj.joint.locked_axes.contains(JointAxesMask::LIN_X) {
                JointAxis::AngX
            } else {
                JointAxis::LinX
            };
            Ok(Dof { link: link.id, index: ml.assembly_id(), axis })
        })
        .collect()
}

#[cfg(test)]
impl DynamicArm {
    /// The world frame of chain joint `k`'s moving link (its origin, metres, and the joint's
    /// axis, base frame), with the state written in.
    fn link_frame(&mut self, k: usize, axis: [f32; 3]) -> ([f64; 3], [f64; 3]) {
        if self.dirty {
            if self.stale {
                self.rebuild();
            }
            self.write_state();
            self.dirty = false;
        }
        let mb = self.world.multibody_joints.get_multibody(self.multibody).unwrap();
        let pose = mb.link(self.dofs[k].link).unwrap().local_to_world();
        let t = pose.translation;
        let a = pose.rotation * Vector::new(axis[0], axis[1], axis[2]);
        ([t.x as f64, t.y as f64, t.z as f64], [a.x as f64, a.y as f64, a.z as f64])
    }

    /// The deepest penetration among the last step's active contacts, metres (0 if none).
    fn penetration_m(&self) -> f64 {
        let mut deepest = 0.0f32;
        for p in self.world.narrow_phase.contact_pairs() {
            for m in p.manifolds() {
                for c in &m.points {
                    deepest = deepest.max(-c.dist);
                }
            }
        }
        deepest as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{PANDA_URDF, UR5_URDF};
    use crate::sim::collision::{ArmCollider, Checks};
    use std::f64::consts::{FRAC_PI_2, PI};

    const DT: f64 = 0.05;
    const HOME: [f64; 6] = [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0];

    fn ur5(obstacles: &[Obstacle], floor: bool) -> DynamicArm {
        DynamicArm::new(UR5_URDF, &Chain::ur5(), DT, obstacles, floor).unwrap()
    }

    /// `steps` steps of `cmd` from `q0` at rest: the joint positions after each.
    fn run(arm: &mut DynamicArm, q0: &[f64], cmd: &[f64], steps: usize) -> Vec<Vec<f64>> {
        arm.set_state(q0, &vec![0.0; q0.len()]).unwrap();
        (0..steps)
            .map(|_| {
                arm.step(cmd);
                let mut q = vec![0.0; q0.len()];
                arm.joint_positions(&mut q);
                q
            })
            .collect()
    }

    /// The largest |q - q0| over a trajectory, rad.
    fn drift(traj: &[Vec<f64>], q0: &[f64]) -> f64 {
        traj.iter().flat_map(|q| q.iter().zip(q0).map(|(a, b)| (a - b).abs())).fold(0.0, f64::max)
    }

    #[test]
    fn joint_values_follow_the_chain_convention() {
        let chain = Chain::ur5();
        let mut arm = ur5(&[], false);
        let q = [0.3, -1.1, 1.4, -0.7, 2.0, -0.5];
        arm.set_state(&q, &[0.0; 6]).unwrap();
        let mut frames = vec![[0.0; 12]; 6];
        chain.segment_frames(&q, &mut frames);
        for (k, f) in frames.iter().enumerate() {
            // UR5 joint axes are their link's z.
            let (p, a) = arm.link_frame(k, [0.0, 0.0, 1.0]);
            for r in 0..3 {
                assert!((p[r] - f[4 * r + 3]).abs() < 1e-5, "joint {k} origin {p:?} vs {f:?}");
                assert!((a[r] - f[4 * r + 2]).abs() < 1e-5, "joint {k} axis {a:?} vs {f:?}");
            }
        }
        // State in, state out (as f32).
        let mut out = [0.0; 6];
        arm.joint_positions(&mut out);
        for k in 0..6 {
            assert_eq!(out[k], q[k] as f32 as f64);
        }
    }

    #[test]
    fn zero_command_holds_the_ur5_home_pose() {
        let mut arm = ur5(&[], true);
        let traj = run(&mut arm, &HOME, &[0.0; 6], 100);
        let d = drift(&traj, &HOME);
        eprintln!("UR5 hold drift over 5 s: {d:.5} rad");
        assert!(d <= 0.02, "drift {d} rad");
        assert!(!arm.in_contact());
    }

    #[test]
    fn zero_command_holds_the_panda() {
        let chain = Chain::load("panda", None).unwrap();
        let mut arm = DynamicArm::new(PANDA_URDF, &chain, DT, &[], true).unwrap();
        let q0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
        let traj = run(&mut arm, &q0, &[0.0; 7], 100);
        let d = drift(&traj, &q0);
        eprintln!("Panda hold drift over 5 s: {d:.5} rad");
        assert!(d <= 0.02, "drift {d} rad");
    }

    /// Mean achieved velocity of joint `j` over steps 2..=20, rad/s.
    fn tracked(arm: &mut DynamicArm, q0: &[f64], j: usize, v: f64) -> f64 {
        let mut cmd = vec![0.0; q0.len()];
        cmd[j] = v;
        let traj = run(arm, q0, &cmd, 20);
        (traj[19][j] - traj[0][j]) / (19.0 * DT)
    }

    #[test]
    fn one_rad_per_second_is_tracked() {
        let mut arm = ur5(&[], true);
        for (j, v) in [(0, 1.0), (2, 1.0), (2, -1.0), (4, 1.0)] {
            let got = tracked(&mut arm, &HOME, j, v);
            eprintln!("joint {j} at {v} rad/s: {got:.5} rad/s ({:.3} %)", 100.0 * (got - v).abs() / v.abs());
            assert!((got - v).abs() <= 0.05 * v.abs(), "joint {j}: {got} rad/s for {v}");
        }
    }

    /// The UR5 with its arm stretched out horizontally (upper arm, forearm and wrist along -x),
    /// lifting it: shoulder_lift towards -pi/2 at its speed limit. Returns the achieved velocity
    /// after the first step and the mean over steps 2..=20.
    fn lift(urdf: &str) -> (f64, f64) {
        let chain = Chain::from_urdf_str(urdf, Some("tool0")).unwrap();
        let mut arm = DynamicArm::new(urdf, &chain, DT, &[], true).unwrap();
        let q0 = [0.0, 0.0, 0.0, -FRAC_PI_2, 0.0, 0.0];
        let cmd = [0.0, -PI, 0.0, 0.0, 0.0, 0.0];
        let traj = run(&mut arm, &q0, &cmd, 20);
        ((traj[0][1] - q0[1]) / DT, (traj[19][1] - traj[0][1]) / (19.0 * DT))
    }

    #[test]
    fn shoulder_torque_saturates_lifting_the_arm() {
        let (first, mean) = lift(UR5_URDF);
        // The same arm with unlimited shoulder torque.
        let strong = UR5_URDF.replacen(r#"effort="150""#, r#"effort="0""#, 2);
        let (first_strong, mean_strong) = lift(&strong);
        eprintln!(
            "shoulder lift at -pi rad/s: first step {first:.4}, mean 2..20 {mean:.4} rad/s; \
             unlimited torque: {first_strong:.4}, {mean_strong:.4}"
        );
        assert!((first_strong + PI).abs() < 0.05 * PI, "{first_strong}");
        // 150 N m against about 54 N m of gravity and 3 kg m^2: well short in the first step.
        assert!(first > -0.8 * PI, "first step {first} rad/s");
    }

    #[test]
    fn position_limits_hold() {
        // The Panda's joint 4 lives in [-3.0718, -0.0698] rad: driven up into its upper limit.
        let chain = Chain::load("panda", None).unwrap();
        let mut arm = DynamicArm::new(PANDA_URDF, &chain, DT, &[], true).unwrap();
        let q0 = [0.0, -0.785, 0.0, -0.5, 0.0, 1.571, 0.785];
        let traj = run(&mut arm, &q0, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], 30);
        let top = traj.iter().map(|q| q[3]).fold(f64::MIN, f64::max);
        eprintln!("Panda joint 4 at +1 rad/s into its limit -0.0698: at most {top:.5} rad");
        assert!(top <= -0.0698 + 0.005 && top > -0.0698 - 0.01, "{top}");
    }

    #[test]
    fn a_link_without_inertial_is_refused() {
        let start = UR5_URDF.find("<link name=\"forearm_link\">").unwrap();
        let a = start + UR5_URDF[start..].find("<inertial>").unwrap();
        let b = start + UR5_URDF[start..].find("</inertial>").unwrap() + "</inertial>".len();
        let xml = format!("{}{}", &UR5_URDF[..a], &UR5_URDF[b..]);
        let chain = Chain::from_urdf_str(&xml, Some("tool0")).unwrap();
        let e = DynamicArm::new(&xml, &chain, DT, &[], false).err().unwrap();
        assert!(matches!(e, Error::Urdf(_)), "{e}");
        assert!(e.to_string().contains("link `forearm_link`") && e.to_string().contains("<inertial>"), "{e}");
        // A negative mass too.
        let xml = UR5_URDF.replacen(r#"<mass value="2.33"/>"#, r#"<mass value="-2.33"/>"#, 1);
        let e = DynamicArm::new(&xml, &Chain::ur5(), DT, &[], false).err().unwrap();
        assert!(e.to_string().contains("link `forearm_link`"), "{e}");
        // And a chain from another document.
        let e = DynamicArm::new(PANDA_URDF, &Chain::ur5(), DT, &[], false).err().unwrap();
        assert!(matches!(e, Error::Urdf(_)), "{e}");
    }

    /// A box the UR5's wrist meets when the base turns from HOME by about `angle` rad.
    fn box_in_the_way(angle: f64) -> Obstacle {
        let p = Chain::ur5().fk(&HOME).position;
        let (s, c) = angle.sin_cos();
        Obstacle::cuboid([0.05, 0.05, 0.05], [c * p.x - s * p.y, s * p.x + c * p.y, p.z], None)
    }

    /// The commands of the contact trajectory: base towards the box, shoulder down to the floor.
    fn pushing(t: usize) -> [f64; 6] {
        if t < 30 {
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        } else {
            [1.0, 0.5, 0.6, 0.0, 0.5, 0.0]
        }
    }

    #[test]
    fn a_box_stops_the_arm() {
        let obstacle = box_in_the_way(0.8);
        let mut arm = ur5(std::slice::from_ref(&obstacle), true);
        let traj = run(&mut arm, &HOME, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], 40);
        assert!(arm.in_contact());
        let pen = arm.penetration_m();
        assert!(pen < 0.005, "{pen} m");
        // Where the kinematic check first finds the arm in the box, turning the base.
        let chain = Chain::ur5();
        let mut col = ArmCollider::new(&chain, Checks { floor: false, self_collision: false });
        col.set_obstacles(std::slice::from_ref(&obstacle));
        let mut q = HOME;
        while col.check(&chain, &q).is_none() {
            q[0] += 1e-4;
        }
        let last = traj[39][0];
        eprintln!(
            "base stopped at {last:.4} rad, penetration {pen:.5} m; capsules first touch the box at {:.4}",
            q[0]
        );
        // The capsules are a little larger than the cylinders: stopping near, not past, there.
        assert!(last < q[0] + 0.01 && last > q[0] - 0.1, "{last} vs {}", q[0]);
    }

    #[test]
    fn same_inputs_same_bits() {
        let obstacles = [box_in_the_way(0.8)];
        let mut a = ur5(&obstacles, true);
        let mut b = ur5(&obstacles, true);
        let ta: Vec<Vec<f64>> = (0..60).map(|t| run_one(&mut a, t)).collect();
        let tb: Vec<Vec<f64>> = (0..60).map(|t| run_one(&mut b, t)).collect();
        assert_eq!(bits(&ta), bits(&tb));
    }

    /// One step of the contact trajectory from HOME (set at t = 0): q then qdot.
    fn run_one(arm: &mut DynamicArm, t: usize) -> Vec<f64> {
        if t == 0 {
            arm.set_state(&HOME, &[0.0; 6]).unwrap();
        }
        arm.step(&pushing(t));
        state(arm)
    }

    /// A UR5's joint positions then velocities.
    fn state(arm: &DynamicArm) -> Vec<f64> {
        let mut out = vec![0.0; 12];
        arm.joint_positions(&mut out[..6]);
        arm.joint_velocities(&mut out[6..]);
        out
    }

    fn bits(t: &[Vec<f64>]) -> Vec<Vec<u64>> {
        t.iter().map(|v| v.iter().map(|x| x.to_bits()).collect()).collect()
    }

    /// Steps `from..to` of the contact trajectory on a new arm set to `state` (q then qdot).
    fn resumed(state: &[f64], from: usize, to: usize, obstacles: &[Obstacle]) -> Vec<Vec<f64>> {
        let mut arm = ur5(obstacles, true);
        arm.set_state(&state[..6], &state[6..]).unwrap();
        (from..to).map(|t| run_one(&mut arm, t.max(1))).collect()
    }

    #[test]
    fn set_state_then_step_continues_bit_for_bit() {
        let obstacles = [box_in_the_way(0.8)];
        let mut arm = ur5(&obstacles, true);
        let mut contacts = 0;
        let full: Vec<Vec<f64>> = (0..80)
            .map(|t| {
                let s = run_one(&mut arm, t);
                contacts += arm.in_contact() as usize;
                s
            })
            .collect();
        eprintln!("{contacts} of 80 steps in contact");
        assert!(contacts >= 20, "the trajectory should press into the box and the floor");
        for k in [5, 31, 40, 55, 70] {
            let again = resumed(&full[k - 1], k, 80, &obstacles);
            assert_eq!(bits(&again), bits(&full[k..]), "resumed at step {k}");
        }
        // The same arm, its state set back to where it was: the same too.
        arm.set_state(&full[49][..6], &full[49][6..]).unwrap();
        let again: Vec<Vec<f64>> = (50..80).map(|t| run_one(&mut arm, t)).collect();
        assert_eq!(bits(&again), bits(&full[50..]));
    }

    /// The contact trajectory, then one that stays near HOME (q then qdot after each step).
    fn both_trajectories(arm: &mut DynamicArm) -> Vec<Vec<f64>> {
        let mut out: Vec<Vec<f64>> = (0..80).map(|t| run_one(arm, t)).collect();
        arm.set_state(&HOME, &[0.0; 6]).unwrap();
        for t in 0..200 {
            arm.step(&swaying(t, 6));
            out.push(state(arm));
        }
        out
    }

    #[test]
    fn exact_resume_equals_a_fresh_world_every_step() {
        let obstacles = four_boxes();
        let mut a = ur5(&obstacles, true);
        let mut b = ur5(&obstacles, true);
        b.rebuild_every_step = true;
        assert_eq!(bits(&both_trajectories(&mut a)), bits(&both_trajectories(&mut b)));
        // New obstacles: `a` copies its new snapshot from then on, `b` still builds every step.
        a.set_obstacles(&obstacles[1..]);
        b.set_obstacles(&obstacles[1..]);
        assert_eq!(bits(&both_trajectories(&mut a)), bits(&both_trajectories(&mut b)));
        // A clone starts from a copy of the snapshot: the same bits again.
        let mut c = a.clone();
        assert_eq!(bits(&both_trajectories(&mut c)), bits(&both_trajectories(&mut a)));
    }

    /// Positions and velocities of `steps` steps from the UR5's home pose under commands of
    /// 1.5 rad/s that press the arm into the floor and itself most of the time; the steps in
    /// contact.
    fn rough(arm: &mut DynamicArm, steps: usize) -> (Vec<Vec<f64>>, usize) {
        arm.set_state(&HOME, &[0.0; 6]).unwrap();
        let (mut out, mut contacts) = (Vec::new(), 0);
        for t in 0..steps {
            let cmd: Vec<f64> =
                (0..6).map(|j| 1.5 * ((t as f64) * 0.03 * (1.0 + j as f64 * 0.37)).sin()).collect();
            arm.step(&cmd);
            contacts += arm.in_contact() as usize;
            out.push(state(arm));
        }
        (out, contacts)
    }

    #[test]
    fn far_pair_filter_changes_no_bit() {
        let obstacles = four_boxes();
        let mut a = ur5(&obstacles, true);
        let mut b = ur5(&obstacles, true);
        b.filter_far_pairs = false;
        assert_eq!(bits(&both_trajectories(&mut a)), bits(&both_trajectories(&mut b)));
        let ((ta, ca), (tb, cb)) = (rough(&mut a, 600), rough(&mut b, 600));
        assert!(ca > 100, "the rough motion makes contact ({ca} steps)");
        assert_eq!((bits(&ta), ca), (bits(&tb), cb));
        // It is not idle: at the home pose it drops most pairs of the arm's 14 colliders, the
        // floor and the boxes (rapier hands it those whose boxes overlap).
        a.set_state(&HOME, &[0.0; 6]).unwrap();
        a.step(&[0.0; 6]);
        let w = &a.world;
        let handles: Vec<ColliderHandle> = w.colliders.iter().map(|(h, _)| h).collect();
        let (mut dropped, mut pairs) = (0, 0);
        for (i, &collider1) in handles.iter().enumerate() {
            for &collider2 in &handles[i + 1..] {
                let context = PairFilterContext {
                    bodies: &w.bodies,
                    colliders: &w.colliders,
                    collider1,
                    collider2,
                    rigid_body1: None,
                    rigid_body2: None,
                };
                pairs += 1;
                dropped += a.far_pairs.filter_contact_pair(&context).is_none() as usize;
            }
        }
        assert!(dropped * 10 > pairs * 8, "{dropped} of {pairs} pairs dropped");
        assert!(dropped < pairs);
    }

    #[test]
    fn gaps_between_bounds() {
        let cap = |a: [f64; 3], b: [f64; 3], radius: f64| Placed::Capsule { a, b, radius };
        let floor = Placed::HalfSpace { normal: [0.0, 0.0, 1.0], offset: 0.0 };
        // Parallel segments 1 m apart, radii 0.1 and 0.2.
        let g = gap_m(cap([0.0; 3], [1.0, 0.0, 0.0], 0.1), cap([0.0, 1.0, 0.0], [1.0, 1.0, 0.0], 0.2));
        assert!((g.unwrap() - 0.7).abs() < 1e-12);
        // A tilted capsule above the floor: its lower end, less the radius.
        let c = cap([0.0, 0.0, 0.5], [0.3, 0.0, 0.2], 0.05);
        assert!((gap_m(c, floor).unwrap() - 0.15).abs() < 1e-12);
        assert!((gap_m(floor, c).unwrap() - 0.15).abs() < 1e-12);
        // A floor raised to z = 0.3 (offset along its normal) is in the capsule: negative.
        let raised = Placed::HalfSpace { normal: [0.0, 0.0, 1.0], offset: 0.3 };
        assert!((gap_m(c, raised).unwrap() + 0.15).abs() < 1e-12);
        assert_eq!(gap_m(floor, raised), None);
    }

    /// A command swaying every joint around where it starts (at most 0.4 rad away), rad/s.
    fn swaying(t: usize, n: usize) -> Vec<f64> {
        (0..n)
            .map(|j| {
                let w = 2.0 + 0.7 * j as f64;
                0.4 * w * (w * t as f64 * DT).cos()
            })
            .collect()
    }

    /// Four boxes around the UR5 (one in the way of the `timing` motion).
    fn four_boxes() -> Vec<Obstacle> {
        vec![
            box_in_the_way(0.8),
            Obstacle::cuboid([0.1, 0.1, 0.2], [0.0, 0.6, 0.2], None),
            Obstacle::cuboid([0.2, 0.05, 0.1], [-0.5, -0.3, 0.1], Some([0.0, 0.0, 0.3826834, 0.9238795])),
            Obstacle::cuboid([0.05, 0.3, 0.05], [0.4, 0.0, 0.9], None),
        ]
    }

    /// Microseconds a step over `steps` steps: swaying around `q0`, or (`rough`) sweeping
    /// commands of 1.5 rad/s that press the arm into the floor and itself most of the time.
    fn time_steps(arm: &mut DynamicArm, q0: &[f64], steps: usize, rough: bool) -> (f64, usize) {
        let n = q0.len();
        arm.set_state(q0, &vec![0.0; n]).unwrap();
        let mut cmd = vec![0.0; n];
        let mut contacts = 0;
        let t0 = thread_cpu_s();
        for t in 0..steps {
            if rough {
                for (j, c) in cmd.iter_mut().enumerate() {
                    *c = 1.5 * ((t as f64) * 0.03 * (1.0 + j as f64 * 0.37)).sin();
                }
            } else {
                cmd = swaying(t, n);
            }
            arm.step(&cmd);
            contacts += arm.in_contact() as usize;
        }
        ((thread_cpu_s() - t0) * 1e6 / steps as f64, contacts)
    }

    /// This thread's CPU time, s (the machine is shared: wall time would count other processes).
    fn thread_cpu_s() -> f64 {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid timespec to write into.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
    }

    /// `cargo test --release -p stagerl --lib physics::tests::timing -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn timing() {
        let panda = Chain::load("panda", None).unwrap();
        let q_panda = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
        let steps = 4000;
        for (mode, exact, every) in
            [("exact", true, false), ("persistent", false, false), ("rebuild", true, true)]
        {
            for rough in [false, true] {
                for (name, obstacles) in [("UR5, floor", vec![]), ("UR5, floor + 4 boxes", four_boxes())] {
                    let mut arm = ur5(&obstacles, true);
                    arm.set_exact_resume(exact);
                    arm.rebuild_every_step = every;
                    time_steps(&mut arm, &HOME, 200, rough);
                    let (us, contacts) = time_steps(&mut arm, &HOME, steps, rough);
                    eprintln!(
                        "{mode}, rough {rough}: {name}: {us:.2} us/step ({contacts} of {steps} in contact)"
                    );
                }
                let mut arm = DynamicArm::new(PANDA_URDF, &panda, DT, &[], true).unwrap();
                arm.set_exact_resume(exact);
                arm.rebuild_every_step = every;
                time_steps(&mut arm, &q_panda, 200, rough);
                let (us, contacts) = time_steps(&mut arm, &q_panda, steps, rough);
                eprintln!(
                    "{mode}, rough {rough}: Panda, floor: {us:.2} us/step ({contacts} of {steps} in contact)"
                );
            }
        }
        let arm = ur5(&four_boxes(), true);
        let t0 = thread_cpu_s();
        for _ in 0..1000 {
            std::hint::black_box(arm.template.build());
        }
        eprintln!("building the world: {:.2} us (thread CPU time)", (thread_cpu_s() - t0) * 1e3);
    }
}
