//! The arm in its world: the kinematic simulation's collision checks ([`collision`]) and the
//! dynamic (rigid-body) simulation under velocity motors ([`physics`], rapier3d).

pub mod collision;
pub mod physics;
