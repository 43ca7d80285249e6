//! Serial kinematic chains: loaded from URDF, compiled into flat arrays, evaluated by hand.
//!
//! A URDF is compiled ([`Chain::from_urdf_str`]) into a serial chain from its root link to a tip
//! link: fixed joints are folded into constant transforms and every actuated joint is rotated so
//! that it moves about (or along) its local z axis. Forward kinematics ([`Chain::fk`]) and the
//! geometric Jacobian ([`Chain::jacobian`]) then run on flat arrays of constants without heap
//! allocation.
//!
//! Units: metres and radians (joint values, positions, limits), metres or radians per second
//! (velocity limits). Poses are expressed in the root (base) link's frame.

use nalgebra::{UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// Which arm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    /// `"ur5"` or `"panda"` for a bundled arm, or a path to a URDF file.
    pub urdf: String,
    /// Tip link of the chain; unset takes the URDF's only leaf link.
    pub tip: Option<String>,
    /// Folders holding ROS package folders: where `package://PKG/...` mesh paths are looked for
    /// first (then `ROS_PACKAGE_PATH`, then the URDF's folder and its parents). Mesh files are
    /// read only below these folders and the URDF's own.
    pub package_paths: Vec<PathBuf>,
    /// A link whose collision mesh cannot be found or read: `"error"` stops with a message
    /// naming the link and the file, `"ignore"` goes on without that geometry.
    pub missing_collision: MissingCollision,
}

impl Default for RobotConfig {
    fn default() -> Self {
        RobotConfig {
            urdf: "ur5".into(),
            tip: None,
            package_paths: Vec::new(),
            missing_collision: MissingCollision::Error,
        }
    }
}

impl RobotConfig {
    /// Load the configured arm (meshes as [`RobotConfig::mesh_options`] says).
    pub fn load(&self) -> Result<Chain> {
        Chain::load_with(&self.urdf, self.tip.as_deref(), &self.mesh_options())
    }

    /// Where meshes are looked for: `package_paths`, then `ROS_PACKAGE_PATH`'s folders.
    pub fn mesh_options(&self) -> MeshOptions {
        MeshOptions {
            package_paths: self.package_paths.clone(),
            ros_package_path: Vec::new(),
            missing: self.missing_collision,
        }
        .with_ros_package_path()
    }
}

mod kin;
pub mod mesh;
#[cfg(test)]
mod tests;
mod urdf;
pub use mesh::{ConvexPart, MeshOptions, MissingCollision};
pub use urdf::{MAX_LENGTH_M, MAX_URDF_BYTES, MAX_XML_DEPTH};

/// The bundled UR5 URDF (see `assets/robots/ur5.urdf`).
pub const UR5_URDF: &str = include_str!("../../../../assets/robots/ur5.urdf");

/// The bundled Franka Emika Panda URDF (see `assets/robots/panda.urdf`), tip `panda_link8`
/// (the flange).
pub const PANDA_URDF: &str = include_str!("../../../../assets/robots/panda.urdf");

/// `a * b` of row-major 3 x 4 transforms (rotation, translation in metres).
pub fn mul_tf(a: &[f64; 12], b: &[f64; 12]) -> [f64; 12] {
    kin::mul(a, b)
}

/// The z axis and translation of [`mul_tf`]`(a, b)` into columns 2 and 3 of `o` (the others
/// left as they are), to the bit.
pub(crate) fn mul_tf_z_and_origin(a: &[f64; 12], b: &[f64; 12], o: &mut [f64; 12]) {
    kin::mul_columns(a, b, 2, o)
}

/// An end-effector pose in the chain's base frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Position in metres.
    pub position: Vector3<f64>,
    /// Orientation, canonicalised so that `w >= 0`.
    pub orientation: UnitQuaternion<f64>,
}

impl Pose {
    /// The orientation as `[x, y, z, w]` with `w >= 0`.
    pub fn quaternion_xyzw(&self) -> [f64; 4] {
        let q = self.orientation.quaternion();
        [q.i, q.j, q.k, q.w]
    }
}

/// Kind of an actuated joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis (radians); URDF `revolute` and `continuous`.
    Revolute,
    /// Translation along the axis (metres).
    Prismatic,
}

/// One actuated joint and its limits.
#[derive(Clone, Debug, PartialEq)]
pub struct JointInfo {
    /// The URDF joint name.
    pub name: String,
    /// Rotation or translation.
    pub kind: JointKind,
    /// Lower position limit (rad or m); `-inf` for a continuous joint.
    pub lower: f64,
    /// Upper position limit (rad or m); `+inf` for a continuous joint.
    pub upper: f64,
    /// Speed limit (rad/s or m/s), positive.
    pub velocity: f64,
    /// Effort limit (N m for a revolute joint, N for a prismatic one), positive: the URDF's
    /// `<limit effort>`, or `f64::INFINITY` when the URDF gives none or 0 (unlimited). Only the
    /// dynamic simulation ([`crate::sim::physics`]) reads it.
    pub effort: f64,
}

/// A collision shape, in metres (the URDF's `<collision>` geometry; a cylinder is taken as
/// the capsule of its radius and length, a mesh as the convex hulls of its parts).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// The points within `radius_m` of the segment from `-half_length_m` to `+half_length_m`
    /// along the local z axis.
    Capsule {
        radius_m: f64,
        half_length_m: f64,
    },
    Sphere {
        radius_m: f64,
    },
    /// A box centred at the origin, half its size along each local axis.
    Cuboid {
        half_extents_m: [f64; 3],
    },
    /// One convex part of a collision mesh (see [`mesh`]).
    Convex(Arc<ConvexPart>),
}

impl Shape {
    /// Its kind in a word: `capsule`, `sphere`, `box`, `convex`.
    pub fn kind(&self) -> &'static str {
        match self {
            Shape::Capsule { .. } => "capsule",
            Shape::Sphere { .. } => "sphere",
            Shape::Cuboid { .. } => "box",
            Shape::Convex(_) => "convex",
        }
    }
}

/// A collision mesh the chain goes on without (`robot.missing_collision = "ignore"`, or a URDF
/// given as text).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnloadedMesh {
    pub link: String,
    /// The file as the URDF names it.
    pub file: String,
    /// Why it was not loaded.
    pub reason: String,
}

/// One collision shape of a link on the chain, placed in its segment's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkShape {
    /// The URDF link it belongs to.
    pub link: String,
    /// The frame it moves with: `None` for the root link (and links fixed to it), the base
    /// frame; `Some(i)` for actuated joint `i`'s frame after its motion ([`Chain::segment_frames`]).
    pub segment: Option<usize>,
    /// Its pose in that frame: a row-major 3 x 4 transform (rotation, translation in metres).
    pub pose: [f64; 12],
    /// Its pose in its link's frame (the `<collision>` element's origin), the same form.
    pub link_pose: [f64; 12],
    pub shape: Shape,
}

/// A serial chain from a root link to a tip link, compiled for fast kinematics.
#[derive(Clone, Debug)]
pub struct Chain {
    joints: Vec<JointInfo>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    velocity: Vec<f64>,
    base_link: String,
    tip_link: String,
    kin: kin::Kinematics,
    shapes: Vec<LinkShape>,
    unloaded: Vec<UnloadedMesh>,
    /// The URDF text it was compiled from (the dynamic simulation loads it again).
    urdf: std::sync::Arc<str>,
}

impl Chain {
    /// The bundled UR5 (root `base_link`, tip `tool0`, 6 revolute joints).
    pub fn ur5() -> Chain {
        Chain::from_urdf_str(UR5_URDF, Some("tool0")).expect("the bundled UR5 URDF compiles")
    }

    /// `"ur5"` or `"panda"` for a bundled arm, otherwise a path to a URDF file. `tip` as in
    /// [`Chain::from_urdf_str`]; meshes found through `ROS_PACKAGE_PATH` and the URDF's folder
    /// ([`Chain::load_with`] for more).
    pub fn load(robot: &str, tip: Option<&str>) -> Result<Chain> {
        Chain::load_with(robot, tip, &MeshOptions::default().with_ros_package_path())
    }

    /// [`Chain::load`] with collision meshes read as `meshes` says.
    pub fn load_with(robot: &str, tip: Option<&str>, meshes: &MeshOptions) -> Result<Chain> {
        if robot == "ur5" {
            Chain::from_urdf_str(UR5_URDF, tip)
        } else if robot == "panda" {
            Chain::from_urdf_str(PANDA_URDF, tip)
        } else {
            Chain::from_urdf_file_with(Path::new(robot), tip, meshes)
        }
    }

    /// Parse a URDF document. `tip`: the tip link; `None` takes the only leaf link.
    ///
    /// The chain runs from the single root link to the tip; joints off that path are ignored.
    /// Errors ([`Error::Urdf`], naming the joint or link at fault): a document that does not parse,
    /// an unknown tip, several leaves and no tip given, more than one root, a link with no path to
    /// the root, a joint naming a missing link, a floating/planar/spherical or mimic joint on the
    /// chain, a revolute or prismatic joint without usable limits (finite `lower < upper`,
    /// `velocity > 0`), a continuous joint without a positive velocity limit, a negative or NaN
    /// effort limit (0 or none reads as unlimited, [`JointInfo::effort`]), a non-finite origin
    /// or axis, an origin or prismatic limit beyond [`MAX_LENGTH_M`], a zero axis, a chain
    /// with no actuated joint, or joints forming a cycle anywhere in the document.
    ///
    /// A document has no folder to read meshes from: its collision meshes are not loaded
    /// ([`Chain::unloaded_collision`]); [`Chain::from_urdf_file`] reads them.
    pub fn from_urdf_str(xml: &str, tip: Option<&str>) -> Result<Chain> {
        Chain::compiled(xml, urdf::compile_str(xml, tip, None)?)
    }

    fn compiled(xml: &str, c: urdf::Compiled) -> Result<Chain> {
        Ok(Chain {
            lower: c.joints.iter().map(|j| j.lower).collect(),
            upper: c.joints.iter().map(|j| j.upper).collect(),
            velocity: c.joints.iter().map(|j| j.velocity).collect(),
            joints: c.joints,
            base_link: c.base_link,
            tip_link: c.tip_link,
            kin: c.kin,
            shapes: c.shapes,
            unloaded: c.unloaded,
            urdf: xml.into(),
        })
    }

    /// The URDF text the chain was compiled from.
    pub fn urdf_source(&self) -> &str {
        &self.urdf
    }

    /// The collision shapes of the links on the chain, root to tip (see [`LinkShape`]).
    pub fn collision_shapes(&self) -> &[LinkShape] {
        &self.shapes
    }

    /// The links on the chain with a collision mesh that was not loaded, once each, root to tip.
    pub fn mesh_collision_links(&self) -> Vec<String> {
        let mut links: Vec<String> = self.unloaded.iter().map(|u| u.link.clone()).collect();
        links.dedup();
        links
    }

    /// The collision meshes of the chain's links that were not loaded, and why.
    pub fn unloaded_collision(&self) -> &[UnloadedMesh] {
        &self.unloaded
    }

    /// The frame each actuated joint moves, after its motion, for joint values `q` (one per
    /// joint, unchecked): `out[i]` is joint `i`'s z-aligned frame in the base frame, a row-major
    /// 3 x 4 transform (metres). The frames [`LinkShape::segment`] refers to; a shorter `out`
    /// gets the first `out.len()`. No allocation.
    pub fn segment_frames(&self, q: &[f64], out: &mut [[f64; 12]]) {
        self.kin.segment_frames(q, out)
    }

    /// The tip's pose from the frames [`Chain::segment_frames`] gave for some joint values:
    /// [`Chain::fk`] of those values, bit for bit, without a second pass over the chain (the
    /// collision check's frames serve the task). `None` without all the frames.
    pub fn tip_pose_from_frames(&self, frames: &[[f64; 12]]) -> Option<Pose> {
        let last = frames.get(self.dof().checked_sub(1)?)?;
        self.kin.tip_from_last_frame(last).map(|m| kin::pose_of(&m))
    }

    /// Read and parse a URDF file (see [`Chain::from_urdf_str`]) and its collision meshes
    /// (found through `ROS_PACKAGE_PATH` and the URDF's folder; a mesh that cannot be read is an
    /// error); [`Error::Io`] if it cannot be read, URDF errors prefixed with the path.
    pub fn from_urdf_file(path: &Path, tip: Option<&str>) -> Result<Chain> {
        Chain::from_urdf_file_with(path, tip, &MeshOptions::default().with_ros_package_path())
    }

    /// [`Chain::from_urdf_file`] with collision meshes read as `meshes` says (see [`mesh`]).
    pub fn from_urdf_file_with(path: &Path, tip: Option<&str>, meshes: &MeshOptions) -> Result<Chain> {
        let size = std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len();
        if size > urdf::MAX_URDF_BYTES {
            return Err(Error::Urdf(format!(
                "{}: {size} bytes, more than the {} bytes a URDF may have",
                path.display(),
                urdf::MAX_URDF_BYTES
            )));
        }
        let xml = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let canon = path.canonicalize().map_err(|e| Error::io(path, e))?;
        let dir = canon.parent().map_or_else(|| PathBuf::from("/"), Path::to_path_buf);
        let source = mesh::MeshSource {
            dir,
            options: meshes,
            limits: mesh::Limits::DEFAULT,
            read: Default::default(),
        };
        let compiled = urdf::compile_str(&xml, tip, Some(&source));
        compiled.and_then(|c| Chain::compiled(&xml, c)).map_err(|e| match e {
            Error::Urdf(m) => Error::Urdf(format!("{}: {m}", path.display())),
            e => e,
        })
    }

    /// Number of actuated joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }
    /// The actuated joints, root to tip.
    pub fn joints(&self) -> &[JointInfo] {
        &self.joints
    }
    /// Lower position limits (rad or m), one per joint; `-inf` for continuous joints.
    pub fn lower_limits(&self) -> &[f64] {
        &self.lower
    }
    /// Upper position limits (rad or m), one per joint; `+inf` for continuous joints.
    pub fn upper_limits(&self) -> &[f64] {
        &self.upper
    }
    /// Speed limits (rad/s or m/s), one per joint, positive.
    pub fn velocity_limits(&self) -> &[f64] {
        &self.velocity
    }
    /// The first joint's origin in the base frame, metres: the centre of the arm's reach.
    pub fn first_joint_origin(&self) -> Vector3<f64> {
        Vector3::from(self.kin.first_joint_origin())
    }
    /// How far the tip can be from [`Chain::first_joint_origin`], metres: the sum of the link
    /// lengths after each joint plus each prismatic joint's largest extension (an upper bound; no
    /// pose puts the tip farther away).
    pub fn reach_m(&self) -> f64 {
        let travel: f64 = self
            .joints
            .iter()
            .filter(|j| j.kind == JointKind::Prismatic)
            .map(|j| j.lower.abs().max(j.upper.abs()))
            .sum();
        self.kin.link_lengths().sum::<f64>() + travel
    }
    /// A bound on the tip's distance from the root link's origin for any joint values within the
    /// limits, metres: [`Chain::first_joint_origin`]'s distance plus [`Chain::reach_m`] (finite:
    /// origins and prismatic limits are bounded by [`MAX_LENGTH_M`]). For observation bounds.
    pub fn reach_bound_m(&self) -> f64 {
        self.first_joint_origin().norm() + self.reach_m()
    }
    /// The root link: the frame poses are expressed in.
    pub fn base_link(&self) -> &str {
        &self.base_link
    }
    /// The tip link whose pose [`Chain::fk`] returns.
    pub fn tip_link(&self) -> &str {
        &self.tip_link
    }

    /// Forward kinematics: the tip pose in the base frame for joint values `q` (rad or m).
    ///
    /// `q.len()` must equal [`Chain::dof`] (checked in debug builds only; in release a longer `q`
    /// has its extra values ignored and a shorter one gives a meaningless pose, without panicking). Use [`Chain::try_fk`] for untrusted input. No heap allocation.
    #[inline]
    pub fn fk(&self, q: &[f64]) -> Pose {
        debug_assert_eq!(q.len(), self.dof(), "fk: q.len() must equal dof");
        kin::pose_of(&self.kin.fk_tf(q))
    }

    /// Checked forward kinematics: errors ([`Error::InvalidInput`]) on a wrong length, a
    /// non-finite joint value, or finite joint values whose pose overflows to a non-finite one.
    pub fn try_fk(&self, q: &[f64]) -> Result<Pose> {
        self.check_q(q)?;
        let pose = self.fk(q);
        let p = pose.position;
        let quat = pose.quaternion_xyzw();
        if p.iter().chain(quat.iter()).any(|v| !v.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "forward kinematics overflows for these finite joint values: position {:?}, \
                 quaternion {quat:?}; joint values must be of a physical scale (within the joints' \
                 limits: {})",
                [p.x, p.y, p.z],
                self.joints
                    .iter()
                    .map(|j| format!("`{}` [{}, {}]", j.name, j.lower, j.upper))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        Ok(pose)
    }

    /// The arm's skeleton for joint values `q` (checked as [`Chain::try_fk`] checks them): the
    /// origin of every joint frame, root to tip, then the tip's position, metres, base frame
    /// (`dof + 1` points; links are the segments between consecutive points).
    pub fn joint_origins(&self, q: &[f64]) -> Result<Vec<[f64; 3]>> {
        self.check_q(q)?;
        Ok(self.kin.joint_origins(q))
    }

    /// Geometric Jacobian of the tip, row-major 6 x dof into `jac` (rows: vx, vy, vz, wx, wy, wz,
    /// base frame). Returns the tip pose as a by-product.
    ///
    /// Column `i` is `[z_i x (p_tip - p_i); z_i]` for a revolute joint (m/rad, 1) and `[z_i; 0]` for
    /// a prismatic one, with `z_i` the joint axis and `p_i` the joint origin in the base frame.
    /// `q.len()` must equal [`Chain::dof`] and `jac.len()` must equal `6 * dof` (both checked in
    /// debug builds only; in release a shorter `jac` panics, a longer one has its tail untouched).
    /// No heap allocation.
    #[inline]
    pub fn jacobian(&self, q: &[f64], jac: &mut [f64]) -> Pose {
        debug_assert_eq!(q.len(), self.dof(), "jacobian: q.len() must equal dof");
        debug_assert_eq!(jac.len(), 6 * self.dof(), "jacobian: jac.len() must be 6 * dof");
        kin::pose_of(&self.kin.jacobian_tf(q, jac))
    }

    /// The tip transform as a row-major 3x4 `[R | t]` (for tests).
    #[cfg(test)]
    pub(crate) fn fk_matrix(&self, q: &[f64]) -> [f64; 12] {
        self.kin.fk_tf(q)
    }

    fn check_q(&self, q: &[f64]) -> Result<()> {
        if q.len() != self.dof() {
            return Err(Error::InvalidInput(format!(
                "q has {} values but the chain `{}` -> `{}` has {} joints; expected length {}",
                q.len(),
                self.base_link,
                self.tip_link,
                self.dof(),
                self.dof()
            )));
        }
        if let Some(i) = q.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "q[{i}] = {} (joint `{}`) is not finite",
                q[i], self.joints[i].name
            )));
        }
        Ok(())
    }
}
