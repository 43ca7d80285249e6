//! # stagerl
//!
//! Deep reinforcement learning for robot-manipulator trajectory planning with the stage-incentive
//! dense rewards of Peng, Yang, Li and Khyam, *Deep Reinforcement Learning with a Stage Incentive
//! Mechanism of Dense Reward for Robotic Trajectory Planning* (the "paper").
//!
//! The folders follow the pipeline from the bottom up; each imports only the folders above it in
//! this list (`tests/it/code_shape.rs` asserts it). Four of them are crates of their own, so that
//! an edit above them does not recompile them and they compile side by side: `stagerl-base`
//! ([`base`]), `stagerl-nn` ([`nn`]) and `stagerl-sim` ([`robot`] and [`sim`], with parry3d and
//! rapier3d); this crate re-exports them at the same paths (`stagerl::nn::Mlp`,
//! `stagerl::base::rng::Rng`) and holds the other twelve.
//! - [`base`]: the error type, the seeded random generator, scalar math, run-time SIMD dispatch,
//!   the fork-join pool one run splits its work over, text bounds and shared value checks.
//! - [`nn`]: a small multilayer-perceptron engine (forward, backward, Adam) with its own
//!   run-time-dispatched SIMD matrix kernels.
//! - [`io`]: atomic file writes, checkpoints, the CSV files, TensorBoard event files and the
//!   protobuf encoder they and the ONNX export share.
//! - [`agent`]: DDPG, TD3, SAC and PPO and the off-policy replay buffer; they see arrays only.
//! - [`robot`]: serial kinematic chains loaded from URDF (UR5 bundled), forward kinematics and
//!   the geometric Jacobian.
//! - [`sim`]: the kinematic simulation's collision checks and the dynamic (rigid-body)
//!   simulation of the arm under velocity motors (rapier3d).
//! - [`reward`]: the paper's reward functions, eqs. 1-15 and 18, with every term exposed.
//! - [`env`](mod@env): the random-target reaching task (single and vectorised), its `[task]`
//!   section, and the one episode rollout of eq. 16 ([`env::rollout()`]).
//! - [`config`]: the TOML schema assembled from the sections the modules own, the `[train]`
//!   section, defaults (the paper's where it gives them) and validation.
//! - [`run`]: a run directory, its lock, the provenance of results and the portable description
//!   of a checkpoint's policy.
//! - [`train`]: the training loop, hindsight relabelling and evaluation.
//! - [`plan`]: a trajectory from a start pose to a target with a trained policy or the scripted
//!   Jacobian controller (the reference the learned policies are measured against).
//! - [`export`]: the policy as an ONNX model.
//! - [`view`]: planned trajectories as a self-contained, animated HTML 3D view.
//! - [`report`]: the paper's indicators, statistics, tables and figures.
//! - [`sweep`]: the paper's protocol of algorithms x rewards x seeds, resumable and shardable.
//!
//! Units: metres, radians, seconds; quaternions are `(x, y, z, w)` on every interface.

pub mod agent;
pub mod config;
pub mod env;
pub mod export;
pub mod io;
pub mod plan;
pub mod report;
pub mod reward;
pub mod run;
pub mod sweep;
pub mod train;
pub mod view;

// The folders of the lower crates, at the same paths as the folders of this one.
pub use stagerl_base::base;
pub use stagerl_nn::nn;
pub use stagerl_sim::{robot, sim};

/// The linear-algebra crate of the public interfaces (`Vector3`, `UnitQuaternion`).
pub use nalgebra;
pub use stagerl_base::{Error, Result};

/// The README's Rust example, compiled by `cargo test` (rustdoc tests the README's `rust` code
/// blocks) so that the front door stays true of the code.
#[doc = include_str!("../../../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
