//! # stagerl-sim
//!
//! stagerl's arm and simulators: [`robot`] (serial kinematic chains loaded from URDF, forward
//! kinematics and the geometric Jacobian) and [`sim`] (the kinematic simulation's collision
//! checks with parry3d, the dynamic simulation with rapier3d, and the scene). It builds on
//! `stagerl-base` only. Use it through the `stagerl` crate, which re-exports both folders as
//! `stagerl::robot` and `stagerl::sim` (see that crate's documentation for the layout).

pub mod robot;
pub mod sim;

// The folder below, under its path in the `stagerl` crate (`crate::base::...`).
use stagerl_base::base;
use stagerl_base::{Error, Result};
