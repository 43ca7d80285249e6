//! # stagerl
//!
//! Deep reinforcement learning for robot-manipulator trajectory planning with the stage-incentive
//! dense rewards of Peng, Yang, Li and Khyam, *Deep Reinforcement Learning with a Stage Incentive
//! Mechanism of Dense Reward for Robotic Trajectory Planning* (the "paper").
//!
//! The modules follow the system:
//! - [`robot`]: serial kinematic chains loaded from URDF (UR5 bundled), forward kinematics and the
//!   geometric Jacobian.
//! - [`reward`]: the paper's reward functions, eqs. 1-15 and 18, with every term exposed.
//! - [`env`](mod@env): the random-target reaching task (single and vectorised).
//! - [`config`]: the TOML schema, its defaults (the paper's where it gives them) and validation.
//! - [`controller`]: a scripted Jacobian controller, the reference the learned policies are
//!   measured against.
//! - [`rng`]: the seeded random generator every stochastic piece uses.
//! - [`nn`]: a small multilayer-perceptron engine (forward, backward, Adam) on `gemm`.
//! - [`agent`]: DDPG, TD3 and SAC; [`replay`]: their replay buffer; [`train`]: the off-policy
//!   loop, evaluation and the run directory; [`checkpoint`], [`log`], [`io`]: what runs write.
//!
//! Units: metres, radians, seconds; quaternions are `(x, y, z, w)` on every interface.

pub mod agent;
pub mod checkpoint;
pub mod config;
pub mod controller;
pub mod env;
pub mod error;
pub mod experiment;
pub mod io;
pub mod lock;
pub mod log;
pub mod metrics;
pub mod nn;
pub mod replay;
pub mod report;
pub mod reward;
pub mod rng;
pub mod robot;
pub mod train;

pub use error::{Error, Result};
/// The linear-algebra crate of the public interfaces (`Vector3`, `UnitQuaternion`).
pub use nalgebra;
