//! Serial kinematic chains: loaded from URDF, compiled into flat arrays, evaluated by hand.
//!
//! INTERFACE STUB: the kinematics helper replaces the bodies; the signatures are what the rest of
//! the crate codes against.

use nalgebra::{UnitQuaternion, Vector3};
use std::path::Path;

use crate::Result;

/// The bundled UR5 URDF (see `assets/robots/ur5.urdf`).
pub const UR5_URDF: &str = include_str!("../../../../assets/robots/ur5.urdf");

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
    pub name: String,
    pub kind: JointKind,
    /// Lower position limit (rad or m); `-inf` for a continuous joint.
    pub lower: f64,
    /// Upper position limit (rad or m); `+inf` for a continuous joint.
    pub upper: f64,
    /// Speed limit (rad/s or m/s), positive.
    pub velocity: f64,
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
}

impl Chain {
    /// The bundled UR5 (tip `tool0`).
    pub fn ur5() -> Chain {
        todo!()
    }

    /// `"ur5"` for the bundled arm, otherwise a path to a URDF file.
    pub fn load(robot: &str, tip: Option<&str>) -> Result<Chain> {
        let _ = (robot, tip);
        todo!()
    }

    /// Parse a URDF document. `tip`: the tip link; `None` takes the only leaf link.
    pub fn from_urdf_str(xml: &str, tip: Option<&str>) -> Result<Chain> {
        let _ = (xml, tip);
        todo!()
    }

    /// Read and parse a URDF file.
    pub fn from_urdf_file(path: &Path, tip: Option<&str>) -> Result<Chain> {
        let _ = (path, tip);
        todo!()
    }

    /// Number of actuated joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }
    pub fn joints(&self) -> &[JointInfo] {
        &self.joints
    }
    pub fn lower_limits(&self) -> &[f64] {
        &self.lower
    }
    pub fn upper_limits(&self) -> &[f64] {
        &self.upper
    }
    pub fn velocity_limits(&self) -> &[f64] {
        &self.velocity
    }
    pub fn base_link(&self) -> &str {
        &self.base_link
    }
    pub fn tip_link(&self) -> &str {
        &self.tip_link
    }

    /// Forward kinematics. `q.len()` must equal [`Chain::dof`] (checked in debug builds).
    pub fn fk(&self, q: &[f64]) -> Pose {
        let _ = q;
        todo!()
    }

    /// Checked forward kinematics: errors on a wrong length or a non-finite joint value.
    pub fn try_fk(&self, q: &[f64]) -> Result<Pose> {
        let _ = q;
        todo!()
    }

    /// Geometric Jacobian of the tip, row-major 6 x dof into `jac` (rows: vx, vy, vz, wx, wy, wz,
    /// base frame). Returns the tip pose as a by-product.
    pub fn jacobian(&self, q: &[f64], jac: &mut [f64]) -> Pose {
        let _ = (q, jac);
        todo!()
    }
}
