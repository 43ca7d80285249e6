//! # stagerl-nn
//!
//! stagerl's network engine, [`nn`]: a small multilayer-perceptron engine (forward, backward,
//! Adam) with its own run-time-dispatched SIMD matrix kernels. It builds on `stagerl-base` only.
//! Use it through the `stagerl` crate, which re-exports it as `stagerl::nn` (see that crate's
//! documentation for the layout).

pub mod nn;

// The folder below, under its path in the `stagerl` crate (`crate::base::...`).
use stagerl_base::base;
