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
//! Settings (those that held a UR5 still and tracked its commands, see `docs/design.md`):
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

use crate::robot::{Chain, JointKind, Shape};
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
        let blueprint = options.collider_blueprint.clone();
        let (mut robot, urdf) = UrdfRobot::from_str(urdf_xml, options, Path::new("."))
            .map_err(|e| Error::Urdf(format!("the rapier URDF loader failed: {e}")))?;
        add_mesh_colliders(&mut robot, &urdf, chain, &blueprint);
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
            } else if let Some(p) = shape.as_convex_polyhedron() {
                let s = p.local_bounding_sphere();
                Some(Bound::Capsule { a: s.center, b: s.center, radius: s.radius })
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

/// The chain's mesh parts (which the loader, built without its mesh features, leaves out) as
/// convex colliders of their links, made from `blueprint` as the loader makes the others.
fn add_mesh_colliders(
    robot: &mut UrdfRobot,
    urdf: &urdf_rs::Robot,
    chain: &Chain,
    blueprint: &ColliderBuilder,
) {
    for s in chain.collision_shapes() {
        let Shape::Convex(part) = &s.shape else { continue };
        let link = robot
            .links
            .iter_mut()
            .find(|l| urdf.links.get(l.urdf_link_index).is_some_and(|u| u.name == s.link));
        let Some(link) = link else { continue };
        let mut builder = blueprint.clone();
        builder.shape = SharedShape::new(part.hull().clone());
        let collider = builder.position(crate::sim::collision::pose3(&s.link_pose)).build();
        link.colliders.push(rapier3d_urdf::UrdfCollider { collider, visual: None });
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

/// The link masses the dynamic simulation takes, kg: from a milligram to ten tonnes.
pub const MIN_LINK_MASS_KG: f64 = 1e-6;
pub const MAX_LINK_MASS_KG: f64 = 1e4;
/// The largest magnitude of a link's inertia value, kg m^2.
pub const MAX_LINK_INERTIA_KG_M2: f64 = 1e4;
/// The farthest a link's centre of mass may lie from its frame, metres.
pub const MAX_INERTIAL_OFFSET_M: f64 = 100.0;

/// An error for a link moved by an actuated chain joint without a positive mass, or a link on
/// the chain with non-finite or negative inertial values or values outside physical ranges
/// (the link and the value named).
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
        // Physical ranges: a mass or an inertia far outside a robot arm's overflows the
        // simulation's f32 arithmetic (positions turn NaN a few steps in).
        if !(MIN_LINK_MASS_KG..=MAX_LINK_MASS_KG).contains(&m) {
            return Err(Error::Urdf(format!(
                "link `{name}` has <mass value=\"{m}\">; the dynamic simulation takes a link mass \
                 from {MIN_LINK_MASS_KG:e} to {MAX_LINK_MASS_KG:e} kg"
            )));
        }
        if let Some((k, v)) = tensor.iter().enumerate().find(|(_, v)| v.abs() > MAX_LINK_INERTIA_KG_M2) {
            let names = ["ixx", "iyy", "izz", "ixy", "ixz", "iyz"];
            return Err(Error::Urdf(format!(
                "link `{name}` has <inertia {}=\"{v}\">; the dynamic simulation takes inertia \
                 values of at most {MAX_LINK_INERTIA_KG_M2:e} kg m^2 in magnitude",
                names[k]
            )));
        }
        if let Some(v) = i.origin.xyz.0.iter().find(|v| v.abs() > MAX_INERTIAL_OFFSET_M) {
            return Err(Error::Urdf(format!(
                "link `{name}` has its <inertial> origin at {v} m from its frame; at most \
                 {MAX_INERTIAL_OFFSET_M} m is taken"
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
mod tests;
