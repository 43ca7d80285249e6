//! # stagerl-base
//!
//! The bottom of the stagerl library: [`base`] (the error type, the seeded random generator,
//! scalar math, run-time SIMD dispatch, the fork-join pool, text bounds and shared value
//! checks). It imports nothing of stagerl. Use it through the `stagerl` crate, which re-exports
//! it as `stagerl::base` (see that crate's documentation for the layout).

pub mod base;

pub use base::error::{Error, Result};
