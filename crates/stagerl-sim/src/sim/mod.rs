//! The arm in its world: the one interface an environment steps ([`arm`]: kinematic or dynamic,
//! with its scene's collision checks), the collision checks ([`collision`]) and the dynamic
//! (rigid-body) simulation under velocity motors ([`physics`], rapier3d).

pub mod arm;
pub mod collision;
pub mod physics;
pub mod rrt_connect;
pub mod scene;
pub mod shield;
