//! # stagerl
//!
//! Deep reinforcement learning for robot-manipulator trajectory planning with the stage-incentive
//! dense rewards of Peng, Yang, Li and Khyam, *Deep Reinforcement Learning with a Stage Incentive
//! Mechanism of Dense Reward for Robotic Trajectory Planning* (the "paper").
//!
//! The modules follow the system:
//! - [`robot`]: serial kinematic chains loaded from URDF (UR5 bundled), forward kinematics and the
//!   geometric Jacobian; [`collision`]: its collision checks in the kinematic simulation;
//!   [`physics`]: a dynamic (rigid-body) simulation of the arm under velocity motors (rapier3d).
//! - [`reward`]: the paper's reward functions, eqs. 1-15 and 18, with every term exposed.
//! - [`env`](mod@env): the random-target reaching task (single and vectorised), its `[task]`
//!   section, and the one episode rollout of eq. 16 ([`env::rollout()`]).
//! - [`config`]: the TOML schema assembled from the sections the modules own, its defaults (the
//!   paper's where it gives them) and validation; [`schedule`]: the `[train]` section;
//!   [`validate`]: the value checks every section shares.
//! - [`controller`]: a scripted Jacobian controller, the reference the learned policies are
//!   measured against.
//! - [`plan`]: a trajectory from a start pose to a target with a trained policy or the
//!   controller; [`policy`]: the portable description of a checkpoint's policy.
//! - [`export`]: the policy as an ONNX model ([`proto`]: the protobuf encoder it and the
//!   TensorBoard writer share).
//! - [`view`]: planned trajectories as a self-contained, animated HTML 3D view.
//! - [`rng`]: the seeded random generator every stochastic piece uses.
//! - [`nn`]: a small multilayer-perceptron engine (forward, backward, Adam) with its own
//!   run-time-dispatched SIMD matrix kernels; [`par`]: the worker threads one run can split its
//!   updates over (same bits on any number).
//! - [`agent`]: TD3 (with DDPG as its one-critic case) and SAC; [`replay`]: their replay buffer;
//!   [`her`]: their hindsight relabelling;
//!   [`train`]: the off-policy loop and evaluation; [`rundir`]: the run directory; [`checkpoint`],
//!   [`log`] (the CSV files and TensorBoard), [`io`]: what runs write; [`experiment`]: sweeps;
//!   [`metrics`], [`report`]: the paper's indicators, tables and figures.
//!
//! Units: metres, radians, seconds; quaternions are `(x, y, z, w)` on every interface.

pub mod agent;
pub mod checkpoint;
pub mod collision;
pub mod config;
pub mod controller;
pub mod env;
pub mod error;
pub mod experiment;
pub mod export;
pub mod her;
pub mod io;
pub mod lock;
pub mod log;
pub mod math;
pub mod metrics;
pub mod nn;
pub mod par;
pub mod physics;
pub mod plan;
pub mod policy;
pub mod proto;
pub mod provenance;
pub mod replay;
pub mod report;
pub mod reward;
pub mod rng;
pub mod robot;
pub mod rundir;
pub mod schedule;
pub mod simd;
pub mod stats;
pub mod text;
pub mod train;
pub mod validate;
pub mod view;

pub use error::{Error, Result};
/// The linear-algebra crate of the public interfaces (`Vector3`, `UnitQuaternion`).
pub use nalgebra;
